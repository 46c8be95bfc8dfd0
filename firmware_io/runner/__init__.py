"""The rendering runner: sensors -> position -> object force -> currents -> PWM, fail-safe.

Two sides. The sensor side (:mod:`.pipeline`, run by the sensor thread of
:mod:`firmware_io.run` and modelled with the same timing by designkit.sim) reads the two
sensor arrays, checks each sensor's health and fits the magnet's position, publishing a
:class:`Fix`. The control step (:mod:`.loop`, period T) never fits::

    newest Fix, if any (a frame ~2 bus passes old)                 [pipeline]
      -> Kalman update at the frame's time, prediction to now      [tracker]
      -> object force f at the predicted position                 [scene]
      -> currents: min ||F(p) I - (f - F0(p))|| within the bounds  [allocation, forcelaw, skip]
      -> voltages: R-L feed-forward within the supply; I^2 t guard [drive, thermal]
      -> MD10C duty/direction, one block write per PCA9685        [firmware_io.hw.coils]

Configuration: :mod:`.config`; start-up sensor calibration: :mod:`.calibration`. For the fault
table, the resume policy and the timing rationale see docs/runner.md. Imports numpy only (plus
the firmware_io drivers); the hardware entry point is ``python -m firmware_io.run``.
"""

from .calibration import (CALIBRATED_RELATIVE_ERROR, CALIBRATION_CURRENT_A, calibrate_sensors,
                          calibration_currents, record_calibration)
from .config import RunnerConfig, config_from_map
from .drive import CurrentPath, feedforward_voltage, rl_step
from .forcelaw import force_law_rows
from .loop import FAULTS, LOCALIZATION_FAULTS, Runner, RunnerParts, SceneForce, StepRecord
from .pipeline import (EXPECTED_SATURATION, SENSOR_FAULTS, CurrentHistory, Fix, SensorFrame,
                       SensorPipeline)
from .skip import CoilSkipBound
from .thermal import ThermalGuard
from .tracker import ConstantVelocityTracker

__all__ = [
    "CALIBRATED_RELATIVE_ERROR", "CALIBRATION_CURRENT_A", "calibrate_sensors",
    "calibration_currents", "record_calibration", "RunnerConfig", "config_from_map",
    "CurrentPath", "feedforward_voltage", "rl_step", "force_law_rows", "FAULTS",
    "LOCALIZATION_FAULTS", "Runner", "RunnerParts", "SceneForce", "StepRecord", "EXPECTED_SATURATION",
    "SENSOR_FAULTS", "CurrentHistory", "Fix", "SensorFrame", "SensorPipeline", "CoilSkipBound",
    "ThermalGuard", "ConstantVelocityTracker",
]
