"""TLV493D-A1B6 decode, parity, configuration and hang recovery.

Frames are built by hand from the register map of the Infineon TLV493D-A1B6 user manual: Bx = b0<<4 | b4>>4,
By = b1<<4 | b4&15, Bz = b2<<4 | b5&15, T = (b3&0xF0)<<4 | b6, 12-bit two's complement,
0.098 mT/LSB, FRM = b3 bits 3:2, CH = b3 bits 1:0, PD = b5 bit 4; T degC = (raw - 340) * 1.1 + 25.
Writes are [0x00, MOD1, byte8, MOD2] with an odd number of ones over the 32 bits.
"""

import pickle

import pytest

from firmware_io.hw.bus import raw_write

from firmware_io.hw.tlv493d import FrameChecks, TLV493D, tlv493d_address, tlv493d_decode, tlv493d_write_frame
from firmware_io.errors import BadInputError, I2CError, SensorConfigError
from firmware_io.hw.sim import SimBus, SimClock, SimTLV493D

LSB = 0.098e-3


def test_decode_positive_negative_and_temperature():
    # Bx = +100 = 0x064, By = -1 = 0xFFF, Bz = -300 = 0xED4, T = 340 = 0x154, FRM = 2, PD = 1
    frame = bytes([0x06, 0xFF, 0xED, 0x10 | (2 << 2), 0x4F, 0x10 | 0x4, 0x54, 0, 0, 0])
    f = tlv493d_decode(frame)
    assert (f.bx_raw, f.by_raw, f.bz_raw) == (100, -1, -300)
    assert f.field_t == pytest.approx((9.8e-3, -0.098e-3, -29.4e-3), rel=1e-12)
    assert f.frame_counter == 2 and f.channel == 0 and f.power_down_flag == 1 and f.test_flag == 0
    assert f.temperature_raw == 340 and f.temperature_c == pytest.approx(25.0)
    assert not f.saturated


def test_decode_range_limits():
    # +2047 = 0x7FF on X, -2048 = 0x800 on Y, 0 on Z; 6-byte read has no temperature
    f = tlv493d_decode(bytes([0x7F, 0x80, 0x00, 0x00, 0xF0, 0x10]))
    assert (f.bx_raw, f.by_raw, f.bz_raw) == (2047, -2048, 0)
    assert f.field_t[0] == pytest.approx(2047 * LSB) and f.field_t[1] == pytest.approx(-2048 * LSB)
    assert f.saturated and f.temperature_raw is None
    # temperature 400 = 0x190 -> (400 - 340) * 1.1 + 25 = 91 degC
    f = tlv493d_decode(bytes([0, 0, 0, 0x10, 0, 0x10, 0x90]))
    assert f.temperature_c == pytest.approx(91.0)
    with pytest.raises(BadInputError):
        tlv493d_decode(b"\x00" * 5)


FACTORY = bytes([0x8D, 0x85, 0x3A])  # bits 4:3 of 0x8D = 01 -> 0x08; 0x3A & 0x1F = 0x1A


