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
from .position_fit import PositionFit


class ModelEstimator(Estimator):
    """Method 'model' (module docstring); the :class:`Estimator` interface."""

    method = "model"
    needs_currents = True

    def __init__(self, model, settings=None, *, calibration=None):
        super().__init__(model, settings, calibration=calibration)
        self.engine = PositionFit(self.model, self.settings, self.calibration)
        self.calibration = self.engine.calibration

    def fit(self, readings: np.ndarray, currents: np.ndarray | None, seed: Pose | None,
            time_s: float | None) -> Estimate:
        if seed is not None:
            self.engine.warm_start(seed.position_m)
        meas = self.engine.corrected(readings)
        return self.engine.fit(meas, currents, self.method)

    def reset(self) -> None:
        self.engine.reset()

    def fallback_position_m(self) -> np.ndarray:
        return self.engine.last_position_m
