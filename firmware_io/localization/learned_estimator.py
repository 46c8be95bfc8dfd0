"""The thesis' learned inverse as an estimator, method 'learned': :class:`LearnedEstimator`.

Subtract the lower array from the upper one, take the sensor with the largest remainder and map
its 3-vector to the magnet's position relative to that sensor with the
:class:`LearnedInverse` (thesis section 3.2.2). Nothing bounds its error, so its estimates are
never ok; it is here to compare with the thesis.
"""

from __future__ import annotations

import numpy as np

from ..errors import BadInputError
from .estimate import Estimate, Pose
from .estimator import Estimator
from .learned import LearnedInverse
from .pose_fit import PoseFit


class LearnedEstimator(Estimator):
    """Method 'learned' (module docstring). ``learned``: the trained :class:`LearnedInverse`
    of the model's design."""

    method = "learned"
    needs_currents = False

    def __init__(self, model, settings=None, *, calibration=None,
                 learned: LearnedInverse | None = None):
        super().__init__(model, settings, calibration=calibration)
        if model.pairs is None:
            raise BadInputError("model.pairs", "(upper, lower) sensor pairs for the subtraction",
                                None)
        if learned is None:
            raise BadInputError("weights", "a learned-inverse file for method 'learned'", None)
        if learned.design_sha256 != model.design_sha256:
            raise BadInputError("weights", f"trained for design {model.design_sha256[:12]}...",
                                f"design {learned.design_sha256[:12]}...",
                                "Retrain: designkit.calibration.learned_inverse."
                                "train_learned_inverse.")
        self.learned = learned
        self.engine = PoseFit(self.model, self.settings, self.calibration, subtract=True)
        self.calibration = self.engine.calibration

    def fit(self, readings: np.ndarray, currents: np.ndarray | None, seed: Pose | None,
            time_s: float | None) -> Estimate:
        fit = self.engine
        d, use, _, _ = fit.data(fit.corrected(readings), None)
        mom = self.model.moment_a_m2.copy()
        if not use.any():
            return Estimate.refused(self.fallback_position_m(), mom, "no usable sensor pair",
                                    self.method)
        k = int(np.argmax(np.where(use, np.linalg.norm(d, axis=1), -1.0)))
        rel, inside = self.learned(d[k])
        p = self.model.sensor_positions_m[fit.pairs[k, 0]] + rel
        reason = ("the learned inverse has no protection level" if inside
                  else "outside the learned inverse's training box")
        return Estimate(p, mom, False, reason, n_used=int(use.sum()), method=self.method)

    def reset(self) -> None:
        """Nothing to forget: each frame is mapped on its own."""

    def fallback_position_m(self) -> np.ndarray:
        return 0.5 * (self.model.box_lower_m + self.model.box_upper_m)