@pytest.mark.parametrize("kwargs, factory, expected", [
    # MCM (FAST|LOW = 0x03) | 0x08; MOD2 = T(0x80)|PT(0x20)|0x1A = 0xBA
    # ones: 0x0B -> 3, 0x85 -> 3, 0xBA -> 5: 11, odd -> P = 0
    ({}, FACTORY, bytes([0x00, 0x0B, 0x85, 0xBA])),
    # IICAddr = 1 adds 0x20: 12 ones, even -> P = 1 -> 0x80 | 0x2B
    ({"iic_addr_code": 1}, FACTORY, bytes([0x00, 0xAB, 0x85, 0xBA])),
    # temperature on: MOD2 = 0x3A (4 ones): 3 + 3 + 4 = 10, even -> P = 1
    ({"temperature": "on"}, FACTORY, bytes([0x00, 0x8B, 0x85, 0x3A])),
    # zero factory bits: MOD1 0x03 (2), MOD2 0xA0 (2): 4, even -> P = 1
    ({}, bytes(3), bytes([0x00, 0x83, 0x00, 0xA0])),
    # IICAddr 3 (0x60) + MCM 0x03 + 0x08 = 0x6B (5 ones): 5 + 3 + 5 = 13, odd -> P = 0
    ({"iic_addr_code": 3}, FACTORY, bytes([0x00, 0x6B, 0x85, 0xBA])),
    # power-down, PT off: MOD1 0x08 (1), MOD2 0x9A (4): 1 + 3 + 4 = 8, even -> P = 1
    ({"mode": "power_down", "parity_test": "off"}, FACTORY, bytes([0x00, 0x88, 0x85, 0x9A])),
])
def test_parity_bit(kwargs, factory, expected):
    frame = tlv493d_write_frame(factory, **kwargs)
    assert frame == expected
    assert bin(int.from_bytes(frame, "big")).count("1") % 2 == 1


def test_address_table():
    # UM Table 6
    assert [tlv493d_address(0x5E, a) for a in range(4)] == [0x5E, 0x5A, 0x4E, 0x4A]
    assert [tlv493d_address(0x1F, a) for a in range(4)] == [0x1F, 0x1B, 0x0F, 0x0B]
    with pytest.raises(BadInputError, match="address"):
        TLV493D(SimBus(), 0x40)


def make(address=0x5E, field=(0.01, -0.02, 0.03), **kw):
    clock = SimClock()
    bus = SimBus(clock=clock)
    sensor = bus.attach(SimTLV493D(field_t=field))
    return bus, sensor, TLV493D(bus, address, sleep=clock.sleep, **kw), clock


def test_configure_exact_bytes_on_the_wire():
    bus, sim, tlv, clock = make()
    tlv.configure()
    msgs = [(m.op, m.addr, m.data, t.error) for t in bus.log for m in t.messages]
    assert msgs[0] == ("w", 0x00, b"\xff", 121)   # general-call reset, SDA high, NACK expected
    assert msgs[1][:2] == ("r", 0x5E) and len(msgs[1][2]) == 10 and msgs[1][2][7:] == FACTORY
    assert msgs[2] == ("w", 0x5E, bytes([0x00, 0x0B, 0x85, 0xBA]), None)
    assert [(op, a, len(d)) for op, a, d, _ in msgs[3:]] == [("r", 0x5E, 6), ("r", 0x5E, 6)]
    assert sim.mode == "master_controlled" and sim.violations == []
    assert tlv.status == "ok"
    # the 40 ms wait after the reset happened on the simulated clock
    assert bus.log[1].start_s - bus.log[0].start_s >= 40e-3


def test_read_values_and_frame_counter_advances():
    bus, sim, tlv, _ = make(field=(0.0123, -0.0456, 0.1))
    tlv.configure()
    counters = []
    for _ in range(5):
        b = tlv.read()
        assert tlv.status == "ok"
        counters.append(tlv.last_frame.frame_counter)
    expected = tuple(round(v / LSB) * LSB for v in (0.0123, -0.0456, 0.1))
    assert b == pytest.approx(expected, abs=1e-12)
    assert all((b - a) % 4 == 1 for a, b in zip(counters, counters[1:]))


def test_value_at_range_limit_is_flagged():
    bus, sim, tlv, _ = make(field=(0.25, -0.3, 0.0))
    tlv.configure()
    b = tlv.read()
    assert tlv.status == "saturated"
    assert b[0] == pytest.approx(2047 * LSB) and b[1] == pytest.approx(-2048 * LSB)


