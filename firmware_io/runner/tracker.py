"""The runner's position tracker: a constant-velocity Kalman filter between sensor frames.

The control step predicts the finger's position (m) at its own time from the newest fix (a
frame a couple of bus passes old); :class:`firmware_io.localization.ConstantVelocityKalman`
does the filtering, this module only fixes the tuning. Why these defaults, and the tracked
error they give on the simulated device: docs/runner.md ("Tracker tuning").
"""

from __future__ import annotations

from ..localization import ConstantVelocityKalman


class ConstantVelocityTracker(ConstantVelocityKalman):
    """:class:`firmware_io.localization.ConstantVelocityKalman` with the runner's tuning
    (``update(position_m, time_s, ok)``, ``predict(time_s)``, ``x`` (2, 3) position, velocity).

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
