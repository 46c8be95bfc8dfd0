"""TCA9548A driver and routing model [TI SCPS207F]: one control register, bit n = channel n,
the new mask connects only after STOP, enabled channels share the upstream address space."""

import pytest

from firmware_io.hw.bus import i2c_msg_class
from firmware_io.hw.tca9548a import TCA9548A
from firmware_io.errors import BadInputError, I2CError
from firmware_io.hw.sim import SimAddressConflict, SimBus, SimTCA9548A, SimTLV493D


def make():
    bus = SimBus()
    mux = bus.attach(SimTCA9548A(0x71))
    a = mux.attach(2, SimTLV493D())
    b = mux.attach(5, SimTLV493D())
    return bus, mux, a, b


def test_select_writes_one_bit_and_is_cached():
    bus, mux, _, _ = make()
    tca = TCA9548A(bus)
    assert tca.address == 0x71
    tca.select(5)
    tca.select(5)
    tca.select(2)
    tca.disable()
    assert bus.writes_to(0x71) == [b"\x20", b"\x04", b"\x00"]
    assert mux.mask == 0
    tca.invalidate()
    tca.disable()
    assert bus.writes_to(0x71)[-1] == b"\x00" and len(bus.writes_to(0x71)) == 4
    tca.select_mask(0x84)
    assert tca.read_mask() == 0x84


def test_routing_only_after_stop():
    bus, mux, _, _ = make()
    M = i2c_msg_class()
    # select + sensor read in one repeated-start transaction: the sensor is not connected yet
    with pytest.raises(OSError) as info:
        bus.i2c_rdwr(M.write(0x71, [0x04]), M.read(0x5E, 6))
    assert info.value.errno == 121
    assert mux.mask == 0x04  # the STOP after the NACK applied the mask
    msg = M.read(0x5E, 6)
    bus.i2c_rdwr(msg)
    assert len(bytes(msg)) == 6


def test_two_same_address_sensors_enabled_is_an_error():
    bus, mux, _, _ = make()
    TCA9548A(bus).select_mask((1 << 2) | (1 << 5))
    with pytest.raises(SimAddressConflict, match="0x5E"):
        bus.read_byte(0x5E)


def test_nack_drops_cache_and_bad_inputs():
    bus, mux, _, _ = make()
    tca = TCA9548A(bus)
    tca.select(1)
    mux.inject_nack()
    with pytest.raises(I2CError, match="TCA9548A at 0x71"):
        tca.select(3)
    assert tca.mask is None
    tca.select(1)  # rewritten although it was the last good mask
    assert bus.writes_to(0x71)[-1] == b"\x02"
    with pytest.raises(BadInputError):
        tca.select(8)
    with pytest.raises(BadInputError):
        TCA9548A(bus, 0x40)
