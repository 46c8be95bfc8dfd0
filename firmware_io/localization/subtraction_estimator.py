"""The thesis' subtraction, method 'dipole': :class:`SubtractionEstimator`.

The lower array, mirrored onto the upper one (the coils' field maps as B_upper = P B_lower; for
the symmetric array P = diag(-1, -1, 1)), is subtracted from the upper array, which cancels the
coils' field without knowing the currents; the magnet (and, unless ``settings.cores`` is False,
the cores it magnetizes) is fitted to the remainder. The fit: :mod:`.position_fit`.
"""

from __future__ import annotations

import numpy as np

from ..errors import BadInputError
from .estimate import Estimate, Pose
from .estimator import Estimator
from .fix import fallback_position, locate
from .pose_fit import PoseFit


class SubtractionEstimator(Estimator):
    """Method 'dipole' (module docstring); the :class:`Estimator` interface. Currents, when
    given, are checked and not used."""

    method = "dipole"
    needs_currents = False

    def __init__(self, model, settings=None, *, calibration=None):
        super().__init__(model, settings, calibration=calibration)
        if model.pairs is None:
            raise BadInputError("model.pairs", "(upper, lower) sensor pairs for the subtraction",
                                None)
        self.engine = PoseFit(self.model, self.settings, self.calibration, subtract=True)
        self.calibration = self.engine.calibration

    def fit(self, readings: np.ndarray, currents: np.ndarray | None, seed: Pose | None,
            time_s: float | None) -> Estimate:
        fit = self.engine
        d, use, sigma, field = fit.data(fit.corrected(readings), None)
        return locate(fit, d, use, sigma, field, seed, self.method)

    def reset(self) -> None:
        self.engine.last = None

    def fallback_position_m(self) -> np.ndarray:
        return fallback_position(self.engine)
