"""The constant-velocity Kalman filter on the magnet's position estimates.

Per axis, with one shared 2 x 2 covariance (position m, velocity m/s): white acceleration as the
process noise, the estimator's position noise as the measurement noise. Estimates that are not
ok are skipped (prediction only); :meth:`ConstantVelocityKalman.predict` extrapolates between
sensor frames for the control loop.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import BadInputError


class ConstantVelocityKalman:
    """Constant-velocity Kalman filter on the position estimates (per axis, shared dt).

    Process: white acceleration of ``accel_rms_m_s2`` (a finger's ~2 m/s^2); measurement noise
    ``meas_rms_m`` per axis. Estimates with ok = False are skipped (prediction only).
    """

    def __init__(self, accel_rms_m_s2: float = 2.0, meas_rms_m: float = 0.5e-3):
        for name, val in (("accel_rms_m_s2", accel_rms_m_s2), ("meas_rms_m", meas_rms_m)):
            if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
                raise BadInputError(name, "a finite number > 0", val)
        self.q = float(accel_rms_m_s2) ** 2
        self.r = float(meas_rms_m) ** 2
        self.reset()

    def reset(self) -> None:
        self.x = None                # (2, 3): position, velocity
        self.t = None
        self.p = (0.0, 0.0, 0.0)     # covariance p00, p01, p11 (the same for each axis)

    def update(self, position_m, time_s: float, ok: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Fold in one estimate; returns (position (3,), velocity (3,)). Scalar arithmetic on
        the shared 2 x 2 covariance (it runs on the control thread)."""
        z = np.asarray(position_m, dtype=float)
        if self.x is None:
            if ok:
                self.x = np.stack([z, np.zeros(3)])
                self.p = (self.r, 0.0, 1.0)
                self.t = float(time_s)
            return z.copy(), np.zeros(3)
        dt = max(float(time_s) - self.t, 0.0)
        p00, p01, p11 = self.p
        q = self.q
        # predict: F P F^T + Q with F = [[1, dt], [0, 1]], Q = q [[dt^4/4, dt^3/2], [., dt^2]]
        p00, p01, p11 = (p00 + 2 * dt * p01 + dt * dt * p11 + q * dt ** 4 / 4,
                         p01 + dt * p11 + q * dt ** 3 / 2, p11 + q * dt * dt)
        x = self.x[0] + dt * self.x[1]
        v = self.x[1]
        if ok:
            s = p00 + self.r
            k0, k1 = p00 / s, p01 / s
            innov = z - x
            x = x + k0 * innov
            v = v + k1 * innov
            p00, p01, p11 = p00 - k0 * p00, p01 - k0 * p01, p11 - k1 * p01
        self.x = np.stack([x, v])
        self.p = (p00, p01, p11)
        self.t = float(time_s)
        return x.copy(), v.copy()

    def innovation(self, position_m, time_s: float) -> tuple[np.ndarray, float]:
        """(position_m minus the prediction at ``time_s`` (3,) m, the prediction's variance per
        axis plus the measurement noise, m^2): what a gate compares a new fix with."""
        if self.x is None:
            raise BadInputError("filter state", "at least one ok estimate before innovation", None)
        dt = max(float(time_s) - self.t, 0.0)
        p00, p01, p11 = self.p
        var = p00 + 2 * dt * p01 + dt * dt * p11 + self.q * dt ** 4 / 4
        return np.asarray(position_m, float) - self.predict(time_s), var + self.r

    def predict(self, time_s: float) -> np.ndarray:
        """Extrapolated position (3,) at ``time_s`` (between frames); NaN-free: raises if empty."""
        if self.x is None:
            raise BadInputError("filter state", "at least one ok estimate before predict", None)
        return self.x[0] + max(float(time_s) - self.t, 0.0) * self.x[1]

