"""Model-based cancellation, method 'model': :class:`ModelEstimator`.

The coils' field predicted from the frame's currents (the map's per-ampere field at the
sensors) is subtracted from every sensor, and the magnet (with the field of the cores it
magnetizes) is fitted to all usable sensors: no subtraction of one array from the other, so no
doubled noise, and the lower array's weak magnet signal counts too. The fit and its integrity:
:mod:`.position_fit`, docs/localization.md.
"""

from __future__ import annotations

import numpy as np

from .estimate import Estimate, Pose
from .estimator import Estimator
from .fix import fallback_position, locate
from .pose_fit import PoseFit


class ModelEstimator(Estimator):
    """Method 'model' (module docstring); the :class:`Estimator` interface."""

    method = "model"
    needs_currents = True

    def __init__(self, model, settings=None, *, calibration=None):
        super().__init__(model, settings, calibration=calibration)
        self.engine = PoseFit(self.model, self.settings, self.calibration, subtract=False)
        self.calibration = self.engine.calibration

    def fit(self, readings: np.ndarray, currents: np.ndarray | None, seed: Pose | None,
            time_s: float | None) -> Estimate:
        fit = self.engine
        d, use, sigma, field = fit.data(fit.corrected(readings), currents)
        return locate(fit, d, use, sigma, field, seed, self.method)

    def reset(self) -> None:
        self.engine.last = None

    def fallback_position_m(self) -> np.ndarray:
        return fallback_position(self.engine)
