"""The runner's pose tracker: a constant-velocity Kalman filter on the position between sensor
frames, and the moment of the newest trusted fix.

The control step predicts the finger's position (m) at its own time from the newest fix (a
frame a couple of bus passes old); :class:`firmware_io.localization.ConstantVelocityKalman`
does the filtering, this module fixes the tuning and carries the moment (A m^2, array frame)
the force law and the torque use. The moment is not extrapolated: a finger turns its splint by
a few degrees in one frame's latency. Why these defaults, and the tracked error they give on the
simulated device: docs/runner.md ("Tracker tuning").
"""

from __future__ import annotations

import numpy as np

from ..localization import ConstantVelocityKalman


class PoseTracker(ConstantVelocityKalman):
    """:class:`firmware_io.localization.ConstantVelocityKalman` with the runner's tuning and
    the moment (``update(position_m, time_s, ok, moment_a_m2)``, ``predict(time_s)``, ``x``
    (2, 3) position, velocity; ``moment_a_m2`` (3,) A m^2 or None before the first fix).

    Parameters
    ----------
    accel_rms_m_s2 : float, m/s^2
        A finger's rms acceleration while exploring a surface.
    meas_rms_m : float, m
        Measurement noise of the calibrated fit. Only the ratio accel/meas sets the gain;
        see docs/runner.md for the choice.
    """

    def __init__(self, accel_rms_m_s2: float = 2.0, meas_rms_m: float = 1.5e-3):
        super().__init__(accel_rms_m_s2, meas_rms_m)

    def reset(self) -> None:
        super().reset()
        self.moment_a_m2 = None

    def update(self, position_m, time_s: float, ok: bool = True, moment_a_m2=None):
        """Fold in one fix (position m at ``time_s`` s, and its moment A m^2 when ok)."""
        out = super().update(position_m, time_s, ok)
        if ok and moment_a_m2 is not None:
            self.moment_a_m2 = np.array(moment_a_m2, dtype=float)
        return out
