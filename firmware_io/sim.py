# SHIM: old path, removed at integration
from .hw.sim import (Message, SimAddressConflict, SimBus, SimClock, SimDevice,  # noqa: F401
                     SimI2cDevFile, SimPCA9685, SimTCA9548A, SimTLV493D, Transaction)
