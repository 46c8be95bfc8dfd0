"""The I2C hardware layer: the bus interface and one driver a chip.

:mod:`.bus` (the :class:`I2CBus` protocol, :func:`open_bus`, raw transfers, wire time),
:mod:`.pca9685` (PWM for the coil drivers), :mod:`.tca9548a` (I2C switch), :mod:`.tlv493d`
(3D Hall sensor), :mod:`.sensors` (every sensor behind the muxes, one flat list), :mod:`.driver`
(the coil driver named by its ratings, the MD10C the default: voltage -> duty and direction),
:mod:`.coils` (the coils' PWM and direction channels on the PCA9685 boards) and :mod:`.sim`
(register-level simulated chips and bus). Register maps and timing: docs/hardware.md.
"""

from .bus import I2CBus, open_bus
from .coils import CoilCommandResult, CoilDriver, CoilOutput, default_coil_wiring
from .driver import (MD10C, CoilDrive, DriveCommand, DriverRating, current_to_command,
                     voltage_to_command)
from .pca9685 import PCA9685, ChannelValue, pca9685_channel_bytes, pca9685_prescale
from .sensors import ArraysReading, SensorArrays, SensorSlot, default_sensor_layout
from .tca9548a import TCA9548A
from .tlv493d import (TLV493D, TLV493D_LINEAR_RANGE_T, TLV493D_LSB_T, FrameChecks, TLVFrame,
                      tlv493d_address, tlv493d_decode, tlv493d_write_frame)

__all__ = [
    "CoilCommandResult", "CoilDriver", "CoilOutput", "default_coil_wiring", "CoilDrive",
    "DriveCommand", "DriverRating", "MD10C", "current_to_command", "voltage_to_command",
    "I2CBus", "open_bus", "PCA9685", "ChannelValue", "pca9685_channel_bytes", "pca9685_prescale",
    "ArraysReading", "SensorArrays", "SensorSlot", "default_sensor_layout", "TCA9548A", "TLV493D",
    "TLV493D_LINEAR_RANGE_T", "TLV493D_LSB_T", "FrameChecks", "TLVFrame", "tlv493d_address",
    "tlv493d_decode", "tlv493d_write_frame",
]
