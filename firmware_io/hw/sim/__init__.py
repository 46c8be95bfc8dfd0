"""Simulated I2C bus with register-level models of the PCA9685, TLV493D-A1B6 and TCA9548A.

There is no hardware here, so firmware_io is built against these models. They follow the chips
at the level the drivers see (their datasheets, as in :mod:`firmware_io.hw`), one chip a module:
:class:`SimPCA9685` (:mod:`.pca9685`), :class:`SimTLV493D` (:mod:`.tlv493d`),
:class:`SimTCA9548A` (:mod:`.tca9548a`), on :class:`SimBus` (:mod:`.bus`) with the kernel side
of ``/dev/i2c-N`` in :class:`SimI2cDevFile` (:mod:`.i2c_dev`) for the real ``smbus2.SMBus``.
Faults are injected on the devices: :meth:`SimDevice.inject_nack`, ``SimTLV493D.stuck_frame``,
``SimTLV493D.reject_config``, a field beyond the range limit.
"""

from .bus import Message, SimAddressConflict, SimBus, SimClock, Transaction
from .device import SimDevice
from .i2c_dev import SimI2cDevFile
from .pca9685 import SimPCA9685
from .tca9548a import SimTCA9548A
from .tlv493d import SimTLV493D

__all__ = [
    "Message", "SimAddressConflict", "SimBus", "SimClock", "Transaction", "SimDevice",
    "SimI2cDevFile", "SimPCA9685", "SimTCA9548A", "SimTLV493D",
]
