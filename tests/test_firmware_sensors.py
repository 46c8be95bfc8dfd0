"""SensorArrays over three simulated TCA9548A muxes with 18 TLV493D (all at 0x5E).

Any moment with two sensors of one address connected would raise SimAddressConflict, so these
tests also check that only one mux channel is ever enabled.
"""

import subprocess
import sys

import numpy as np
import pytest

from firmware_io import SensorArrays, SensorSlot
from firmware_io.hw.tlv493d import FrameChecks
from firmware_io.errors import BadInputError
from firmware_io.hw.sim import SimBus, SimClock, SimTCA9548A, SimTLV493D

LSB = 0.098e-3


NO_VALUE_CHECKS = FrameChecks(frozen_reads=0, zero_reads=0)
"""These tests hold each sensor's field constant and noise-free, which the frozen-value check
would rightly flag; its own tests turn it on."""


def make(**kw):
    kw.setdefault("checks", NO_VALUE_CHECKS)
    clock = SimClock()
    bus = SimBus(clock=clock)
    muxes = [bus.attach(SimTCA9548A(0x71 + k)) for k in range(3)]
    fields = np.array([[1e-3 * i, -2e-3 * i, 0.05 - 4e-3 * i] for i in range(18)])
    sims = [muxes[i // 8].attach(i % 8, SimTLV493D(field_t=fields[i])) for i in range(18)]
    arrays = SensorArrays(bus, sleep=clock.sleep, clock=clock.now, **kw)
    return bus, muxes, sims, arrays, fields


def test_reads_every_sensor_in_tesla():
    bus, muxes, sims, arrays, fields = make()
    assert arrays.configure() == ("ok",) * 18
    assert all(s.resets == 1 for s in sims)  # each reset reached its own sensor only
    r = arrays.read()
    expected = np.round(fields / LSB) * LSB  # 0.098 mT quantisation
    assert r.field_t.shape == (18, 3)
    np.testing.assert_allclose(r.field_t, expected, atol=1e-12)
    assert r.healthy.all() and r.status == ("ok",) * 18
    assert bus.violations() == []


def test_one_loop_transactions():
    bus, muxes, sims, arrays, _ = make()
    arrays.configure()
    arrays.read()
    bus.clear_log()
    arrays.read()
    addrs = [t.messages[0].addr for t in bus.log]
    # 18 six-byte reads; 18 selects + 3 disables when moving from one mux to the next
    assert addrs.count(0x5E) == 18 and len(addrs) == 18 + 18 + 3
    assert all(len(t.messages[0].data) == 6 for t in bus.log if t.messages[0].addr == 0x5E)


def test_health_stuck_nack_and_saturation():
    bus, muxes, sims, arrays, fields = make(checks=FrameChecks(hang_reads=3, frozen_reads=0, zero_reads=0))
    arrays.configure()
    first = arrays.read()
    sims[4].stuck_frame = True
    sims[10].nack_always = True
    sims[15].field_t = (0.0, 0.0, 0.5)  # beyond the range limit
    statuses4, statuses10 = [], []
    for _ in range(5):
        r = arrays.read()
        statuses4.append(r.status[4])
        statuses10.append(r.status[10])
    # the frozen counter, debounced by the sensor: 'hung' until its reset's wake-up is over
    # (test_a_hung_sensor_is_reset_between_passes: when it recovers)
    assert statuses4 == ["ok", "stale", "stale", "hung", "hung"]
    # the NACKing sensor is reset after hang_reads NACKs and configured in later passes,
    # after the reset's wake-up: missing meanwhile (test_a_nacking_sensor_...: when it fails)
    assert statuses10 == ["nack"] * 5
    np.testing.assert_allclose(r.field_t[10], first.field_t[10])  # last good value kept
    assert r.status[15] == "saturated" and r.field_t[15][2] == pytest.approx(2047 * LSB)
    assert not r.healthy[10] and not r.healthy[15] and not r.healthy[4]
    assert np.isfinite(r.field_t).all()
    # failed sensor comes back when it answers again (retry interval, then the reset's wait)
    sims[10].nack_always = False
    for _ in range(arrays.retry_interval + 50):
        r = arrays.read()
    assert r.status[10] == "ok"


def _configured_and_timed():
    """(bus, sims, arrays, seconds of one healthy pass on the simulated clock) after one
    configuration and one read, hang_reads 3."""
    bus, _, sims, arrays, _ = make(checks=FrameChecks(hang_reads=3, frozen_reads=0, zero_reads=0))
    arrays.configure()
    arrays.read()
    t0 = bus.clock.now()
    arrays.read()
    return bus, sims, arrays, bus.clock.now() - t0


def test_a_hung_sensor_is_reset_between_passes():
    """Sensor 4's frame counter freezes (ADC hang-up): 'stale' for hang_reads - 1 reads,
    'hung' from the hang_reads-th, then one general-call reset sent in that pass and the
    configuration in the first pass at least reset_wait_s later ('recovered'), then fresh
    values ('ok'). No pass waits the reset's wake-up, the other 17 keep reading fresh values,
    and the sensor counts one recovery."""
    bus, sims, arrays, healthy_pass_s = _configured_and_timed()
    clock = bus.clock
    wait_s = arrays.sensors[4].reset_wait_s
    sims[4].stuck_frame = True
    resets0, statuses, longest = sims[4].resets, [], 0.0
    for k in range(100):
        for s in sims:
            s.field_t = (1e-3 * k, 0.0, 0.01)
        t0 = clock.now()
        r = arrays.read()
        longest = max(longest, clock.now() - t0)
        statuses.append(r.status[4])
        if k > 0:   # a read returns the conversion the previous read started
            others = np.delete(r.field_t, 4, axis=0)
            np.testing.assert_allclose(others[:, 0], np.round(1e-3 * (k - 1) / LSB) * LSB,
                                       atol=1e-12)
        if statuses[-1] == "ok" and "recovered" in statuses:
            break
    n_hung = statuses.count("hung")
    assert statuses == ["ok", "stale", "stale"] + ["hung"] * n_hung + ["recovered", "ok"]
    assert sims[4].resets - resets0 == 1 and not sims[4].stuck_frame
    assert longest < 1.5 * healthy_pass_s < wait_s
    # the configuration came in the first pass after the wake-up, not earlier
    assert (n_hung - 1) * healthy_pass_s < wait_s * 1.01 <= (n_hung + 1) * 1.5 * healthy_pass_s
    assert arrays.sensors[4].recoveries == 1
    np.testing.assert_allclose(r.field_t[4, 0], np.round(1e-3 * (len(statuses) - 2) / LSB) * LSB,
                               atol=1e-12)


def test_a_nacking_sensor_is_reset_between_passes_and_the_others_keep_their_rate():
    """Sensor 10 stops answering: hang_reads NACKs, then config_attempts resets, each
    configured only once its reset_wait_s wake-up is over, in later passes: no pass takes
    longer than a healthy one plus a reset and a configuration attempt (no 40 ms wait inside
    a read), the other 17 sensors read fresh values in every pass, and the sensor reports
    'nack' until its last attempt failed, then 'failed' (as a blocking reset did); when it
    answers again it is configured after the retry interval, again without a stalled pass."""
    bus, sims, arrays, healthy_pass_s = _configured_and_timed()
    clock = bus.clock
    wait_s, attempts = arrays.sensors[10].reset_wait_s, arrays.sensors[10].config_attempts
    sims[10].nack_always = True
    bus.clear_log()
    resets0, statuses, longest = sims[10].resets, [], 0.0
    for k in range(200):
        for i, s in enumerate(sims):
            s.field_t = (1e-3 * k, -1e-3 * i, 0.01)
        t0 = clock.now()
        r = arrays.read()
        longest = max(longest, clock.now() - t0)
        statuses.append(r.status[10])
        others = np.delete(r.field_t, 10, axis=0)
        if k > 0:   # a read returns the conversion the previous read started
            np.testing.assert_allclose(others[:, 0], np.round(1e-3 * (k - 1) / LSB) * LSB,
                                       atol=1e-12)
            assert sum(r.healthy) == 17
        if r.status[10] == "failed":
            break
    assert sims[10].resets - resets0 == attempts
    assert statuses[:-1] == ["nack"] * (len(statuses) - 1) and statuses[-1] == "failed"
    assert longest < 1.5 * healthy_pass_s < wait_s
    # each attempt reads the sensor's factory bytes at least reset_wait_s after its reset
    resets = [t.start_s for t in bus.log if t.messages[0].addr == 0x00]
    tries = [t.start_s for t in bus.log if t.messages[0].addr == 0x5E
             and len(t.messages[0].data) == 0 and t.error is not None and t.start_s > resets[0]]
    assert len(resets) == len(tries) == attempts
    for reset_s in resets:
        assert min(t for t in tries if t > reset_s) - reset_s >= wait_s
    assert len(statuses) * healthy_pass_s > attempts * wait_s
    # it answers again: back after the retry interval and one wake-up, no pass stalled
    sims[10].nack_always = False
    longest, k = 0.0, 0
    while r.status[10] != "ok" and k < arrays.retry_interval + 50:
        t0 = clock.now()
        r = arrays.read()
        longest, k = max(longest, clock.now() - t0), k + 1
    assert r.status[10] == "ok" and arrays.retry_interval <= k
    assert longest < 1.5 * healthy_pass_s
    assert bus.violations() == []


def test_layout_validation():
    with pytest.raises(BadInputError):
        SensorArrays(SimBus(), [SensorSlot(0x71, 0)] * 2)
    with pytest.raises(BadInputError):
        SensorArrays(SimBus(), [])


def test_firmware_io_imports_neither_designkit_nor_smbus2():
    code = ("import sys, firmware_io, firmware_io.hw.sim, firmware_io.hw; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('designkit', 'smbus2', 'scipy')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=str(__import__("pathlib").Path(__file__).parents[1]))


def test_a_frozen_sensor_is_excluded_and_the_others_are_not():
    """Every sensor with the datasheet's noise (the value checks on), sensor 4's values frozen
    while its frame counter runs: it reports 'frozen' from the 8th repeat on, shows its last
    good value meanwhile, and is reset after hang_reads frozen passes (the fault survives the
    reset: it stays out); no other sensor is ever flagged."""
    bus, muxes, sims, arrays, fields = make(checks=FrameChecks())
    rng = np.random.default_rng(3)
    for s, f in zip(sims, fields):
        s.field_source = lambda f=f: f + rng.normal(scale=1e-4, size=3)
    arrays.configure()
    good = arrays.read()
    sims[4].value_fault = "frozen"
    seen = []
    for _ in range(40):
        r = arrays.read()
        seen.append(r.status[4])
        assert all(st == "ok" for k, st in enumerate(r.status) if k != 4), r.status
    first = seen.index("frozen")
    # 8 repeats of the values converted before the fault; a reset does not bring it back
    assert first == 8 and "ok" not in seen[first:], seen
    assert sims[4].resets >= 2                  # reset after hang_reads frozen passes
    np.testing.assert_allclose(r.field_t[4], good.field_t[4], atol=5 * LSB)
