"""MD10C current commands and the CoilDriver on two simulated PCA9685 boards.

Expected duties by hand from I = D Vs / R (sign-magnitude MD10C, Cytron MD10C user manual) with
D = counts / 4096, and the PCA9685 byte rules of its datasheet. Default wiring: coil k < 8 on board
0x40, PWM channel 2k, DIR channel 2k+1; coil 8 on board 0x41, channels 0 and 1. Positive current
-> DIR low (full-OFF bytes 00 00 00 10), negative -> DIR high (full-ON bytes 00 10 00 00).
"""

import pickle

import pytest

from firmware_io import CoilDrive, CoilDriver, CoilOutput, CoilWriteError, current_to_command
from firmware_io.hw.pca9685 import PCA9685
from firmware_io.errors import BadInputError
from firmware_io.hw.sim import SimBus, SimClock, SimPCA9685

LOW, HIGH, OFF = b"\x00\x00\x00\x10", b"\x00\x10\x00\x00", b"\x00\x00\x00\x10"


def duty_bytes(counts):
    return bytes([0, 0, counts & 0xFF, counts >> 8])


def test_current_to_command_by_hand():
    d = CoilDrive(supply_voltage_v=24.0, resistance_ohm=4.0, current_limit_a=5.0)
    # 1 A: D = 4/24 = 1/6 -> 682.67 -> 683 counts
    c = current_to_command(1.0, d)
    assert (c.duty_counts, c.direction, c.clamped) == (683, "forward", False)
    assert c.current_a == pytest.approx(683 / 4096 * 24 / 4)
    # -3 A: D = 0.5 -> 2048, reverse
    c = current_to_command(-3.0, d)
    assert (c.duty_counts, c.direction, c.pwm_value) == (2048, "reverse", 2048)
    # 7 A: clamped to the 5 A coil limit: D = 20/24 -> 3413.33 -> 3413
    c = current_to_command(7.0, d)
    assert (c.duty_counts, c.clamped) == (3413, True)
    # supply-limited: 12 V / 4 ohm = 3 A is D = 1 -> full ON
    c = current_to_command(-4.0, CoilDrive(12.0, 4.0, 5.0))
    assert (c.duty_counts, c.pwm_value, c.direction, c.clamped) == (4096, "on", "reverse", True)
    assert c.current_a == pytest.approx(-3.0)
    # driver rating: 30 V / 1 ohm could give 30 A, the MD10C's 13 A continuous caps it
    c = current_to_command(20.0, CoilDrive(30.0, 1.0, 13.0))
    assert c.duty_counts == round(13 / 30 * 4096) == 1775 and c.clamped
    assert current_to_command(0.0, d).pwm_value == "off"


@pytest.mark.parametrize("kwargs", [
    {"supply_voltage_v": -5.0, "resistance_ohm": 5.0, "current_limit_a": 6.0},
    {"supply_voltage_v": 24.0, "resistance_ohm": 0.0, "current_limit_a": 6.0},
    {"supply_voltage_v": 24.0, "resistance_ohm": 5.0, "current_limit_a": 14.0},  # > 13 A
    {"supply_voltage_v": float("nan"), "resistance_ohm": 5.0, "current_limit_a": 6.0},
])
def test_coil_drive_rejects_out_of_rating(kwargs):
    with pytest.raises(BadInputError):
        CoilDrive(**kwargs)


def make(kill_switch=None):
    clock = SimClock()
    bus = SimBus(clock=clock)
    sa, sb = bus.attach(SimPCA9685(0x40)), bus.attach(SimPCA9685(0x41))
    boards = [PCA9685(bus, 0x40, sleep=clock.sleep), PCA9685(bus, 0x41, sleep=clock.sleep)]
    driver = CoilDriver(boards, CoilDrive(24.0, 4.0, 5.0), sleep=clock.sleep, kill_switch=kill_switch)
    driver.initialize(1526)
    bus.clear_log()
    return bus, sa, sb, driver, clock


