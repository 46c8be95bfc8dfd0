"""Simulated Hall-sensor arrays (thesis section 3.2) from designkit's own physics: the readings
the runner-side estimators (firmware_io.localization) are tested and studied against.

Two arrays of TLV493D-A1B6 3-D Hall sensors, one on each coil axis, ``sensors.offset_m`` above
the coil tops (upper array) and below the coil bottoms (lower array). A reading is

    reading = gain * R^T B(p_true) + offset + noise, quantized to 0.098 mT, clipped at the
    12-bit codes -2048 / +2047,

with B the sum of the finger magnet's exact cylinder field (:func:`magnet_field`, moment from
the design), the coils' field at the given currents (``CoilArray.actuation_matrix``) and the
field of the cores the magnet magnetizes (:class:`InducedCoreModel` or
``CoilArray.magnet_core_field``). A sensor with any axis beyond the chip's +-130 mT linear range
(datasheet) reads NaN, as the runner must treat it. Positions m, fields T, currents A, in the
array frame (coil tops at z = 0, z up). Also here: the thesis' field cases
(:func:`case_currents`) and the forward model the estimators need (:func:`forward_model`).
Stated defaults of the sensor errors, and the model's details: docs/localization.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np

from firmware_io.hw.tlv493d import TLV493D_LINEAR_RANGE_T, TLV493D_LSB_T
from firmware_io.localization import DEFAULT_NOISE_T

from ..constants import MU0
from ..design import Design, default_design
from ..errors import BadInputError
from ..field import magnetized_cylinder_field
from ..model.array import CoilArray
from ..support import validate as v

TLV_LSB_T = TLV493D_LSB_T
"""Field per LSB of the TLV493D 12-bit values, T (datasheet)."""
TLV_LINEAR_RANGE_T = TLV493D_LINEAR_RANGE_T
"""Specified linear range, T; beyond it a reading is flagged saturated."""
TLV_CODE_MIN, TLV_CODE_MAX = -2048, 2047
TLV_NOISE_T = DEFAULT_NOISE_T
"""Noise per axis, T rms (TLV493D-A1B6 datasheet figure)."""

FieldCase = Literal["off", "static", "sinusoidal", "time-varying", "rendering"]
FIELD_CASES: tuple[str, ...] = ("off", "static", "sinusoidal", "time-varying", "rendering")
THESIS_MAE_MM = {"off": 0.80, "static": 1.26, "sinusoidal": 0.91, "time-varying": 0.86}
"""Measured MAE of the thesis' localization in its field cases 1-4 (n = 125 each), mm."""


# ---------------------------------------------------------------------------- geometry
def sensor_positions_m(design: Design | None = None, array=None) -> np.ndarray:
    """Nominal sensor positions, shape (2, n, 3), m: the map's flat sensor list in two halves
    (the default layout: the upper array, then the lower array, n = n_coils; a layout of its
    own, e.g. a planned one, in its order: an even count).

    Uses ``CoilArray.sensor_poses()`` when the array provides it (one definition), else the
    design rule: on each coil axis, ``sensors.offset_m`` above z = 0 and below the coil bottom.
    """
    if array is not None and hasattr(array, "sensor_poses"):
        pos = np.asarray(array.sensor_poses()[0], dtype=float)
        if len(pos) % 2:
            raise BadInputError("sensor layout", "an even number of sensors for the simulated "
                                "device (its sensors in two halves)", len(pos))
        return pos.reshape(2, -1, 3)
    d = design or default_design()
    c = np.array(d.coil_centres_m(), dtype=float)
    up, lo = c.copy(), c.copy()
    up[:, 2] = d.sensors.offset_m
    lo[:, 2] = -d.coil.length_m - d.sensors.offset_m
    return np.stack([up, lo])


def _frame_from_axis(axis: np.ndarray) -> np.ndarray:
    """Rotation matrix whose third column is the unit vector ``axis``."""
    u = axis / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(helper, u)
    e1 /= np.linalg.norm(e1)
    return np.column_stack([e1, np.cross(u, e1), u])


