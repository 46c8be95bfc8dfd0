"""The Cramer-Rao bound of finger-magnet poses from a Hall-sensor layout.

Each sensor reads, on its chip's axes, R_s^T (sum of the magnets' fields + a uniform background)
plus independent Gaussian noise of variance noise^2 + lsb^2 / 12 per axis (the analog noise and
the readout's rounding, uniform over one count). For N magnets of known |m| the unknowns are 5 N
(each centre and moment direction, :mod:`.response`) or 3 N (positions, directions known), plus
3 for the background when it is fitted, as the pose estimator does. The Fisher information is
F = sum_s J_s^T J_s / sigma^2 over the sensors that stay linear (every chip axis within
``usable_fraction`` of the range: the runner leaves the others out), and the bound on any
unbiased estimate's covariance is F^-1 (Kay, Fundamentals of Statistical Signal Processing I,
ch. 3). Reported per magnet: the position's rms error sqrt(tr C_pos) (m), its mean absolute
error E|e| for e ~ N(0, C_pos) (m) and the direction's rms error (rad). With isotropic noise the
bound does not depend on how a chip is turned, except through which sensors stay linear.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal

import numpy as np

from firmware_io.hw.tlv493d import TLV493D_LINEAR_RANGE_T, TLV493D_LSB_T
from firmware_io.localization import DEFAULT_NOISE_T
from firmware_io.runner.headroom import EXPECTED_SATURATION

from ..errors import BadInputError
from .response import Response

UNOBSERVABLE_CONDITION = 1e13
"""A Fisher information whose scaled condition number exceeds this is singular: the pose is
not observable from the usable sensors (bounds then reported as :data:`UNOBSERVABLE_M`)."""
UNOBSERVABLE_M = 1.0
"""The position bound reported for a pose the sensors cannot observe, m (and pi rad)."""


@dataclass(frozen=True)
class BoundSettings:
    """What the bound assumes.

    ``noise_t``: analog noise per axis, T rms (default: the TLV493D's); ``lsb_t``: one count, T
    (0: no rounding term); ``dof``: 'pose' (5 a magnet) or 'position' (3, directions known);
    ``background``: 'uniform' (3 nuisance unknowns) or 'none'; ``cores``: 'coupled' (the
    cores magnetized by the magnets add to the readings) or 'none'; ``range_t`` and
    ``usable_fraction``: a sensor with a chip axis beyond their product is left out.
    """

    noise_t: float = DEFAULT_NOISE_T
    lsb_t: float = TLV493D_LSB_T
    dof: Literal["pose", "position"] = "pose"
    background: Literal["uniform", "none"] = "uniform"
    cores: Literal["coupled", "none"] = "coupled"
    range_t: float = TLV493D_LINEAR_RANGE_T
    usable_fraction: float = EXPECTED_SATURATION

    def __post_init__(self):
        for name in ("noise_t", "range_t", "usable_fraction"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise BadInputError(name, "a finite number > 0", getattr(self, name))
        if not (math.isfinite(self.lsb_t) and self.lsb_t >= 0):
            raise BadInputError("lsb_t", "a finite number >= 0 T", self.lsb_t)
        for name, choices in (("dof", ("pose", "position")), ("background", ("uniform", "none")),
                              ("cores", ("coupled", "none"))):
            if getattr(self, name) not in choices:
                raise BadInputError(name, f"one of {choices}", getattr(self, name))

    @property
    def variance_t2(self) -> float:
        """Per-axis variance of a reading, T^2: noise^2 + lsb^2 / 12."""
        return self.noise_t ** 2 + self.lsb_t ** 2 / 12.0

    @property
    def magnet_dof(self) -> int:
        return 5 if self.dof == "pose" else 3

    def n_unknowns(self, n_magnets: int) -> int:
        """5 N (or 3 N) + 3 with the background."""
        return self.magnet_dof * n_magnets + (3 if self.background == "uniform" else 0)


@dataclass(frozen=True)
class Bound:
    """The bound per scenario (n_scenarios) and magnet (n_magnets), SI.

    ``position_rms_m`` sqrt(tr C_pos); ``position_mae_m`` E|e|; ``orientation_rms_rad`` (zeros
    when directions are known); ``condition`` the Fisher information's condition number after
    scaling its diagonal to 1; ``usable`` the sensors that stay linear; ``observable`` False
    where F is singular (bounds there: :data:`UNOBSERVABLE_M`, pi).
    """

    position_rms_m: np.ndarray
    position_mae_m: np.ndarray
    orientation_rms_rad: np.ndarray
    condition: np.ndarray
    usable: np.ndarray
    observable: np.ndarray


def usable_sensors(fields_t: np.ndarray, frames: np.ndarray, settings: BoundSettings
                   ) -> np.ndarray:
    """(n_sensors, n_scenarios) bool: every chip axis of the summed field ``fields_t``
    (n_sensors, n_scenarios, 3) T, array frame, within ``usable_fraction`` x ``range_t``
    (``frames`` (n_sensors, 3, 3): columns the chip's axes)."""
    chip = np.einsum("sai,sna->sni", frames, fields_t)
    return np.abs(chip).max(axis=-1) <= settings.usable_fraction * settings.range_t


def scenario_jacobians(response: Response, scenarios: np.ndarray, sensors: np.ndarray,
                       settings: BoundSettings) -> tuple[np.ndarray, np.ndarray]:
    """Stacked Jacobians (n_sensors, n_scenarios, 3, n_unknowns) in the array frame and the
    summed fields (n_sensors, n_scenarios, 3) T of the scenarios' magnets (``scenarios``
    (n_scenarios, n_magnets): indices into the response's poses) at the sites ``sensors``."""
    d = settings.magnet_dof
    n_mag = scenarios.shape[1]
    jac = response.jacobian[sensors]
    blocks = [jac[:, scenarios[:, k], :, :d] for k in range(n_mag)]
    if settings.background == "uniform":
        blocks.append(np.broadcast_to(np.eye(3), blocks[0].shape[:2] + (3, 3)))
    field = response.field_t[sensors][:, scenarios].sum(axis=2)
    return np.concatenate(blocks, axis=-1), field


def fisher_information(jacobians: np.ndarray, frames: np.ndarray, usable: np.ndarray,
                       variance_t2: float) -> np.ndarray:
    """(n_scenarios, P, P): sum over the usable sensors of J^T J / sigma^2, J the readings'
    Jacobian on each chip's axes (``jacobians`` (n_sensors, n_scenarios, 3, P), array frame)."""
    chip = np.einsum("sai,snap->snip", frames, jacobians) * usable[:, :, None, None]
    return np.einsum("snip,sniq->npq", chip, chip) / variance_t2


def bound_from_fisher(fisher: np.ndarray, n_magnets: int, magnet_dof: int) -> tuple:
    """(covariance (n, P, P), condition (n,), observable (n,)) of Fisher informations
    (n, P, P); a singular one gets a zero covariance and observable False."""
    diag = np.einsum("npp->np", fisher)
    ok = np.all(diag > 0, axis=1)
    scale = 1.0 / np.sqrt(np.where(diag > 0, diag, 1.0))
    scaled = fisher * scale[:, :, None] * scale[:, None, :]
    eig = np.linalg.eigvalsh(scaled)
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = np.where(eig[:, 0] > 0, eig[:, -1] / np.where(eig[:, 0] > 0, eig[:, 0], 1.0),
                        np.inf)
    ok &= cond < UNOBSERVABLE_CONDITION
    cov = np.zeros_like(fisher)
    if ok.any():
        inv = np.linalg.inv(scaled[ok])
        cov[ok] = inv * scale[ok][:, :, None] * scale[ok][:, None, :]
    return cov, np.where(ok, cond, UNOBSERVABLE_CONDITION), ok


def pose_bound(response: Response, scenarios, sensors, frames,
               settings: BoundSettings = BoundSettings()) -> Bound:
    """The Cramer-Rao bound of every scenario from the sensors at sites ``sensors`` (indices
    into the response's sites) with chip ``frames`` (n_sensors, 3, 3).

    ``scenarios``: (n_scenarios, n_magnets) int, the magnets' poses (indices into the
    response's poses) estimated jointly in each scenario.
    """
    scen = np.atleast_2d(np.asarray(scenarios, dtype=int))
    idx = np.asarray(sensors, dtype=int)
    jac, field = scenario_jacobians(response, scen, idx, settings)
    usable = usable_sensors(field, np.asarray(frames, dtype=float), settings)
    fisher = fisher_information(jac, np.asarray(frames, dtype=float), usable,
                                settings.variance_t2)
    return summarize(fisher, scen.shape[1], settings, usable.sum(axis=0))


def summarize(fisher: np.ndarray, n_magnets: int, settings: BoundSettings,
              usable: np.ndarray) -> Bound:
    """:class:`Bound` of Fisher informations (n_scenarios, P, P)."""
    d = settings.magnet_dof
    cov, cond, ok = bound_from_fisher(fisher, n_magnets, d)
    pos = np.stack([cov[:, k * d:k * d + 3, k * d:k * d + 3] for k in range(n_magnets)], 1)
    rms = np.sqrt(np.maximum(np.einsum("nkii->nk", pos), 0.0))
    mae = mean_norm(pos)
    if d == 5:
        ang = np.sqrt(np.maximum(np.stack([cov[:, k * 5 + 3, k * 5 + 3] + cov[:, k * 5 + 4,
                                                                           k * 5 + 4]
                                           for k in range(n_magnets)], 1), 0.0))
    else:
        ang = np.zeros_like(rms)
    bad = ~ok
    rms[bad], mae[bad] = UNOBSERVABLE_M, UNOBSERVABLE_M
    ang[bad] = math.pi if d == 5 else 0.0
    return Bound(rms, mae, ang, cond, np.asarray(usable, dtype=int), ok)


@lru_cache(maxsize=1)
def sphere_rule(n: int = 2000) -> np.ndarray:
    """(n, 3) unit vectors of a Fibonacci lattice: equal-weight quadrature on the sphere."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (3.0 - math.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.c_[r * np.cos(phi), r * np.sin(phi), z]


MEAN_CHI3 = 2.0 * math.sqrt(2.0 / math.pi)
"""E|z| for z ~ N(0, I_3)."""


def mean_norm(cov: np.ndarray, chunk: int = 2048) -> np.ndarray:
    """E|e| for e ~ N(0, cov), cov (..., 3, 3): E|z| E_d sqrt(d^T cov d), |z| and the
    direction d of a standard normal being independent (the sphere by :func:`sphere_rule`;
    relative error below 1e-3 for any covariance, 1e-6 for a round one)."""
    d = sphere_rule()
    outer = np.einsum("ki,kj->ijk", d, d).reshape(9, -1)
    flat = cov.reshape(-1, 9)
    out = np.empty(len(flat))
    for a in range(0, len(flat), chunk):
        q = flat[a:a + chunk] @ outer
        out[a:a + chunk] = np.sqrt(np.maximum(q, 0.0)).mean(axis=1)
    return MEAN_CHI3 * out.reshape(cov.shape[:-2])
