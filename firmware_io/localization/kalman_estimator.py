"""Another estimator's fixes filtered by a constant-velocity Kalman filter, method 'kalman':
:class:`KalmanEstimator`.

Each ok fix of the inner estimator is folded into :class:`ConstantVelocityKalman`; the estimate
reports the filtered position and velocity, and the protection level of the filtered position
(:func:`.integrity.fused_protection_level`: the filter's gain and prediction variance scale the
fix's noise part, the model-bias part stays). Not-ok fixes are skipped (prediction only) and the
estimate stays not ok. :meth:`KalmanEstimator.predict` extrapolates between frames.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import BadInputError
from .estimate import Estimate, Pose
from .estimator import Estimator
from .filter import ConstantVelocityKalman
from .integrity import fused_protection_level, ratio_quantiles


class KalmanEstimator(Estimator):
    """Method 'kalman' (module docstring).

    Parameters
    ----------
    inner : Estimator -- whose fixes are filtered
    kalman : ConstantVelocityKalman (default: its defaults)
    frame_period_s : float, s -- the frame time assumed when :meth:`estimate` gets none
    """

    method = "kalman"

    def __init__(self, inner: Estimator, kalman: ConstantVelocityKalman | None = None,
                 frame_period_s: float = 0.01):
        super().__init__(inner.model, inner.settings, calibration=inner.calibration)
        if not (isinstance(frame_period_s, (int, float)) and 0 < frame_period_s < 10):
            raise BadInputError("frame_period_s", "in (0, 10) s", frame_period_s)
        self.inner, self.frame_period_s = inner, float(frame_period_s)
        self.kalman = kalman if kalman is not None else ConstantVelocityKalman()
        self.needs_currents = inner.needs_currents

    @property
    def n_sensors(self) -> int:
        return self.inner.n_sensors

    def fit(self, readings: np.ndarray, currents: np.ndarray | None, seed: Pose | None,
            time_s: float | None) -> Estimate:
        est = self.inner.fit(readings, currents, seed, time_s)
        kf = self.kalman
        t = time_s if time_s is not None else (
            kf.t + self.frame_period_s if kf.t is not None else 0.0)
        pl = est.protection_level_m
        if est.ok and kf.x is not None:
            _, var = kf.innovation(est.position_m, t)
            pred = var - kf.r
            pl = fused_protection_level(pl, est.position_covariance_m2, pred, self.model_bias_m,
                                        pred / var, ratio_quantiles(self.integrity_risk))
        pos, vel = kf.update(est.position_m, t, est.ok)
        return dataclasses.replace(est, position_m=pos, velocity_m_s=vel, method=self.method,
                                   protection_level_m=pl)

    def predict(self, time_s: float) -> np.ndarray:
        """The filter's extrapolated position (3,) m at ``time_s``."""
        return self.kalman.predict(time_s)

    def magnet_free(self, readings_t, currents_a=None) -> bool:
        return self.inner.magnet_free(readings_t, currents_a)

    def reset(self) -> None:
        self.inner.reset()
        self.kalman.reset()

    def fallback_position_m(self) -> np.ndarray:
        return self.inner.fallback_position_m()