def test_nine_coil_command_mixed_signs_exact_bytes():
    bus, sa, sb, driver, _ = make()
    # counts: 1 A -> 683, 2 A -> 1365.33 -> 1365, 3 A -> 2048, 5 A -> 3413.33 -> 3413
    result = driver.command([1, -1, 2, -2, 0, 3, -3, 5, -5])
    assert len(bus.log) == 2  # one transaction per chip
    expected_a = bytes([0x06]) + b"".join([
        duty_bytes(683), LOW, duty_bytes(683), HIGH, duty_bytes(1365), LOW, duty_bytes(1365), HIGH,
        OFF, LOW,  # coil 4: no current, DIR left low
        duty_bytes(2048), LOW, duty_bytes(2048), HIGH, duty_bytes(3413), LOW,
    ])
    expected_b = bytes([0x06]) + duty_bytes(3413) + HIGH
    assert bus.writes_to(0x40) == [expected_a]
    assert bus.writes_to(0x41) == [expected_b]
    assert sa.duty(0) == 683 / 4096 and sa.level(3) == "high" and sa.level(1) == "low"
    assert sb.duty(0) == 3413 / 4096 and sb.level(1) == "high"
    assert result.current_a[8] == pytest.approx(-3413 / 4096 * 6.0)
    assert not result.clamped.any() and result.reversed_coils == ()
    assert bus.violations() == []


def test_reversal_is_sequenced():
    bus, sa, sb, driver, clock = make()
    driver.command([1, 0, 0, 0, 0, 0, 0, 0, 2])
    bus.clear_log()
    result = driver.command([-1, 0, 0, 0, 0, 0, 0, 0, 2])
    assert result.reversed_coils == (0,)
    writes = bus.writes_to(0x40)
    assert len(writes) == 2
    assert writes[0][:9] == bytes([0x06]) + OFF + HIGH     # PWM off + new DIR in one STOP
    assert writes[1] == bytes([0x06]) + duty_bytes(683)    # then the PWM
    t_first, t_second = (t.start_s for t in bus.log if t.messages[0].addr == 0x40)
    assert t_second - t_first >= 1 / 1525.87890625  # at least one PWM period with PWM off
    assert sa.level(1) == "high" and sa.duty(0) == 683 / 4096
    # zero current: no DIR toggle, no reversal
    bus.clear_log()
    assert driver.command([0] * 9).reversed_coils == ()
    assert sa.level(1) == "high"


def test_nack_during_coil_write_leaves_every_coil_off():
    bus, sa, sb, driver, _ = make()
    driver.command([1] * 9)
    sb.inject_nack(count=1)  # board B misses the next command; A already took it
    with pytest.raises(CoilWriteError) as info:
        driver.command([2, -2, 2, -2, 2, -2, 2, -2, 2])
    err = info.value
    assert isinstance(err, OSError) and err.errno == 121 and err.safe_state == "all_off_confirmed"
    assert "0x41" in str(err) and "switched off" in str(err)
    again = pickle.loads(pickle.dumps(err))  # errors cross process boundaries in runners
    assert (again.errno, again.safe_state, str(again)) == (121, "all_off_confirmed", str(err))
    assert all(sa.duty(n) == 0.0 for n in range(16)) and all(sb.duty(n) == 0.0 for n in range(16))
    assert bus.writes_to(0x40)[-1] == b"\xfd\x10" and bus.writes_to(0x41)[-1] == b"\xfd\x10"


def test_unconfirmed_safe_state_calls_kill_switch():
    calls = []
    bus, sa, sb, driver, _ = make(kill_switch=lambda: calls.append(1))
    driver.command([1] * 9)
    sb.nack_always = True
    with pytest.raises(CoilWriteError, match="NOT confirmed on 0x41") as info:
        driver.command([1] * 9)
    assert info.value.safe_state == "unconfirmed" and calls == [1]
    assert all(sa.duty(n) == 0.0 for n in range(16))


def test_bad_inputs():
    bus, sa, sb, driver, _ = make()
    with pytest.raises(BadInputError, match="currents_a"):
        driver.command([1] * 8)
    with pytest.raises(BadInputError, match="currents_a"):
        driver.command([float("nan")] * 9)
    boards = driver.boards
    with pytest.raises(BadInputError):
        CoilDriver(boards, CoilDrive(24, 4, 5), [CoilOutput(0, 0, 1), CoilOutput(0, 1, 2)])
    with pytest.raises(BadInputError):
        CoilDriver(boards, CoilDrive(24, 4, 5), [CoilOutput(2, 0, 1)])
