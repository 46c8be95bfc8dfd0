"""What :class:`.magnets_estimator.MagnetsEstimator` returns: :class:`MagnetsEstimate`, one
:class:`.estimate.Estimate` a magnet in the design's magnet order plus what the magnets share
(the excluded sensors, the background, the residual test).

Each magnet's ``ok`` is the one flag that means "trust this magnet's fix": the joint fit
converged, its residual passed the chi-square test (after fault exclusion), the magnet is
known to be the one it is reported as (its identity), and its protection levels are within
the alert limits. ``MagnetsEstimate.ok`` is every magnet's.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .estimate import Estimate


@dataclass(frozen=True)
class MagnetsEstimate:
    """One frame's fixes of N magnets (SI, array frame).

    magnets : tuple of N :class:`Estimate`, in the design's magnet order (identity: index)
    excluded_sensors : the sensors fault exclusion removed from the joint fit
    consistent : the joint fit passed every test but the alert limits
    background_t : (3,) T, the estimated uniform ambient field
    chi2, dof : the joint residual test's statistic and degrees of freedom
    reason : why not every magnet is ok ('' when all are): the frame's, or the first
        not-ok magnet's, named
    frame_positions_m, frame_covariances_m2 : per magnet, its position (3,) m and covariance
        (3, 3) m^2 from this frame's sensors alone (a seed's prior taken out, linearized at
        the fix), or None (not found, not determined by the sensors alone; N = 1: the
        single-magnet fix does not report it): the measurement a
        tracker's filter takes in -- a fix with a prior already holds the prediction, and
        filtering the fix again counts the prediction twice (docs/localization.md)
    """

    magnets: tuple
    excluded_sensors: tuple = ()
    consistent: bool = False
    background_t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    chi2: float = 0.0
    dof: int = 0
    reason: str = ""
    frame_positions_m: tuple = ()
    frame_covariances_m2: tuple = ()

    @property
    def ok(self) -> bool:
        """Every magnet's fix trusted."""
        return bool(self.magnets) and all(m.ok for m in self.magnets)

    @property
    def positions_m(self) -> np.ndarray:
        """(N, 3) m, the magnets' positions (trusted or not: see each ``ok``)."""
        return np.array([m.position_m for m in self.magnets]).reshape(-1, 3)

    @classmethod
    def refused(cls, estimates, reason: str) -> "MagnetsEstimate":
        """A not-ok frame: each magnet's given (not-ok) estimate, one reason."""
        est = tuple(estimates)
        return cls(est, reason=reason, frame_positions_m=(None,) * len(est),
                   frame_covariances_m2=(None,) * len(est))
