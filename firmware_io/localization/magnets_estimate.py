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
    """

    magnets: tuple
    excluded_sensors: tuple = ()
    consistent: bool = False
    background_t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    chi2: float = 0.0
    dof: int = 0
    reason: str = ""

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
        return cls(tuple(estimates), reason=reason)
