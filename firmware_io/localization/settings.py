"""The estimators' settings: one frozen :class:`EstimatorSettings` (SI units, checked once).

Every estimator (:mod:`.estimator`) takes one; ``dataclasses.replace(settings, ...)`` makes a
variant. The defaults make ``ok`` mean trusted: a fix whose protection level exceeds 5 mm or
15 degrees is not ok. Why each default: docs/localization.md ("Settings").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..errors import BadInputError
from ..hw.tlv493d import TLV493D_LSB_T
from .calibration import CALIBRATED_RELATIVE_ERROR, UNCALIBRATED_RELATIVE_ERROR
from .sensor_model import DEFAULT_NOISE_T


@dataclass(frozen=True)
class EstimatorSettings:
    """What an estimator assumes and how far it trusts a fix (SI).

    noise_t : T rms per axis, the sensors' analog noise; the fit's per-axis variance is
        noise_t^2 + lsb_t^2 / 12 plus the model-error terms
    lsb_t : T, the readout's quantization step
    relative_error : relative model error of a reading (gain, mounting); None: 0.02
        uncalibrated, 0.001 with a calibration
    mount_position_m : m, sensor position uncertainty (weighs near-field sensors)
    model_bias_m : m, bound on the fit's bias from what the noise model leaves out, added to
        the protection level; None: 1 mm uncalibrated, 0.5 mm calibrated
    model_bias_rad : rad, the same for the moment direction; None: 1 degree uncalibrated,
        0.5 degree calibrated
    integrity_risk : probability per fix that the error exceeds the protection level
    false_alarm : probability per fix that a correct fit fails the residual test
    missed_detection : probability that the residual test misses the fault that makes the
        undetected-fault protection level (RAIM's P_md)
    alert_limit_m : m, largest position protection level of an ok fix
    orientation_alert_limit_rad : rad, largest moment-direction protection level of an ok fix
    residual_limit : largest normalized rms residual of an ok fix (a cap beside the test)
    reacquire_m : m, a warm fit that moved farther is checked by the global search
    refresh_m : m, the magnet-model corrections are re-linearized beyond this move
    max_iterations : Levenberg-Marquardt iterations per solve
    cores : model the magnet-induced core field (None: when the sensor model has it)
    fit_moment_magnitude : fit |m| as a sixth unknown (calibration); else |m| from the model
    orientation : 'fit' the moment's direction (the pose), or keep the model's 'fixed' (the
        position alone: for layouts with too few sensors for a pose; ok then trusts the
        assumed direction and the orientation protection level is inf)
    background : 'uniform' fits a uniform ambient field (3 unknowns), 'off' assumes none
    gradient : 'auto' adds the ambient field's gradient (5 unknowns: symmetric, traceless) when
        the uniform model fails the residual test, no single sensor explains it, and the
        gradient lowers chi2 by more than the chi-square(5) quantile at ``false_alarm`` and
        passes the test; 'off' never
    max_exclusions : sensors fault exclusion may drop from one fix (0: detection only)
    fault_model : the faults the undetected-fault protection level covers: 'bounded' -- on any
        one sensor an offset up to ``fault_offset_t`` on one axis or a gain error up to
        ``fault_gain`` (larger errors, a zero or frozen reading, must fail the residual test:
        the integrity study measures that they do); 'any' -- a fault of any shape and size (the
        GNSS slope bound; a sensor without redundancy then makes the level infinite)
    fault_offset_t : T, the largest offset of a bounded fault
    fault_gain : the largest relative gain error of a bounded fault
    """

    noise_t: float = DEFAULT_NOISE_T
    lsb_t: float = TLV493D_LSB_T
    relative_error: float | None = None
    mount_position_m: float = 0.0
    model_bias_m: float | None = None
    model_bias_rad: float | None = None
    integrity_risk: float = 1e-4
    false_alarm: float = 1e-6
    missed_detection: float = 1e-3
    alert_limit_m: float = 5e-3
    orientation_alert_limit_rad: float = math.radians(15.0)
    residual_limit: float = 5.0
    reacquire_m: float = 5e-3
    refresh_m: float = 1e-3
    max_iterations: int = 30
    cores: bool | None = None
    fit_moment_magnitude: bool = False
    orientation: Literal["fit", "fixed"] = "fit"
    background: Literal["uniform", "off"] = "uniform"
    gradient: Literal["auto", "off"] = "auto"
    max_exclusions: int = 1
    fault_model: Literal["bounded", "any"] = "bounded"
    fault_offset_t: float = 2e-3
    fault_gain: float = 0.05

    def __post_init__(self):
        for name in ("noise_t", "residual_limit", "reacquire_m", "refresh_m"):
            val = getattr(self, name)
            if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
                raise BadInputError(name, "a finite number > 0 (SI)", val)
        for name in ("lsb_t", "mount_position_m", "relative_error", "model_bias_m",
                     "model_bias_rad", "fault_offset_t", "fault_gain"):
            val = getattr(self, name)
            if val is not None and not (isinstance(val, (int, float)) and math.isfinite(val)
                                        and val >= 0):
                raise BadInputError(name, "a finite number >= 0 (SI) or None", val)
        for name in ("integrity_risk", "false_alarm", "missed_detection"):
            val = getattr(self, name)
            if not (isinstance(val, (int, float)) and 0 < val < 0.5):
                raise BadInputError(name, "a probability in (0, 0.5)", val)
        for name in ("alert_limit_m", "orientation_alert_limit_rad"):
            val = getattr(self, name)
            if not (isinstance(val, (int, float)) and val > 0):
                raise BadInputError(name, "a number > 0 (or inf)", val)
        if not (isinstance(self.max_iterations, int) and 1 <= self.max_iterations <= 1000):
            raise BadInputError("max_iterations", "an integer in [1, 1000]", self.max_iterations)
        if not (isinstance(self.max_exclusions, int) and 0 <= self.max_exclusions <= 3):
            raise BadInputError("max_exclusions", "an integer in [0, 3]", self.max_exclusions)
        if self.fault_model not in ("bounded", "any"):
            raise BadInputError("fault_model", "'bounded' or 'any'", self.fault_model)
        if self.gradient not in ("auto", "off"):
            raise BadInputError("gradient", "'auto' or 'off'", self.gradient)
        if self.orientation not in ("fit", "fixed"):
            raise BadInputError("orientation", "'fit' or 'fixed'", self.orientation)
        if self.background not in ("uniform", "off"):
            raise BadInputError("background", "'uniform' or 'off'", self.background)
        if not isinstance(self.fit_moment_magnitude, bool):
            raise BadInputError("fit_moment_magnitude", "True or False",
                                self.fit_moment_magnitude)

    def relative_error_for(self, calibrated: bool) -> float:
        """The relative model error of a reading, with or without a calibration."""
        if self.relative_error is not None:
            return float(self.relative_error)
        return CALIBRATED_RELATIVE_ERROR if calibrated else UNCALIBRATED_RELATIVE_ERROR

    def model_bias_for(self, calibrated: bool) -> float:
        """The model-bias bound (m) added to the protection level."""
        if self.model_bias_m is not None:
            return float(self.model_bias_m)
        return 0.5e-3 if calibrated else 1e-3

    def model_bias_rad_for(self, calibrated: bool) -> float:
        """The moment direction's model-bias bound (rad) added to its protection level."""
        if self.model_bias_rad is not None:
            return float(self.model_bias_rad)
        return math.radians(0.5 if calibrated else 1.0)

    @property
    def variance_floor_t2(self) -> float:
        """noise_t^2 + lsb_t^2 / 12, T^2: a reading's variance per axis before model errors."""
        return self.noise_t ** 2 + self.lsb_t ** 2 / 12.0


POSITION_ONLY = EstimatorSettings(alert_limit_m=math.inf, orientation="fixed",
                                  fault_offset_t=0.0, fault_gain=0.0, background="off")
"""The position fit of a magnet whose direction is known (the thesis' upright magnet, the
estimators before the pose): no background, the fault-free protection level, no alert limit
(a caller applies its own)."""


MIN_SENSORS_FOR_POSE = 7
"""Fewest sensors whose frame the default settings fit the pose and the room with: after one
sensor is excluded, 3 (n - 1) readings for 8 unknowns (position, direction, background) leave
at least as many degrees of freedom as unknowns for the residual test to see a fault."""


def settings_for_layout(n_sensors: int) -> EstimatorSettings:
    """The default settings for a layout of ``n_sensors`` sensors: :class:`EstimatorSettings`
    (the pose, the uniform background, the bounded-fault protection) from
    :data:`MIN_SENSORS_FOR_POSE` sensors on. Below, the position alone with the map's moment
    direction and no background (3 unknowns), the same alert limits, and no undetected-fault
    term: so few sensors cannot bound one lying sensor's effect (each carries the fix), so
    ``ok`` then trusts every sensor's value (fault detection still excludes a gross liar)."""
    if n_sensors >= MIN_SENSORS_FOR_POSE:
        return EstimatorSettings()
    return EstimatorSettings(orientation="fixed", background="off", gradient="off",
                             fault_offset_t=0.0, fault_gain=0.0)
