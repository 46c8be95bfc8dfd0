"""The two-array :class:`firmware_io.localization.Localizer` behind the pose estimator
interface the runner codes against, until the pose estimators replace it.

The interface: ``fix(readings_t (n_sensors, 3) T, NaN unusable; currents_a (n_coils,) A)`` ->
an estimate with ``position_m``, ``moment_a_m2`` (array frame), ``ok`` (trusted), ``reason``,
``covariance`` (position block first, m^2), ``protection_level_m``,
``orientation_protection_level_rad``, ``excluded_sensors`` (fault detection), ``background_t``,
``chi2``, ``dof``, ``n_used``; it never raises on a bad frame. ``reset()`` makes the next fix
start from the global search; ``integrity_risk`` and ``model_bias_m`` feed the runner's
multi-frame protection level. The Localizer fits the position only: the moment it reports is
the map's, no sensor is excluded, the background is zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class PoseEstimate:
    """One frame's pose estimate (SI; fields as the module docstring lists)."""

    position_m: np.ndarray
    moment_a_m2: np.ndarray
    ok: bool
    reason: str = ""
    covariance: np.ndarray | None = None
    protection_level_m: float = math.inf
    orientation_protection_level_rad: float = math.inf
    excluded_sensors: tuple = ()
    background_t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    chi2: float = 0.0
    dof: int = 0
    n_used: int = 0


class LocalizerShim:
    """A :class:`firmware_io.localization.Localizer` as a pose estimator (module docstring).

    Sensors 0..n-1 are its upper array, n..2n-1 its lower one.
    """

    def __init__(self, localizer):
        self.localizer = localizer
        self.n_sensors = 2 * localizer.model.n_sensors
        self.moment_a_m2 = np.asarray(localizer.model.moment_a_m2, float)
        self.integrity_risk = localizer.integrity_risk
        self.model_bias_m = localizer.model_bias_m

    def reset(self) -> None:
        self.localizer.reset()

    def fix(self, readings_t, currents_a) -> PoseEstimate:
        n = self.n_sensors // 2
        try:
            r = np.asarray(readings_t, dtype=float)
            if r.shape != (2 * n, 3):
                return self._refused(f"bad frame: readings of shape {r.shape} (expected "
                                     f"({2 * n}, 3))")
            est = self.localizer.fix(r[:n], r[n:], currents_a)
        except (TypeError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            return self._refused(f"bad frame: {exc}")
        return PoseEstimate(np.asarray(est.position_m, float), self.moment_a_m2.copy(),
                            bool(est.ok), est.reason, est.covariance_m2,
                            float(est.protection_level_m), 0.0 if est.ok else math.inf,
                            (), np.zeros(3), float(est.chi2), int(est.dof), int(est.n_used))

    def _refused(self, reason: str) -> PoseEstimate:
        centre = 0.5 * (self.localizer.model.box_lower_m + self.localizer.model.box_upper_m)
        return PoseEstimate(np.asarray(centre, float), self.moment_a_m2.copy(), False, reason)
