"""Where is the finger magnet? Estimators over the two Hall arrays -- numpy only (runs on the
controller).

    loc = Localizer.from_map("fieldmap.npz", method="model")
    est = loc.locate(top_t, bottom_t, currents_a)     # (9, 3) T each; NaN = missing/saturated
    est.position_m, est.residual, est.ok

One concept a module: :mod:`.magnet` (the magnet's multipole and exact cylinder field),
:mod:`.sensor_model` (what the estimators know about the sensors and coils),
:mod:`.estimator` (:class:`Localizer`, methods 'learned', 'dipole', 'model', 'kalman'),
:mod:`.lm` (its Levenberg-Marquardt), :mod:`.integrity` (residual test, covariance and
protection level of a fix),
:mod:`.calibration` (per-sensor gains, rotation, offset and position error from frames with
the coils driven), :mod:`.learned` (the thesis' learned inverse, section 3.2.2) and
:mod:`.filter` (the constant-velocity Kalman filter). The methods, the magnet model's
derivation and the measured accuracy: docs/localization.md.
"""

from .calibration import (CALIBRATED_RELATIVE_ERROR, UNCALIBRATED_RELATIVE_ERROR,
                          SensorCalibration, calibrate)
from .estimator import METHODS, Estimate, Localizer
from .filter import ConstantVelocityKalman
from .learned import LearnedInverse
from .magnet import MU0, cylinder_field, multipole_field
from .sensor_model import DEFAULT_NOISE_T, SensorModel

__all__ = [
    "CALIBRATED_RELATIVE_ERROR", "UNCALIBRATED_RELATIVE_ERROR",
    "SensorCalibration", "calibrate", "METHODS", "Estimate", "Localizer",
    "ConstantVelocityKalman", "LearnedInverse", "MU0", "cylinder_field", "multipole_field",
    "DEFAULT_NOISE_T", "SensorModel",
]
