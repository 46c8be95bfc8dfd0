"""firmware_io: the I2C layer between a rendering runner and the EHI hardware.

PCA9685 PWM boards drive one sign-magnitude coil driver per coil (PWM + DIR; the design names
it by its ratings, the Cytron MD10C by default); two arrays of TLV493D-A1B6 Hall sensors sit
behind TCA9548A muxes. Needs only numpy, plus smbus2 for a
real bus (imported lazily). Nothing here imports designkit.

Main entry points::

    from firmware_io import open_bus, CoilDriver, CoilDrive, SensorArrays
    from firmware_io.hw import PCA9685, TLV493D, TCA9548A
    from firmware_io.hw.sim import SimBus       # register-level simulated devices
"""

from .errors import BadInputError, CoilWriteError, FirmwareIOError, I2CError, SensorConfigError
from .hw import (PCA9685, TCA9548A, TLV493D, ArraysReading, CoilCommandResult, CoilDrive,
                 CoilDriver, CoilOutput, DriveCommand, I2CBus, SensorArrays, SensorSlot,
                 current_to_command, default_coil_wiring, default_sensor_layout, open_bus,
                 voltage_to_command)

__all__ = [
    "I2CBus", "open_bus", "CoilDriver", "CoilOutput", "CoilCommandResult", "default_coil_wiring",
    "PCA9685", "TCA9548A", "TLV493D", "BadInputError", "CoilWriteError", "FirmwareIOError",
    "I2CError", "SensorConfigError", "CoilDrive", "DriveCommand", "current_to_command",
    "voltage_to_command",
    "ArraysReading", "SensorArrays", "SensorSlot", "default_sensor_layout",
]
