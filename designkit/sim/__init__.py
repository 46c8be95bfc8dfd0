"""The simulated device, so that firmware_io's runner can be closed around it end to end.

What is simulated, and from what:

* the finger: a scripted trajectory (:mod:`.trajectory`: ``slide`` over the object as in
  thesis Fig. 4.5, ``poke`` down into it, ``tilt`` (a slide with the magnet tilting up to 45
  degrees), or a CSV file with columns ``t_s, x_m, y_m, z_m`` and optionally ``tilt_deg,
  azimuth_deg``);
* the true force on the magnet: designkit's array model evaluated directly at the true pose
  (position and tilted moment, + the magnet's pull on the cores when the model has it), never
  the map, so that the map's, the estimator's and the allocator's errors show up in the result
  (:mod:`.device`, :mod:`.samples`);
* the coil currents: each coil an R-L circuit driven by the voltage its driver applies from the
  drive record's supply (the design's), read back from the simulated PCA9685 registers, so the
  bytes the runner wrote are what moves the current;
* the sensors: register-level TLV493D models behind TCA9548A muxes on their own simulated bus,
  whose wire-time model sets when a frame is complete (:mod:`.sensors`);
* faults on a schedule (:mod:`.faults`), injected on the simulated devices.

The loop is :mod:`.loop`, what a run says :mod:`.report` and :mod:`.plot`, the whole
``designkit run --simulate`` :mod:`.run`.
"""

from .device import SimulatedDevice
from .faults import FAULT_TYPES, FaultSchedule, inject
from .loop import LoopTiming, SimulationResult, simulate
from .plot import plot_run
from .report import (force_error_causes, force_lag_s, loop_by_kind, loop_by_state, summarize,
                     time_to_safe, write_run_csv)
from .run import RunSettings, drive_data, run_simulation
from .sensors import SimSensorSource
from .trajectory import (TILT_COLUMNS, TRAJECTORY_COLUMNS, Trajectory, poke_trajectory,
                         slide_trajectory, tilt_trajectory, tilted_direction)

__all__ = [
    "SimulatedDevice", "FAULT_TYPES", "FaultSchedule", "inject",
    "LoopTiming", "SimulationResult", "simulate", "plot_run", "force_error_causes", "force_lag_s",
    "loop_by_kind", "loop_by_state", "summarize", "time_to_safe", "write_run_csv", "drive_data",
    "RunSettings", "run_simulation", "SimSensorSource", "TILT_COLUMNS", "TRAJECTORY_COLUMNS",
    "Trajectory", "poke_trajectory", "slide_trajectory", "tilt_trajectory", "tilted_direction",
]
