"""Where is the finger magnet? Pose estimators over the Hall sensors -- numpy only (runs on the
controller).

    est = estimator_from_map("fieldmap.npz", "model")           # or ModelEstimator(model, settings)
    fix = est.estimate(readings_t, currents_a)   # (n_sensors, 3) T, NaN = missing; (n_coils,) A
    if fix.ok: fix.position_m, fix.moment_a_m2   # ok: trusted (protection levels within limits)

One interface (:class:`Estimator`, :mod:`.estimator`), one method a module: 'model'
(:mod:`.model_estimator`), 'dipole' (:mod:`.subtraction_estimator`), 'learned'
(:mod:`.learned_estimator`), 'kalman' (:mod:`.kalman_estimator`), chosen by name in
:mod:`.factory`; several magnets at once: :class:`MagnetsEstimator` (:mod:`.magnets_estimator`,
the joint fit :mod:`.magnets_fit`, acquisition and identities :mod:`.magnets_locate`); their settings (:mod:`.settings`) and result (:mod:`.estimate`). The fit
(:mod:`.position_fit`, :mod:`.lm`), the magnet's field (:mod:`.magnet`), the sensors
(:mod:`.sensor_model`, :mod:`.calibration`, :mod:`.frame`), integrity (:mod:`.integrity`), the
learned inverse (:mod:`.learned`) and the Kalman filter (:mod:`.filter`). Derivations and
measured accuracy: docs/localization.md.
"""

from .calibration import (CALIBRATED_RELATIVE_ERROR, UNCALIBRATED_RELATIVE_ERROR,
                          CalibrationSettings, SensorCalibration, calibrate)
from .estimate import Estimate, Pose
from .estimator import Estimator
from .factory import METHODS, estimator_from_map, make_estimator
from .filter import ConstantVelocityKalman
from .kalman_estimator import KalmanEstimator
from .learned import LearnedInverse
from .learned_estimator import LearnedEstimator
from .magnet import MU0, cylinder_field, multipole_field
from .magnets_estimate import MagnetsEstimate
from .magnets_estimator import MagnetsEstimator
from .model_estimator import ModelEstimator
from .sensor_model import DEFAULT_NOISE_T, SensorModel
from .settings import (MIN_SENSORS_FOR_POSE, POSITION_ONLY, EstimatorSettings,
                       settings_for_layout)
from .subtraction_estimator import SubtractionEstimator

__all__ = [
    "CALIBRATED_RELATIVE_ERROR", "UNCALIBRATED_RELATIVE_ERROR", "CalibrationSettings",
    "SensorCalibration", "calibrate", "Estimate", "Pose", "Estimator", "METHODS", "estimator_from_map",
    "make_estimator", "ConstantVelocityKalman", "KalmanEstimator", "LearnedInverse",
    "LearnedEstimator", "MagnetsEstimate", "MagnetsEstimator", "MU0", "cylinder_field", "multipole_field", "ModelEstimator",
    "DEFAULT_NOISE_T", "SensorModel", "EstimatorSettings", "POSITION_ONLY",
    "MIN_SENSORS_FOR_POSE", "settings_for_layout",
    "SubtractionEstimator",
]
