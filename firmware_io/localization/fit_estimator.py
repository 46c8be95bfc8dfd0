"""The estimators that fit the magnet's pose to the sensors (:mod:`.pose_fit`): the shared base
:class:`PoseFitEstimator` of 'model' and 'dipole'. Each subclass says what its observation
blocks are (``subtract``); the fit, the integrity verdict and the warm start are this class's.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from ..errors import BadInputError
from .estimate import Estimate, Pose
from .estimator import Estimator
from .frame import check_currents, check_readings
from .fix import fallback_position, locate
from .pose_fit import PoseFit


class PoseFitEstimator(Estimator):
    """An :class:`Estimator` whose fix is :func:`.fix.locate` on a :class:`PoseFit`; its
    ``engine`` holds the fit's tables and the last trusted state."""

    subtract: ClassVar[bool] = False
    """Observation blocks: the model's (upper, lower) pairs subtracted, or each sensor."""

    def __init__(self, model, settings=None, *, calibration=None):
        super().__init__(model, settings, calibration=calibration)
        self.engine = PoseFit(self.model, self.settings, self.calibration,
                              subtract=self.subtract)
        self.calibration = self.engine.calibration

    def fit(self, readings: np.ndarray, currents: np.ndarray | None, seed: Pose | None,
            time_s: float | None) -> Estimate:
        fit = self.engine
        d, use, sigma, field = fit.data(fit.corrected(readings),
                                        None if self.subtract else currents)
        return locate(fit, d, use, sigma, field, seed, self.method)

    def magnet_free(self, readings_t, currents_a=None) -> bool:
        fit = self.engine
        try:
            readings = check_readings(readings_t, self.n_sensors, None)
            currents = (None if self.subtract
                        else check_currents(currents_a, self.model.n_coils))
        except BadInputError:
            return False
        d, use, sigma, _ = fit.data(fit.corrected(readings), currents)
        return fit.explained_without_magnet(d, np.where(use, 1.0 / sigma, 0.0))

    def reset(self) -> None:
        self.engine.last = None

    def fallback_position_m(self) -> np.ndarray:
        return fallback_position(self.engine)
