"""The thesis' subtraction, method 'dipole': :class:`SubtractionEstimator`.

The lower array, mirrored onto the upper one (the coils' field maps as B_upper = P B_lower; for
the symmetric array P = diag(-1, -1, 1)), is subtracted from the upper array, which cancels the
coils' field without knowing the currents; the magnet's pose (and, unless ``settings.cores`` is
False, the cores it magnetizes) is fitted to the remainder. The fit: :mod:`.pose_fit`.
"""

from __future__ import annotations

from ..errors import BadInputError
from .fit_estimator import PoseFitEstimator


class SubtractionEstimator(PoseFitEstimator):
    """Method 'dipole' (module docstring); the :class:`Estimator` interface. Currents, when
    given, are checked and not used."""

    method = "dipole"
    needs_currents = False
    subtract = True

    def __init__(self, model, settings=None, *, calibration=None):
        if model.pairs is None:
            raise BadInputError("model.pairs", "(upper, lower) sensor pairs for the subtraction",
                                None)
        super().__init__(model, settings, calibration=calibration)
