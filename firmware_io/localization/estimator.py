"""The one interface of the magnet's pose estimators: :class:`Estimator`.

Each method is one subclass in its own module ('model': :mod:`.model_estimator`, 'dipole':
:mod:`.subtraction_estimator`, 'learned': :mod:`.learned_estimator`, 'kalman':
:mod:`.kalman_estimator`); :mod:`.factory` picks one by name. An estimator holds a
:class:`SensorModel` (the sensors' poses, the coils' field there, the magnet), an
:class:`EstimatorSettings` and an optional :class:`SensorCalibration`. One call per frame::

    est = estimator.estimate(readings_t, currents_a)   # (n_sensors, 3) T, (n_coils,) A
    if est.ok: ...                                     # trusted: use est.position_m, ...

:meth:`Estimator.estimate` never raises on a frame: a wrong shape, non-finite values or too few
usable sensors give a not-ok :class:`Estimate` whose ``reason`` says why.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import numpy as np

from ..errors import BadInputError
from .calibration import SensorCalibration
from .estimate import Estimate, Pose
from .frame import check_currents, check_readings
from .sensor_model import SensorModel
from .settings import EstimatorSettings


class Estimator(abc.ABC):
    """The magnet's pose from one frame of the sensors (see the module docstring).

    Parameters
    ----------
    model : SensorModel
    settings : EstimatorSettings (default: its defaults)
    calibration : SensorCalibration, a path to a saved one, or None (uncalibrated)
    """

    method: ClassVar[str] = ""
    """The method's name ('model', 'dipole', 'learned', 'kalman')."""
    needs_currents: ClassVar[bool] = True
    """Whether :meth:`estimate` needs the frame's coil currents."""

    def __init__(self, model: SensorModel, settings: EstimatorSettings | None = None, *,
                 calibration=None):
        if not isinstance(model, SensorModel):
            raise BadInputError("model", "a SensorModel", type(model).__name__)
        self.model = model
        self.settings = settings if settings is not None else EstimatorSettings()
        if calibration is not None and not isinstance(calibration, (SensorCalibration, tuple)):
            calibration = SensorCalibration.load(calibration)
        self.calibration = calibration

    @classmethod
    def from_map(cls, path, settings: EstimatorSettings | None = None, *, calibration=None,
                 expected_design_sha256: str | None = None, magnet_size_m=None,
                 octupole_m2: float | None = None, **extra) -> "Estimator":
        """This method's estimator from a v2 map file (:meth:`SensorModel.from_map`);
        ``extra`` keywords go to the class (e.g. ``learned`` for 'learned')."""
        model = SensorModel.from_map(path, expected_design_sha256=expected_design_sha256,
                                     magnet_size_m=magnet_size_m, octupole_m2=octupole_m2)
        return cls(model, settings, calibration=calibration, **extra)

    @property
    def n_sensors(self) -> int:
        """Sensors in a frame (the rows of ``readings_t``)."""
        return self.model.n_sensors

    @property
    def integrity_risk(self) -> float:
        """Probability per fix that the error exceeds the protection level."""
        return self.settings.integrity_risk

    @property
    def model_bias_m(self) -> float:
        """The model-bias bound (m) inside every protection level."""
        return self.settings.model_bias_for(self.calibration is not None)

    def estimate(self, readings_t, currents_a=None, *, usable=None, seed: Pose | None = None,
                 time_s: float | None = None) -> Estimate:
        """The pose from one frame; never raises on the frame's contents.

        Parameters
        ----------
        readings_t : (n_sensors, 3) T, each sensor in its own frame; NaN = missing/unusable
        currents_a : (n_coils,) A, the coils' currents when the frame was sampled
        usable : (n_sensors,) bool, optional -- False excludes a sensor (as NaN would)
        seed : Pose, optional -- a prior pose (a tracker's prediction) to start from
        time_s : float, optional -- the frame's time (filtering estimators)
        """
        try:
            readings = check_readings(readings_t, self.n_sensors, usable)
            currents = (check_currents(currents_a, self.model.n_coils)
                        if currents_a is not None or self.needs_currents else None)
        except BadInputError as exc:
            self.reset()
            return Estimate.refused(self.fallback_position_m(), self.model.moment_a_m2,
                                    f"bad frame: {exc}", self.method)
        try:
            return self.fit(readings, currents, seed, time_s)
        except (ArithmeticError, np.linalg.LinAlgError) as exc:
            # a numerical failure inside the fit: refuse the frame, never stop the control step
            self.reset()
            return Estimate.refused(self.fallback_position_m(), self.model.moment_a_m2,
                                    f"numerical failure: {exc}", self.method)

    def magnet_free(self, readings_t, currents_a=None) -> bool:
        """Does the frame show no magnet and sensors that agree: the coils' field at
        ``currents_a`` and (when the settings fit one) a uniform background explain every usable
        sensor within the residual test at the false-alarm probability? Then no sensor carries
        an offset much beyond the noise -- a check of the sensors while the finger is away (a
        runner's acquisition uses it). Never raises; False when the method cannot tell."""
        return False

    @abc.abstractmethod
    def fit(self, readings: np.ndarray, currents: np.ndarray | None, seed: Pose | None,
            time_s: float | None) -> Estimate:
        """The estimate of a checked frame: readings (n_sensors, 3) T (NaN = unusable),
        currents (n_coils,) A or None."""

    @abc.abstractmethod
    def reset(self) -> None:
        """Forget the warm start (and any filter state): the next fit starts cold."""

    @abc.abstractmethod
    def fallback_position_m(self) -> np.ndarray:
        """(3,) m reported by a not-ok estimate without a fit: the last ok position or the
        plausible box's centre."""
