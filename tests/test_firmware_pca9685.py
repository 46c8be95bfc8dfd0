"""PCA9685 driver against the register-level simulated chip.

Expected bytes come from the NXP PCA9685 datasheet (rev. 4, sections 7.3-7.3.5), written out by
hand here: PRE_SCALE = round(25 MHz / (4096 f)) - 1, channel bytes [ON_L, ON_H, OFF_L, OFF_H],
full ON = ON_H bit 4, full OFF = OFF_H bit 4, LED0_ON_L = 0x06, ALL_LED_OFF_H = 0xFD.
"""

import pytest

from firmware_io.hw.pca9685 import PCA9685, pca9685_prescale
from firmware_io.errors import BadInputError, I2CError
from firmware_io.hw.sim import SimAddressConflict, SimBus, SimClock, SimPCA9685, SimTCA9548A


def make(address=0x40):
    clock = SimClock()
    bus = SimBus(clock=clock)
    chip = bus.attach(SimPCA9685(address))
    return bus, chip, PCA9685(bus, address, sleep=clock.sleep), clock


# datasheet table: p=3 -> 1525.9 Hz (max), p=5 -> 1017 Hz, p=30 (0x1E) -> 197 Hz
@pytest.mark.parametrize("hz, prescale", [(1526, 0x03), (1000, 0x05), (200, 0x1E)])
def test_set_pwm_frequency_exact_bytes_and_register(hz, prescale):
    bus, chip, pca, _ = make()
    pca.initialize(1000)
    bus.clear_log()
    actual = pca.set_pwm_frequency(hz)
    # read MODE1 (0x20 after init), SLEEP|AI, PRE_SCALE, wake with AI, RESTART|AI
    assert [(m.op, m.addr, m.data) for t in bus.log for m in t.messages] == [
        ("w", 0x40, b"\x00"), ("r", 0x40, b"\x20"),
        ("w", 0x40, b"\x00\x30"),
        ("w", 0x40, bytes([0xFE, prescale])),
        ("w", 0x40, b"\x00\x20"),
        ("w", 0x40, b"\x00\xa0"),
    ]
    assert chip.regs[0xFE] == prescale
    assert chip.regs[0x00] == 0x20  # awake, AI, RESTART cleared, ALLCALL off
    assert actual == pytest.approx(25e6 / (4096 * (prescale + 1)), rel=1e-12)
    assert bus.violations() == []


def test_prescale_formula_values():
    assert pca9685_prescale(1526) == 3
    assert pca9685_prescale(1000) == 5
    assert pca9685_prescale(200) == 30
    assert pca9685_prescale(24) == 253  # round(254.3) - 1
    with pytest.raises(BadInputError, match="hz"):
        pca9685_prescale(5000)
    with pytest.raises(BadInputError, match="hz"):
        pca9685_prescale(float("nan"))


def test_initialize_sequence_clears_allcall_and_turns_all_off():
    bus, chip, pca, _ = make()
    assert chip.responds_to(0x70)  # power-up: All-Call on
    pca.initialize(1526)
    assert bus.writes_to(0x40) == [b"\x00\x30", b"\xfe\x03", b"\x01\x04", b"\xfd\x10", b"\x00\x20", b"\x00\xa0"]
    assert not chip.responds_to(0x70)
    assert all(chip.duty(n) == 0.0 for n in range(16))
    assert chip.frequency_hz == pytest.approx(1525.87890625)


def test_allcall_conflicts_with_mux_at_0x70_until_cleared():
    bus = SimBus()
    chip = bus.attach(SimPCA9685(0x40))
    bus.attach(SimTCA9548A(0x70))
    with pytest.raises(SimAddressConflict):
        bus.write_byte(0x70, 0x01)
    PCA9685(bus, 0x40, sleep=lambda s: None).initialize()
    bus.write_byte(0x70, 0x01)  # only the mux answers now
    assert not chip.responds_to(0x70)