def magnet_field(points_m, position_m, moment_a_m2, radius_m: float, length_m: float) -> np.ndarray:
    """Exact field of a uniformly magnetized cylinder magnet, (n, 3), T.

    Parameters
    ----------
    points_m : array-like, shape (n, 3), m
    position_m : array-like, shape (3,), m -- the magnet's centre
    moment_a_m2 : array-like, shape (3,), A m^2 -- along the cylinder axis; M = |m| / volume
    radius_m, length_m : float, m
    """
    p, _ = v.points(points_m)
    c = v.vector3("position_m", position_m, "m")
    m = v.vector3("moment_a_m2", moment_a_m2, "A m^2")
    mag = float(np.linalg.norm(m))
    if mag == 0.0:
        raise BadInputError("moment_a_m2", "a non-zero 3-vector, A m^2", m.tolist())
    rot = _frame_from_axis(m)
    local = (p - c) @ rot
    b = magnetized_cylinder_field(local, radius_m, length_m,
                                  mag / (math.pi * radius_m**2 * length_m))
    return b @ rot.T


# ---------------------------------------------------------------------------- induced cores
class InducedCoreModel:
    """Field of the iron cores magnetized by the finger magnet (zero coil current).

    How: each core is cut into ``n_slices`` axial slices (graded towards the ends), each a
    uniformly axially magnetized cylinder (:func:`designkit.field.magnetized_cylinder_field`).
    The slice magnetizations M_k solve the linear-core condition M = chi H on the slice-averaged
    axial field, H = H_magnet + H_slices (a thin-rod integral equation):
    ``(I / chi - D) M = <H_magnet,z>`` with ``D[i, j]`` the cross-section-averaged axial H of slice
    j (M = 1 A/m) over slice i. The magnet's applied field is averaged over 5 points of each
    slice's mid-plane (axis and 4 points at 0.7 R). Neglected (stated): transverse
    magnetization (demagnetizing factor ~0.5, so chi_eff ~ 2 against ~30 axially), core-to-core
    coupling, saturation (linear mu_r from the design). The coupled array model
    (``CoilArray.magnet_core_field``) replaces this where it exists.

    The result is linear in the magnet's field, so ``operator()`` returns the (2 n 3, 5 S)
    matrix mapping the applied axial H at the sample points to the sensors' field; the runner
    side uses the same linear map with the dipole field (firmware_io.localization).
    """

    def __init__(self, design: Design, points_m: np.ndarray, *, n_slices: int = 20):
        if design.core is None:
            raise BadInputError("design.core", "a core (an air-core array has no induced field)",
                                None)
        core = design.core
        self.radius_m = core.radius_m
        chi = core.relative_permeability - 1.0
        t = 0.5 * (1 - np.cos(np.linspace(0.0, math.pi, n_slices + 1)))
        edges = (t - 0.5) * core.length_m  # local to the core centre
        self.lengths_m = np.diff(edges)
        self.centres_local_m = 0.5 * (edges[1:] + edges[:-1])
        coil_centres = np.array(design.coil_centres_m(), dtype=float)
        core_centres = coil_centres + np.array([0.0, 0.0, core.offset_m])
        self.core_centres_m = core_centres
        # sample points (axis + 4 at 0.7 R) of each slice mid-plane, weights 1/3 and 1/6 each
        r = 0.7 * core.radius_m
        ring = np.array([[0, 0], [r, 0], [0, r], [-r, 0], [0, -r]], dtype=float)
        self.sample_weights = np.array([1 / 3] + [1 / 6] * 4)
        samples = np.zeros((len(core_centres), n_slices, 5, 3))
        samples[..., :2] = ring[None, None] + core_centres[:, None, None, :2]
        samples[..., 2] = core_centres[:, None, None, 2] + self.centres_local_m[None, :, None]
        self.samples_m = samples
        # slice-slice interaction, the same for every core (identical, parallel)
        loc = np.zeros((n_slices, 5, 3))
        loc[..., :2] = ring[None]
        loc[..., 2] = self.centres_local_m[:, None]
        d = np.empty((n_slices, n_slices))
        for j in range(n_slices):
            rel = loc.reshape(-1, 3) - np.array([0.0, 0.0, self.centres_local_m[j]])
            bz = magnetized_cylinder_field(rel, core.radius_m, self.lengths_m[j], 1.0)[:, 2]
            hz = bz.reshape(n_slices, 5) / MU0
            hz[j] -= 1.0  # H = B / mu0 - M inside slice j
            d[:, j] = hz @ self.sample_weights
        self.solve_matrix = np.linalg.inv(np.eye(n_slices) / chi - d)  # M = K <H_app>
        # sensors' field per unit slice magnetization: (n_pts, 3, n_cores, n_slices)
        pts = np.asarray(points_m, dtype=float).reshape(-1, 3)
        self.points_m = pts
        s = np.empty((len(pts), 3, len(core_centres), n_slices))
        for c, cc in enumerate(core_centres):
            for j in range(n_slices):
                rel = pts - (cc + np.array([0.0, 0.0, self.centres_local_m[j]]))
                s[:, :, c, j] = magnetized_cylinder_field(rel, core.radius_m, self.lengths_m[j], 1.0)
        self.response = s

    def operator(self) -> np.ndarray:
        """(n_pts * 3, n_cores * n_slices * 5): sensors' B (T) per applied H_z (A/m) at the samples."""
        nc, ns = self.samples_m.shape[:2]
        k = np.einsum("ij,w->ijw", self.solve_matrix, self.sample_weights)  # (ns, ns, 5)
        out = np.einsum("pdcj,jkw->pdckw", self.response, k)
        return out.reshape(len(self.points_m) * 3, nc * ns * 5)

    def field(self, applied_hz_a_m: np.ndarray) -> np.ndarray:
        """Sensors' induced B, (..., n_pts, 3), T, from the applied H_z at the samples
        (..., n_cores, n_slices, 5), A/m."""
        h = np.asarray(applied_hz_a_m, dtype=float)
        havg = h @ self.sample_weights                     # (..., nc, ns)
        m = havg @ self.solve_matrix.T                     # (..., nc, ns) A/m
        return np.einsum("pdcj,...cj->...pd", self.response, m)

    def field_of_magnet(self, magnet_positions_m, moment_a_m2, radius_m, length_m) -> np.ndarray:
        """Induced B at the model's points for each magnet position, (k, n_pts, 3), T."""
        pos, _ = v.points(magnet_positions_m, "magnet_positions_m")
        flat = self.samples_m.reshape(-1, 3)
        out = np.empty((len(pos), len(self.points_m), 3))
        for i, p in enumerate(pos):
            hz = magnet_field(flat, p, moment_a_m2, radius_m, length_m)[:, 2] / MU0
            out[i] = self.field(hz.reshape(self.samples_m.shape[:3]))
        return out