def test_address_assignment_and_low_reset_level():
    bus, sim, tlv, _ = make(address=0x5A)
    tlv.configure()
    assert sim.address == 0x5A
    assert bus.writes_to(0x5E)[-1][1] & 0x60 == 0x20  # IICAddr = 01 written to the base address
    tlv.read()
    assert bus.log[-1].messages[0].addr == 0x5A
    # a sensor whose reset level is low lives at 0x1F: the reset data byte is 0x00
    bus2, sim2, tlv2, _ = make(address=0x1F)
    assert sim2.base_address == 0x5E  # power-up level high; the reset re-latches it low
    tlv2.configure()
    assert bus2.writes_to(0x00)[0] == b"\x00" and sim2.address == 0x1F and tlv2.status == "ok"


def test_recovery_from_stuck_frame_counter():
    bus, sim, tlv, _ = make(checks=FrameChecks(hang_reads=3))
    tlv.configure()
    tlv.read()
    resets_before = sim.resets
    sim.stuck_frame = True
    statuses = [tlv.read() and tlv.status for _ in range(4)]
    # the first read still shows the conversion made before the hang; then the counter freezes
    assert statuses == ["ok", "stale", "stale", "recovered"]
    assert sim.resets == resets_before + 1 and not sim.stuck_frame
    assert sim.mode == "master_controlled"
    sim.field_t = (0.0, 0.0, -0.05)
    tlv.read()
    b = tlv.read()
    assert tlv.status == "ok" and b[2] == pytest.approx(round(-0.05 / LSB) * LSB)
    assert tlv.recoveries == 1


def test_parity_rejected_config_is_retried_then_reported():
    bus, sim, tlv, _ = make()
    sim.reject_config = 1  # first write rejected, as if parity were wrong
    tlv.configure()
    assert tlv.status == "ok" and sim.parity_rejections == 1 and sim.resets == 2
    bus2, sim2, tlv2, _ = make()
    sim2.reject_config = 99
    with pytest.raises(SensorConfigError, match="did not take its configuration"):
        tlv2.configure()
    assert tlv2.status == "failed"


def test_sim_rejects_wrong_parity():
    bus, sim, _, _ = make()
    good = tlv493d_write_frame(FACTORY)
    bad = bytes([good[0], good[1] ^ 0x80, good[2], good[3]])
    raw_write(bus, 0x5E, bad)
    assert sim.mode == "power_down" and sim.parity_rejections == 1
    raw_write(bus, 0x5E, good)
    assert sim.mode == "master_controlled"


def test_not_ready_and_nack():
    bus, sim, tlv, _ = make()
    tlv.configure()
    sim.busy_reads = 1
    tlv.read()
    assert tlv.status == "not_ready"
    sim.inject_nack()
    with pytest.raises(I2CError) as info:
        tlv.read()
    assert info.value.errno == 121 and tlv.status == "nack"
    err = pickle.loads(pickle.dumps(info.value))
    assert err.errno == 121 and str(err) == str(info.value)


def test_temperature_on_reads_seven_bytes():
    bus, sim, tlv, _ = make(temperature="on")
    sim.temperature_raw = 350
    tlv.configure()
    tlv.read()
    assert len(bus.log[-1].messages[0].data) == 7
    assert tlv.temperature_c == pytest.approx((350 - 340) * 1.1 + 25)


# ---------------------------------------------------------------------------------------------
# values a sensor reports with an ok frame: frozen, all zero


def _frame_bytes(bx, by, bz, frm, pd=1, ff=1):
    """The six bytes a TLV493D sends for 12-bit values bx, by, bz (temperature off: its nibble
    and byte 6 are 0), frame counter ``frm``, channel 0 [UM register map]."""
    x, y, z = (v & 0xFFF for v in (bx, by, bz))
    return bytes([x >> 4, y >> 4, z >> 4, frm << 2, (x & 0xF) << 4 | (y & 0xF),
                  ff << 5 | pd << 4 | (z & 0xF)])


