"""The rendering runner: sensors -> pose -> object force -> currents -> PWM, fail-safe.

Two sides. The sensor side (:mod:`.pipeline`, run by the sensor thread of
:mod:`firmware_io.run` and modelled with the same timing by designkit.sim) reads every sensor,
checks each sensor's health and headroom and runs the pose estimator, publishing a
:class:`Fix`. The control step (:mod:`.loop`, period T) never fits::

    newest Fix, if any (a frame ~2 bus passes old)                 [pipeline, frames]
      -> innovation gate, Kalman update at the frame's time, predict [gate, tracker]
      -> object force f at the predicted position                 [scene]
      -> currents: min ||F(p, m) I - (f - F0(p))|| within the bounds [forcelaw, allocation,
         (+ the scene's sensor headroom), torque m x B reported       headroom, skip]
      -> voltages: R-L feed-forward within the supply; I^2 t guard [drive, thermal]
      -> driver duty/direction, one block write per PCA9685       [firmware_io.hw.coils]

N magnets (:mod:`.magnets_loop`, :mod:`.magnets_pipeline`, :mod:`.magnets_force`): one track
per magnet, each its own contact, one allocation of the stacked rows with the magnets' pull on
each other compensated; any magnet untrusted switches every coil off.

Configuration: :mod:`.config`; start-up sensor calibration: :mod:`.calibration`; sensor fault
names and the exclusion latch: :mod:`.sensor_faults`. For the fault table, the resume policy
and the timing rationale see docs/runner.md. Imports numpy only (plus the firmware_io
drivers); the hardware entry point is ``python -m firmware_io.run``.
"""

from .calibration import (CALIBRATED_RELATIVE_ERROR, CALIBRATION_CURRENT_A, calibrate_sensors,
                          calibration_currents, record_calibration)
from .config import RunnerConfig, config_from_map
from .drive import CurrentPath, feedforward_voltage, rl_step
from .forcelaw import force_law_matrix, force_law_rows, torque_matrix
from .frames import Fix, SensorFrame
from .gate import InnovationGate, rendered_protection_level
from .headroom import EXPECTED_SATURATION, SensorHeadroom, SensorLayout, expected_saturation
from .history import CurrentHistory
from .loop import FAULTS, LOCALIZATION_FAULTS, Runner, RunnerIO, SceneForce, StepRecord
from .magnets_force import condition_number, magnet_weights, stacked_rows
from .magnets_loop import MagnetLane, MagnetsRunner, MagnetsSettings, MagnetsStepRecord
from .magnets_pipeline import MagnetsFix, MagnetsPipeline
from .pipeline import SensorPipeline
from .sensor_faults import FDE_LATCH_PASSES, SENSOR_FAULTS, ExclusionLatch
from .skip import CoilSkipBound, gradient_norm
from .thermal import ThermalGuard
from .tracker import PoseTracker

__all__ = [
    "CALIBRATED_RELATIVE_ERROR", "CALIBRATION_CURRENT_A", "calibrate_sensors",
    "calibration_currents", "record_calibration", "RunnerConfig", "config_from_map",
    "CurrentPath", "feedforward_voltage", "rl_step", "force_law_matrix", "force_law_rows",
    "torque_matrix", "Fix", "SensorFrame",
    "InnovationGate", "rendered_protection_level", "EXPECTED_SATURATION", "SensorHeadroom",
    "SensorLayout", "expected_saturation", "CurrentHistory", "FAULTS", "LOCALIZATION_FAULTS",
    "Runner", "RunnerIO", "SceneForce", "StepRecord", "SensorPipeline", "FDE_LATCH_PASSES",
    "SENSOR_FAULTS", "ExclusionLatch", "CoilSkipBound", "gradient_norm", "ThermalGuard",
    "PoseTracker", "condition_number", "magnet_weights", "stacked_rows", "MagnetLane",
    "MagnetsRunner", "MagnetsSettings", "MagnetsStepRecord", "MagnetsFix", "MagnetsPipeline",
]