# ---------------------------------------------------------------------------- sensor errors
@dataclass(frozen=True)
class SensorErrors:
    """Per-sensor deviations, all (2, n, ...) arrays (upper array, then lower).

    offsets_t (2, n, 3) T; gains (2, n, 3); rotations (2, n, 3, 3) (sensor axes as columns in
    the array frame); position_errors_m (2, n, 3) m; dead (2, n) bool.
    """

    offsets_t: np.ndarray
    gains: np.ndarray
    rotations: np.ndarray
    position_errors_m: np.ndarray
    dead: np.ndarray

    @classmethod
    def ideal(cls, n: int) -> "SensorErrors":
        return cls(np.zeros((2, n, 3)), np.ones((2, n, 3)), np.tile(np.eye(3), (2, n, 1, 1)),
                   np.zeros((2, n, 3)), np.zeros((2, n), bool))

    @classmethod
    def random(cls, n: int, rng: np.random.Generator, *, offset_t: float = 0.01e-3,
               gain: float = 0.01, mount_position_m: float = 0.5e-3,
               mount_angle_deg: float = 1.0, dead: Sequence[tuple[int, int]] = ()) -> "SensorErrors":
        """Random errors: offset and gain normal (rms per axis ``offset_t``, ``gain``); a
        mounting shift of length ``mount_position_m`` and a rotation by ``mount_angle_deg``,
        each about a random direction; ``dead`` lists (array, index) pairs."""
        v.nonnegative("offset_t", offset_t, "T")
        v.nonnegative("gain", gain, "")
        v.nonnegative("mount_position_m", mount_position_m, "m")
        v.nonnegative("mount_angle_deg", mount_angle_deg, "deg")
        d = rng.normal(size=(2, n, 3))
        d *= mount_position_m / np.linalg.norm(d, axis=-1, keepdims=True)
        axes = rng.normal(size=(2, n, 3))
        axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
        rot = _rodrigues(axes, math.radians(mount_angle_deg))
        dd = np.zeros((2, n), bool)
        for a, i in dead:
            if a not in (0, 1) or not 0 <= i < n:
                raise BadInputError("dead", f"(array 0|1, index 0..{n - 1}) pairs", (a, i))
            dd[a, i] = True
        return cls(rng.normal(scale=offset_t, size=(2, n, 3)),
                   1.0 + rng.normal(scale=gain, size=(2, n, 3)), rot, d, dd)


