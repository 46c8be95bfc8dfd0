"""The runner's pose tracker: a constant-velocity Kalman filter on the position between sensor
frames, the moment of the newest trusted fix, and the prior each new frame is fitted with.

The control step predicts the finger's position (m) at its own time from the newest fix (a
frame a couple of bus passes old); :class:`firmware_io.localization.ConstantVelocityKalman`
does the filtering, this module fixes the tuning and carries the moment (A m^2, array frame)
the force law and the torque use. The moment is not extrapolated: its direction's uncertainty
grows at a finger's turning rate instead. The sensor side fits every frame with the tracker's
prediction at the frame's time as the prior (:meth:`TrackedPose.prior`): the position's
variance the filter's prediction variance, the direction's the newest fix's plus the turn since.
Why these defaults, and the tracked error they give on the simulated device: docs/runner.md
("Tracker tuning", "Priors and acquisition").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import BadInputError
from ..localization import ConstantVelocityKalman, Pose

TURN_RMS_RAD_S = math.radians(60.0)
"""A finger's rms turning rate (rad/s): the splint tilts 20-30 degrees in ordinary use within a
fraction of a second."""

SPEED_RMS_M_S = 0.3
"""A finger's rms speed while exploring (m/s): the prior's velocity variance is at most its
square (the filter starts from an uninformative velocity)."""

PRIOR_ACCEL_M_S2 = 20.0
"""The acceleration (rms, m/s^2) the prior allows between frames: a finger's quick starts and
stops, not the smooth exploring the filter is tuned for (a prior too tight for them is rejected
by the frame, and the fix falls back to a cold one)."""

PRIOR_SPEED_ERROR_M_S = 0.05
"""The least velocity error (rms, m/s) the prior assumes: the filter's velocity lags a sudden
change."""

UNKNOWN_DIRECTION_VAR = math.radians(30.0) ** 2
"""The direction's variance (rad^2) when the fix gave none (an estimator that keeps the map's
direction): a prior that says little about it."""


@dataclass(frozen=True)
class TrackedPose:
    """What the tracker knew after its newest update (an immutable copy the sensor side reads
    while the control step goes on): the newest trusted fix (``position_m`` (3,) m,
    ``moment_a_m2`` (3,) A m^2, ``covariance`` (5, 5) over the position, m^2, and two rotations
    of the direction about its tangent axes, rad^2; ``t_s`` its frame time), the filter's
    velocity (3,) m/s and its per-axis variance (m/s)^2 (within :data:`PRIOR_SPEED_ERROR_M_S`
    and :data:`SPEED_RMS_M_S`), the acceleration's ``accel_var`` (m/s^2)^2
    (:data:`PRIOR_ACCEL_M_S2`) and the direction's variance growth ``turn_var`` (rad/s)^2."""

    position_m: np.ndarray
    moment_a_m2: np.ndarray
    covariance: np.ndarray
    t_s: float
    velocity_m_s: np.ndarray
    velocity_var: float
    accel_var: float
    turn_var: float

    def prior(self, time_s: float) -> Pose:
        """The pose expected at ``time_s`` (s) as a :class:`firmware_io.localization.Pose`: the
        newest fix moved by the velocity, its covariance grown per position axis by the
        velocity's uncertainty and the acceleration over the interval (v_var dt^2 + q dt^4 /
        4) and per rotation by the turn (turn_var dt^2)."""
        dt = max(float(time_s) - self.t_s, 0.0)
        cov = self.covariance.copy()
        grow = self.velocity_var * dt * dt + self.accel_var * dt ** 4 / 4
        cov[[0, 1, 2], [0, 1, 2]] += grow
        cov[[3, 4], [3, 4]] += self.turn_var * dt * dt
        return Pose(self.position_m + dt * self.velocity_m_s, self.moment_a_m2.copy(), cov)


class PoseTracker(ConstantVelocityKalman):
    """:class:`firmware_io.localization.ConstantVelocityKalman` with the runner's tuning, the
    moment and the newest fix's pose covariance (``update(position_m, time_s, ok, moment_a_m2,
    covariance)``, ``predict(time_s)``, ``x`` (2, 3) position, velocity; ``moment_a_m2`` (3,) A
    m^2 or None before the first fix; :meth:`snapshot` for the sensor side's prior).

    Parameters
    ----------
    accel_rms_m_s2 : float, m/s^2
        A finger's rms acceleration while exploring a surface.
    meas_rms_m : float, m
        Measurement noise of the calibrated fit. Only the ratio accel/meas sets the gain;
        see docs/runner.md for the choice.
    turn_rms_rad_s : float, rad/s -- a finger's rms turning rate (:data:`TURN_RMS_RAD_S`)
    """

    def __init__(self, accel_rms_m_s2: float = 2.0, meas_rms_m: float = 1.5e-3,
                 turn_rms_rad_s: float = TURN_RMS_RAD_S):
        super().__init__(accel_rms_m_s2, meas_rms_m)
        if not (isinstance(turn_rms_rad_s, (int, float)) and math.isfinite(turn_rms_rad_s)
                and turn_rms_rad_s > 0):
            raise BadInputError("turn_rms_rad_s", "a finite number > 0, rad/s", turn_rms_rad_s)
        self.turn_var = float(turn_rms_rad_s) ** 2

    def reset(self) -> None:
        super().reset()
        self.moment_a_m2 = None
        self.fix = None           # (position (3,), covariance (5, 5), frame time) of the newest

    def update(self, position_m, time_s: float, ok: bool = True, moment_a_m2=None,
               covariance=None):
        """Fold in one fix (position m at ``time_s`` s; when ok its moment A m^2 and its
        covariance: (3, 3) m^2 of the position, or (5, 5) with the direction's two rotations,
        rad^2; a direction without one gets :data:`UNKNOWN_DIRECTION_VAR`)."""
        out = super().update(position_m, time_s, ok)
        if ok and moment_a_m2 is not None:
            self.moment_a_m2 = np.array(moment_a_m2, dtype=float)
            cov = np.diag([self.r] * 3 + [UNKNOWN_DIRECTION_VAR] * 2)
            if covariance is not None:
                c = np.asarray(covariance, float)
                k = min(len(c), 5)
                cov[:k, :k] = c[:k, :k]
            self.fix = (np.array(position_m, dtype=float), cov, float(time_s))
        return out

    def snapshot(self) -> TrackedPose | None:
        """The state as an immutable :class:`TrackedPose` (None before the first fix with a
        moment)."""
        if self.x is None or self.fix is None:
            return None
        p, cov, t = self.fix
        v_var = min(max(float(self.p[2]), PRIOR_SPEED_ERROR_M_S ** 2), SPEED_RMS_M_S ** 2)
        return TrackedPose(p.copy(), self.moment_a_m2.copy(), cov.copy(), t, self.x[1].copy(),
                           v_var, PRIOR_ACCEL_M_S2 ** 2, self.turn_var)
