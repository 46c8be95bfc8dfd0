"""An estimator by its method's name: :func:`make_estimator`, :func:`estimator_from_map`.

``METHODS`` names the methods (docs/localization.md): 'model' (:class:`ModelEstimator`),
'dipole' (:class:`SubtractionEstimator`), 'learned' (:class:`LearnedEstimator`, needs the
trained inverse), 'kalman' (:class:`KalmanEstimator` over a 'model' estimator).
"""

from __future__ import annotations

from ..errors import BadInputError
from .estimator import Estimator
from .kalman_estimator import KalmanEstimator
from .learned import LearnedInverse
from .learned_estimator import LearnedEstimator
from .model_estimator import ModelEstimator
from .sensor_model import SensorModel
from .settings import EstimatorSettings, settings_for_layout
from .subtraction_estimator import SubtractionEstimator

METHODS = ("learned", "dipole", "model", "kalman")


def make_estimator(method: str, model: SensorModel, settings: EstimatorSettings | None = None,
                   *, calibration=None, learned: LearnedInverse | None = None) -> Estimator:
    """The estimator of ``method`` (one of :data:`METHODS`) for ``model``; ``settings`` None:
    :func:`settings_for_layout` of its sensors."""
    if settings is None:
        settings = settings_for_layout(model.n_sensors)
    if method == "model":
        return ModelEstimator(model, settings, calibration=calibration)
    if method == "dipole":
        return SubtractionEstimator(model, settings, calibration=calibration)
    if method == "learned":
        return LearnedEstimator(model, settings, calibration=calibration, learned=learned)
    if method == "kalman":
        return KalmanEstimator(ModelEstimator(model, settings, calibration=calibration))
    raise BadInputError("method", f"one of {METHODS}", method)


def estimator_from_map(path, method: str = "model", settings: EstimatorSettings | None = None,
                       *, calibration=None, weights=None,
                       expected_design_sha256: str | None = None, magnet_size_m=None,
                       octupole_m2: float | None = None) -> Estimator:
    """The estimator of ``method`` from a v2 map file (:meth:`SensorModel.from_map`);
    ``weights``: the learned inverse's file for 'learned'; ``calibration``: a
    :class:`SensorCalibration` or a path to a saved one."""
    if method not in METHODS:
        raise BadInputError("method", f"one of {METHODS}", method)
    model = SensorModel.from_map(path, expected_design_sha256=expected_design_sha256,
                                 magnet_size_m=magnet_size_m, octupole_m2=octupole_m2)
    learned = LearnedInverse.load(weights) if weights is not None else None
    return make_estimator(method, model, settings, calibration=calibration, learned=learned)