def test_frame_bytes_by_hand():
    # 12.3 mT -> 125.5 -> 126 = 0x07E; -45.6 mT -> -465.3 -> -465 = 0xE2F; 100 mT -> 1020 = 0x3FC
    assert _frame_bytes(126, -465, 1020, 2) == bytes([0x07, 0xE2, 0x3F, 0x08, 0xEF, 0x3C])


def test_frozen_values_with_a_live_frame_counter_are_reported():
    """The chip keeps converting (the frame counter advances) but repeats its values: 'ok' for
    frozen_reads - 1 repeats, 'frozen' from the frozen_reads-th (8 by default). The read before
    the fault already showed these values, so the 8th read after it is the 8th repeat."""
    bus, sim, tlv, _ = make(field=(0.0123, -0.0456, 0.1))
    tlv.configure()
    tlv.read()
    sim.value_fault = "frozen"
    sim.field_t = (0.02, 0.02, 0.02)     # the field changes; the chip does not say so
    statuses, frames = [], []
    for _ in range(10):
        tlv.read()
        statuses.append(tlv.status)
        frames.append(bus.log[-1].messages[0].data)
    assert statuses == ["ok"] * 7 + ["frozen"] * 3
    counters = [(f[3] >> 2) & 3 for f in frames]
    assert all((b - a) % 4 == 1 for a, b in zip(counters, counters[1:]))   # live counter
    for f, frm in zip(frames, counters):
        assert f == _frame_bytes(126, -465, 1020, frm)
    assert FrameChecks().frozen_reads == 8


def test_all_zero_values_are_reported_after_zero_reads():
    bus, sim, tlv, _ = make(field=(0.0123, -0.0456, 0.1))
    tlv.configure()
    tlv.read()
    sim.value_fault = "zero"
    statuses = []
    for _ in range(7):
        tlv.read()
        statuses.append(tlv.status)
    # the first read returns the conversion made before the fault; then five zero frames
    assert statuses == ["ok"] * 5 + ["zero"] * 2
    frm = (bus.log[-1].messages[0].data[3] >> 2) & 3
    assert bus.log[-1].messages[0].data == _frame_bytes(0, 0, 0, frm)
    # the checks can be switched off (a test bench with a constant, noise-free field)
    bus2, sim2, tlv2, _ = make(checks=FrameChecks(frozen_reads=0, zero_reads=0))
    tlv2.configure()
    sim2.value_fault = "zero"
    for _ in range(20):
        tlv2.read()
    assert tlv2.status == "ok"


def test_a_healthy_sensor_with_datasheet_noise_is_not_flagged():
    """0.1 mT rms noise (about one LSB) in a zero field and in a constant one, 3000 reads each:
    never 'frozen' nor 'zero' (by chance: ~1e-3 and ~1e-11 per read window); a sensor at
    frozen_reads = 2 would be."""
    import numpy as np

    rng = np.random.default_rng(1)
    for field in ((0.0, 0.0, 0.0), (0.01, -0.02, 0.03)):
        bus, sim, tlv, _ = make()
        sim.field_source = lambda f=field: np.asarray(f) + rng.normal(scale=1e-4, size=3)
        tlv.configure()
        seen = {tlv.read() and tlv.status for _ in range(3000)}
        assert seen == {"ok"}, seen
    bus, sim, tlv, _ = make(checks=FrameChecks(frozen_reads=2))
    sim.field_source = lambda: np.array([0.0, 0.0, 0.0]) + rng.normal(scale=1e-4, size=3)
    tlv.configure()
    assert "frozen" in {tlv.read() and tlv.status for _ in range(3000)}


def test_frame_checks_refuse_bad_debounces():
    with pytest.raises(BadInputError, match="hang_reads"):
        FrameChecks(hang_reads=0)
    with pytest.raises(BadInputError, match="frozen_reads"):
        FrameChecks(frozen_reads=-1)
    with pytest.raises(BadInputError, match="checks"):
        TLV493D(SimBus(), 0x5E, checks=3)