def _rodrigues(axes: np.ndarray, angle: float) -> np.ndarray:
    k = np.zeros(axes.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -axes[..., 2], axes[..., 1], -axes[..., 0]
    k = k - np.swapaxes(k, -1, -2)
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


# ---------------------------------------------------------------------------- the simulator
@dataclass(frozen=True)
class Readings:
    """Simulated frames. top_t, bottom_t (k, n, 3) T in the array frame, NaN where a sensor is
    saturated (any axis beyond +-130 mT) or dead; codes (k, 2, n, 3) int (12-bit values);
    saturated (k, 2, n) bool; true_field_t (k, 2, n, 3) T (noise-free, at the true poses)."""

    top_t: np.ndarray
    bottom_t: np.ndarray
    codes: np.ndarray
    saturated: np.ndarray
    true_field_t: np.ndarray


class SensorSimulator:
    """Readings of the two Hall arrays for magnet positions and coil currents.

    Parameters
    ----------
    design : Design, optional (default design)
    array : CoilArray, optional (built from the design)
    errors : SensorErrors or 'ideal' or 'default'
        'default' draws :meth:`SensorErrors.random` with the module's stated defaults.
    noise_t : float, T rms per axis (default 0.1 mT, datasheet)
    moment_direction : (3,), the magnet's axis (default: the design's, ``magnet.direction``)
    induced : {'coupled', 'rod', 'off'}
        The cores' field induced by the magnet: 'coupled' = ``CoilArray.magnet_core_field``
        (all cores solved together, the magnet as a point dipole; the costlier per position),
        'rod' = :class:`InducedCoreModel` (each core alone), 'off' = none.
    seed : int
    """

    def __init__(self, design: Design | None = None, *, array=None,
                 errors: SensorErrors | Literal["ideal", "default"] = "default",
                 noise_t: float = TLV_NOISE_T, moment_direction=None,
                 induced: Literal["coupled", "rod", "off"] = "coupled", seed: int = 0):
        self.design = design or default_design()
        self.array = array or CoilArray.from_design(self.design)
        self.noise_t = v.nonnegative("noise_t", noise_t, "T")
        self.rng = np.random.default_rng(seed)
        self.nominal_m = sensor_positions_m(self.design, self.array)
        n = self.nominal_m.shape[1]
        self.n = n
        if isinstance(errors, str):
            if errors not in ("ideal", "default"):
                raise BadInputError("errors", "a SensorErrors, 'ideal' or 'default'", errors)
            errors = (SensorErrors.ideal(n) if errors == "ideal"
                      else SensorErrors.random(n, np.random.default_rng(seed + 1)))
        self.errors = errors
        self.true_m = self.nominal_m + errors.position_errors_m
        if moment_direction is None:
            moment_direction = self.design.magnet.moment_vector_a_m2
        u = v.vector3("moment_direction", moment_direction)
        if not np.linalg.norm(u) > 0:
            raise BadInputError("moment_direction", "a non-zero 3-vector", u.tolist())
        mg = self.design.magnet
        self.moment_a_m2 = u / np.linalg.norm(u) * mg.moment_a_m2
        pts = self.true_m.reshape(-1, 3)
        self.coil_field_t_per_a = self.array.actuation_matrix(pts)[:, :3, :].reshape(
            2, n, 3, self.array.n_coils)
        if induced not in ("coupled", "rod", "off"):
            raise BadInputError("induced", "'coupled', 'rod' or 'off'", induced)
        self.induced_mode = induced
        self._induced = None
        if induced == "rod" and self.design.core is not None:
            self._induced = InducedCoreModel(self.design, pts)

    # -- field parts -------------------------------------------------------------------
    def magnet_part(self, magnet_positions_m) -> np.ndarray:
        """(k, 2, n, 3) T: the magnet's exact field at the true sensor positions."""
        pos, _ = v.points(magnet_positions_m, "magnet_positions_m")
        mg = self.design.magnet
        pts = self.true_m.reshape(-1, 3)
        return np.stack([magnet_field(pts, p, self.moment_a_m2, mg.radius_m, mg.length_m)
                         for p in pos]).reshape(len(pos), 2, self.n, 3)

    def induced_part(self, magnet_positions_m) -> np.ndarray:
        """(k, 2, n, 3) T: the cores' field induced by the magnet (zero current)."""
        pos, _ = v.points(magnet_positions_m, "magnet_positions_m")
        if self.induced_mode == "off" or self.design.core is None:
            return np.zeros((len(pos), 2, self.n, 3))
        pts = self.true_m.reshape(-1, 3)
        if self._induced is None:
            return np.stack([self.array.magnet_core_field(pts, p, self.moment_a_m2)
                             for p in pos]).reshape(len(pos), 2, self.n, 3)
        mg = self.design.magnet
        return self._induced.field_of_magnet(pos, self.moment_a_m2, mg.radius_m,
                                             mg.length_m).reshape(len(pos), 2, self.n, 3)

    def coil_part(self, currents_a) -> np.ndarray:
        """(k, 2, n, 3) T: the coils' (and their cores') field at the currents (k, n_coils), A."""
        i = np.atleast_2d(np.asarray(currents_a, dtype=float))
        if i.ndim != 2 or i.shape[1] != self.array.n_coils or not np.all(np.isfinite(i)):
            raise BadInputError("currents_a", f"finite, shape (k, {self.array.n_coils}), A",
                                f"shape {np.shape(currents_a)}")
        return np.einsum("asdc,kc->kasd", self.coil_field_t_per_a, i)

    # -- readout -------------------------------------------------------------------------
    def read(self, magnet_positions_m, currents_a, *, parts=None, rng=None) -> Readings:
        """Simulated frames for k magnet positions and k current vectors.

        ``parts``: optional precomputed (magnet, induced) arrays (k, 2, n, 3) to reuse across
        field cases (the expensive part).
        """
        pos, _ = v.points(magnet_positions_m, "magnet_positions_m")
        coil = self.coil_part(currents_a)
        if len(coil) != len(pos):
            raise BadInputError("currents_a", f"{len(pos)} rows (one per magnet position)",
                                f"{len(coil)} rows")
        mag, ind = parts if parts is not None else (self.magnet_part(pos), self.induced_part(pos))
        b = mag + ind + coil
        return self.readout(b, rng=rng)

    def readout(self, field_t: np.ndarray, *, rng=None) -> Readings:
        """Sensor chain applied to the true field (k, 2, n, 3) T in the array frame."""
        return tlv_readout(field_t, self.errors, self.noise_t, rng or self.rng)


def analog_reading(field_t: np.ndarray, errors: SensorErrors, noise_t: float,
                   rng: np.random.Generator) -> np.ndarray:
    """What each sensor's ADC converts, T, (k, 2, n, 3): gain * R^T B + offset + noise, for the
    true field (k, 2, n, 3) T in the array frame (the register-level TLV493D model of
    firmware_io.hw.sim quantizes it)."""
    local = np.einsum("asji,kasj->kasi", errors.rotations, field_t)  # R^T B
    return errors.gains * local + errors.offsets_t + rng.normal(scale=noise_t, size=local.shape)


def tlv_readout(field_t: np.ndarray, errors: SensorErrors, noise_t: float,
                rng: np.random.Generator) -> Readings:
    """The TLV493D chain: gain * R^T B + offset + noise -> 12-bit codes (clipped at -2048 /
    +2047) -> tesla; a sensor with any axis beyond +-130 mT (outside the linear range) or dead
    reads NaN. ``field_t`` (k, 2, n, 3) T in the array frame."""
    e = errors
    s = analog_reading(field_t, errors, noise_t, rng)
    codes = np.clip(np.rint(s / TLV_LSB_T), TLV_CODE_MIN, TLV_CODE_MAX).astype(np.int16)
    meas = codes * TLV_LSB_T
    sat = np.any(np.abs(meas) > TLV_LINEAR_RANGE_T, axis=-1)
    # the reader knows only the nominal orientation: it reports the sensor axes as array axes
    out = meas.astype(float)
    out[sat] = np.nan
    out[:, e.dead] = np.nan
    return Readings(out[:, 0], out[:, 1], codes, sat, field_t)


# ---------------------------------------------------------------------------- field cases
def case_currents(case: FieldCase, times_s, n_coils: int, *, seed: int = 0,
                  max_current_a: float = 6.0) -> np.ndarray:
    """Coil currents (k, n_coils), A, of the thesis' field cases at the times (k,) s.

    * 'off' -- case 1: every coil off;
    * 'static' -- case 2: every coil at +0.65 A;
    * 'sinusoidal' -- case 3: 0.65 A amplitude, 1 Hz, coil k phase-shifted by 2 pi k / n
      (the thesis gives neither frequency nor phases);
    * 'time-varying' -- case 4: each coil a different sum of five sinusoids (0.3-5 Hz, random
      phases) scaled to a 1 A peak (the thesis says only "time-varying, 1 A peak");
    * 'rendering' -- like case 4 with the per-coil limit ``max_current_a`` (6 A) as the peak.
    """
    t = np.atleast_1d(np.asarray(times_s, dtype=float))
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise BadInputError("times_s", "a finite 1-D array, s", f"shape {np.shape(times_s)}")
    if case == "off":
        return np.zeros((len(t), n_coils))
    if case == "static":
        return np.full((len(t), n_coils), 0.65)
    if case == "sinusoidal":
        ph = 2 * math.pi * np.arange(n_coils) / n_coils
        return 0.65 * np.sin(2 * math.pi * 1.0 * t[:, None] + ph[None])
    if case in ("time-varying", "rendering"):
        peak = 1.0 if case == "time-varying" else v.positive("max_current_a", max_current_a, "A")
        rng = np.random.default_rng(seed)
        f = rng.uniform(0.3, 5.0, size=(n_coils, 5))
        ph = rng.uniform(0, 2 * math.pi, size=(n_coils, 5))
        a = rng.uniform(0.5, 1.0, size=(n_coils, 5))
        s = np.einsum("cj,tcj->tc", a, np.sin(2 * math.pi * f[None] * t[:, None, None] + ph[None]))
        return peak * s / a.sum(axis=1)[None]
    raise BadInputError("case", f"one of {FIELD_CASES}", case)


def random_positions(n: int, rng: np.random.Generator, *, z_range_m=(0.020, 0.070),
                     half_width_m: float = 0.025) -> np.ndarray:
    """n uniform random magnet positions (n, 3), m, in the box |x|, |y| <= half_width, z in range."""
    lo, hi = z_range_m
    return np.c_[rng.uniform(-half_width_m, half_width_m, (n, 2)), rng.uniform(lo, hi, n)]


def forward_model(sim: SensorSimulator) -> dict:
    """The numbers the runner-side estimator needs (what the v2 map carries), from the design.

    Returns a dict for :class:`firmware_io.localization.SensorModel` (its flat sensor list:
    the upper array, then the lower): nominal ``sensor_positions_m`` (2 n, 3),
    ``coil_field_t_per_a`` (2 n, 3, n_coils) at the nominal positions, the (upper, lower)
    ``pairs``, ``moment_a_m2`` (3,), ``octupole_m2`` (the magnet's l = 3 multipole
    coefficient / dipole coefficient, h^2 - 3 a^2 / 4), the induced-core linear operator (see
    :class:`InducedCoreModel`) and ``design_sha256``.
    """
    d = sim.design
    pts = sim.nominal_m.reshape(-1, 3)
    coil = sim.array.actuation_matrix(pts)[:, :3, :]
    mg = d.magnet
    out = {"sensor_positions_m": pts.copy(), "coil_field_t_per_a": coil,
           "pairs": np.c_[np.arange(sim.n), sim.n + np.arange(sim.n)],
           "moment_a_m2": sim.moment_a_m2.copy(),
           "octupole_m2": (mg.length_m / 2) ** 2 - 0.75 * mg.radius_m**2,
           "design_sha256": d.spec_hash()}
    if d.core is not None:
        model = InducedCoreModel(d, pts)
        out["induced_samples_m"] = model.samples_m.reshape(-1, 3)
        out["induced_operator"] = model.operator()
    return out
