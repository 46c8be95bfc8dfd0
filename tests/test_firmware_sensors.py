"""SensorArrays over three simulated TCA9548A muxes with 18 TLV493D (all at 0x5E).

Any moment with two sensors of one address connected would raise SimAddressConflict, so these
tests also check that only one mux channel is ever enabled.
"""

import subprocess
import sys

import numpy as np
import pytest

from firmware_io import SensorArrays, SensorSlot
from firmware_io.errors import BadInputError
from firmware_io.hw.sim import SimBus, SimClock, SimTCA9548A, SimTLV493D

LSB = 0.098e-3


def make(**kw):
    clock = SimClock()
    bus = SimBus(clock=clock)
    muxes = [bus.attach(SimTCA9548A(0x71 + k)) for k in range(3)]
    fields = np.array([[1e-3 * i, -2e-3 * i, 0.05 - 4e-3 * i] for i in range(18)])
    sims = [muxes[i // 8].attach(i % 8, SimTLV493D(field_t=fields[i])) for i in range(18)]
    arrays = SensorArrays(bus, sleep=clock.sleep, **kw)
    return bus, muxes, sims, arrays, fields


def test_reads_two_arrays_in_tesla():
    bus, muxes, sims, arrays, fields = make()
    assert arrays.configure() == ("ok",) * 18
    assert all(s.resets == 1 for s in sims)  # each reset reached its own sensor only
    r = arrays.read()
    expected = np.round(fields / LSB) * LSB  # 0.098 mT quantisation
    assert r.top_t.shape == (9, 3) and r.bottom_t.shape == (9, 3)
    np.testing.assert_allclose(r.top_t, expected[:9], atol=1e-12)
    np.testing.assert_allclose(r.bottom_t, expected[9:], atol=1e-12)
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
    bus, muxes, sims, arrays, fields = make(hang_threshold=3)
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
    assert statuses4 == ["ok", "stale", "stale", "recovered", "ok"]
    assert statuses10[:2] == ["nack", "nack"] and statuses10[2] == "failed"
    np.testing.assert_allclose(r.bottom_t[1], first.bottom_t[1])  # last good value kept
    assert r.status[15] == "saturated" and r.bottom_t[6][2] == pytest.approx(2047 * LSB)
    assert not r.healthy[10] and not r.healthy[15] and r.healthy[4]
    assert np.isfinite(r.top_t).all() and np.isfinite(r.bottom_t).all()
    # failed sensor comes back when it answers again (retry interval)
    sims[10].nack_always = False
    for _ in range(arrays.retry_interval + 2):
        r = arrays.read()
    assert r.status[10] == "ok"


def test_layout_validation():
    with pytest.raises(BadInputError):
        SensorArrays(SimBus(), [SensorSlot(0x71, 0)] * 2)
    with pytest.raises(BadInputError):
        SensorArrays(SimBus(), [SensorSlot(0x71, 0)])


def test_firmware_io_imports_neither_designkit_nor_smbus2():
    code = ("import sys, firmware_io, firmware_io.hw.sim, firmware_io.hw; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('designkit', 'smbus2', 'scipy')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=str(__import__("pathlib").Path(__file__).parents[1]))