def test_set_channels_exact_bytes_one_transaction():
    bus, chip, pca, _ = make()
    pca.initialize()
    bus.clear_log()
    pca.set_channels({0: 2048, 1: "on", 2: "off", 3: 1, 4: 4095})
    assert len(bus.log) == 1
    assert bus.log[0].messages[0].data == bytes([
        0x06,
        0x00, 0x00, 0x00, 0x08,   # 2048 = 0x800
        0x00, 0x10, 0x00, 0x00,   # full ON
        0x00, 0x00, 0x00, 0x10,   # full OFF
        0x00, 0x00, 0x01, 0x00,   # 1
        0x00, 0x00, 0xFF, 0x0F,   # 4095 = 0xFFF
    ])
    assert chip.duty(0) == 0.5 and chip.duty(1) == 1.0 and chip.duty(2) == 0.0
    assert chip.duty(3) == 1 / 4096 and chip.duty(4) == 4095 / 4096


def test_more_than_32_bytes_uses_i2c_rdwr_in_one_transaction():
    bus, chip, pca, _ = make()
    pca.initialize()
    bus.clear_log()
    pca.set_channels({n: 100 * (n + 1) for n in range(16)})
    assert len(bus.log) == 1 and bus.log[0].api == "i2c_rdwr"
    data = bus.log[0].messages[0].data
    assert len(data) == 65 and data[0] == 0x06
    for n in range(16):
        d = 100 * (n + 1)
        assert chip.channel_bytes(n) == bytes([0, 0, d & 0xFF, d >> 8])
    # <= 32 data bytes: plain SMBus block write, same bytes on the wire
    bus.clear_log()
    pca.set_channels({14: 5, 15: "on"})
    assert bus.log[0].api == "write_i2c_block_data"
    assert bus.log[0].messages[0].data == bytes([0x06 + 4 * 14, 0, 0, 5, 0, 0, 0x10, 0, 0])


def test_gap_channels_keep_their_last_value():
    bus, chip, pca, _ = make()
    pca.initialize()
    pca.set_channels({1: 700})
    pca.set_channels({0: 5, 2: 6})  # channel 1 inside the span: rewritten unchanged
    assert chip.channel_bytes(1) == bytes([0, 0, 700 & 0xFF, 700 >> 8])


def test_outputs_change_only_at_stop_and_all_off():
    bus, chip, pca, _ = make()
    pca.initialize()
    pca.set_channels({3: 1000})
    bus.clear_log()
    pca.all_off()
    assert bus.writes_to(0x40) == [b"\xfd\x10"]
    assert all(chip.duty(n) == 0.0 for n in range(16))


def test_sim_prescale_ignored_when_awake_and_auto_increment_wraps():
    bus, chip, pca, _ = make()
    pca.initialize(1526)
    bus.write_byte_data(0x40, 0xFE, 0x40)
    assert chip.regs[0xFE] == 0x03
    assert any("PRE_SCALE" in v for v in bus.violations())
    # AI: LED15_OFF_H is 0x45; the next byte lands in MODE1 (0x00)
    bus.write_i2c_block_data(0x40, 0x44, [0x00, 0x10, 0x21])
    assert chip.regs[0x45] == 0x10 and chip.regs[0x00] == 0x21


def test_restart_needs_500us_after_wake():
    bus, chip, _, clock = make()
    PCA9685(bus, 0x40, sleep=clock.sleep).initialize(1526)
    PCA9685(bus, 0x40, sleep=clock.sleep).set_channels({0: 100})
    assert bus.violations() == []
    hasty = PCA9685(bus, 0x40, sleep=lambda s: None)
    hasty.set_pwm_frequency(1000)
    assert any("500 us" in v for v in bus.violations())


def test_nack_raises_i2c_error_with_errno_121():
    bus, chip, pca, _ = make()
    pca.initialize()
    chip.inject_nack()
    with pytest.raises(I2CError, match="0x40") as info:
        pca.set_channels({0: 1})
    assert info.value.errno == 121 and isinstance(info.value, OSError)


@pytest.mark.parametrize("bad", [{16: 1}, {0: 4096}, {0: -1}, {0: "half"}, {}, {0: True}])
def test_bad_channel_values(bad):
    _, _, pca, _ = make()
    with pytest.raises(BadInputError):
        pca.set_channels(bad)
