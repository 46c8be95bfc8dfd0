"""What an estimator returns (:class:`Estimate`) and the prior pose it may start from
(:class:`Pose`), in the array frame (SI).

``Estimate.ok`` is the one flag that means "trust this": the fit converged, its residual passed
the chi-square test (after fault exclusion, when a sensor was excluded) and its protection
levels are within the settings' alert limits. Everything else is there to say how far to trust
it and why not. The covariance's orientation coordinates are two small rotations (rad) of the
moment direction u, about the axes ``orientation_axes`` e1, e2 (unit, perpendicular to u and
to each other): u' = normalize(u + a e1 + b e2) to first order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Pose:
    """A magnet pose: position_m (3,) m and moment_a_m2 (3,) A m^2, array frame (a tracker's
    prediction for a warm start). With ``covariance`` (5, 5) over the position (m^2) and two
    rotations of the moment (rad^2, about the axes :func:`firmware_io.localization.pose.
    tangent_axes` gives for its direction, as an :class:`Estimate`'s ``orientation_axes``) the
    estimator also uses it as a prior observation of the pose (a tracker's prediction and its
    uncertainty): a frame that disagrees with it is solved again without it, cold."""

    position_m: np.ndarray
    moment_a_m2: np.ndarray
    covariance: np.ndarray | None = None


@dataclass(frozen=True)
class Estimate:
    """One fix (SI, array frame).

    position_m : (3,) m
    moment_a_m2 : (3,) A m^2, the moment found (its magnitude the model's unless fitted)
    ok : bool, trusted (see the module docstring); reason: why not ('' when ok)
    covariance : (k, k) over the position (m) and then the orientation (rad, about
        ``orientation_axes``) and, when fitted, log |m|; k = 3 when the orientation was not
        fitted; None without a fit
    protection_level_m : m, bound on the position error at the integrity risk, the
        undetected single-sensor fault included (inf without a fit)
    orientation_protection_level_rad : rad, the same for the moment direction
    excluded_sensors : indices of the sensors fault exclusion removed
    background_t : (3,) T, the estimated uniform ambient field
    chi2, dof : the residual test's statistic and degrees of freedom
    n_used : sensors (or subtracted pairs) in the fit; iterations; method
    orientation_axes : (2, 3), e1 and e2 of the covariance's orientation block
    velocity_m_s : (3,) m/s from a filtering estimator, else None
    consistent : the fit passed every test but the alert limits (converged, inside the box,
        the residual test after any exclusion, finite protection levels): what a caller that
        bounds the undetected fault otherwise (a runner's acquisition) may use
    fault_free_protection_level_m, fault_free_orientation_protection_level_rad : m, rad, the
        protection levels without the undetected single-sensor fault's term (the model bias
        and the covariance's bound); inf without a fit
    prior_used : the fit was solved with the seed's covariance as a prior (False: no prior
        given, or the frame disagreed with it and was solved cold)
    """

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
    iterations: int = 0
    method: str = ""
    orientation_axes: np.ndarray | None = None
    velocity_m_s: np.ndarray | None = None
    consistent: bool = False
    fault_free_protection_level_m: float = math.inf
    fault_free_orientation_protection_level_rad: float = math.inf
    prior_used: bool = False

    @property
    def position_covariance_m2(self) -> np.ndarray | None:
        """(3, 3) m^2, the position block of ``covariance`` (None without a fit)."""
        return None if self.covariance is None else self.covariance[:3, :3]

    @property
    def residual(self) -> float:
        """Normalized rms residual sqrt(chi2 / dof) (1 ~ the noise level; 0 without a fit)."""
        return math.sqrt(self.chi2 / self.dof) if self.dof > 0 else 0.0

    @classmethod
    def refused(cls, position_m, moment_a_m2, reason: str, method: str) -> "Estimate":
        """A not-ok estimate without a fit (bad frame, too few sensors): the given pose."""
        return cls(np.array(position_m, float), np.array(moment_a_m2, float), False, reason,
                   method=method)
