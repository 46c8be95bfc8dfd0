"""Question: how fast can the hardware loop run on one I2C bus?

One loop of the rendering runner reads all 18 TLV493D sensors (with the TCA9548A selects they
need) and writes one coil command to the two PCA9685 boards. This study

1. records that loop's transactions on the register-level simulated bus (firmware_io.hw.sim) and
   turns them into wire time at 100 kHz, 400 kHz and 1 MHz with the formula of firmware_io.hw.bus
   (9 clocks per byte including the address byte, + START/STOP, + 1 per repeated START);
2. measures the Python cost per loop of the firmware_io drivers on this host, subtracting the
   time spent inside the simulated device models (reference run in the same process);
3. adds a per-ioctl kernel overhead, which cannot be measured without hardware: the
   optimistic and pessimistic values of ``IOCTL_OVERHEAD_S`` per transaction, bracketing the
   overhead inferred from published Raspberry Pi I2C measurements (not repeatable here);

and reports the achievable loop rate = 1 / (wire + ioctls x overhead + Python). The TCA9548A is
specified up to 400 kHz only, so the 1 MHz row is out of spec for the sensor segment; the 'split'
row puts the PCA9685s on their own 1 MHz adapter (written in parallel) and the sensors at 400 kHz.

Python overhead is measured on the machine running the study; a Raspberry Pi runs CPython
several times slower, so rerun this there before trusting the rate.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit.support.atomic import write_json_atomic, write_text_atomic
from firmware_io import CoilDrive, CoilDriver, SensorArrays
from firmware_io.hw.pca9685 import PCA9685
from firmware_io.hw.sim import SimBus, SimClock, SimPCA9685, SimTCA9548A, SimTLV493D

SCL_HZ = (100e3, 400e3, 1e6)
# per-ioctl kernel overhead, s: brackets the ~0.15 ms inferred from published Raspberry Pi I2C
# measurements
IOCTL_OVERHEAD_S = {"optimistic": 0.05e-3, "pessimistic": 0.3e-3}
TCA9548A_MAX_SCL_HZ = 400e3


def build_system(clock: SimClock):
    """Two PCA9685 (0x40, 0x41), three TCA9548A (0x71-0x73), 18 TLV493D, one per channel."""
    bus = SimBus(scl_hz=400e3, clock=clock)
    sim_boards = [bus.attach(SimPCA9685(0x40)), bus.attach(SimPCA9685(0x41))]
    muxes = [bus.attach(SimTCA9548A(0x71 + k)) for k in range(3)]
    rng = np.random.default_rng(7)
    for i in range(18):
        muxes[i // 8].attach(i % 8, SimTLV493D(field_t=rng.uniform(-0.05, 0.05, 3)))
    boards = [PCA9685(bus, 0x40, sleep=clock.sleep), PCA9685(bus, 0x41, sleep=clock.sleep)]
    coils = CoilDriver(boards, CoilDrive(24.0, 4.0, 5.0), sleep=clock.sleep)
    arrays = SensorArrays(bus, sleep=clock.sleep)
    return bus, sim_boards, coils, arrays


def _classify(tr) -> str:
    m = tr.messages[0]
    if m.addr in (0x40, 0x41):
        return "pwm_write"
    if 0x70 <= m.addr <= 0x77:
        return "mux_select"
    return "sensor_read"


def run(out_dir, quick: bool = False) -> dict:
    """Run the study; write ``bench_io.json`` and ``bench_io.txt`` under ``out_dir``."""
    out_dir = Path(out_dir)
    clock = SimClock()
    bus, sim_boards, coils, arrays = build_system(clock)
    coils.initialize(1526.0)
    status = arrays.configure()
    assert all(s == "ok" for s in status), status
    rng = np.random.default_rng(1)
    base = np.array([1.0, -1.0, 2.0, -2.0, 0.5, 3.0, -3.0, 4.0, -4.0])
    coils.command(base)

    # 1. one loop's transactions (same signs as before: no reversal step)
    bus.clear_log()
    arrays.read()
    coils.command(base * 1.1)
    loop_log = list(bus.log)
    kinds = [_classify(t) for t in loop_log]
    n_tx = len(loop_log)
    counts = {k: kinds.count(k) for k in ("sensor_read", "mux_select", "pwm_write")}
    wire = {}
    for f in SCL_HZ:
        parts = {k: sum(t.wire_time_s(f) for t, c in zip(loop_log, kinds) if c == k) for k in counts}
        wire[f] = {"total_s": sum(parts.values()), **{f"{k}_s": v for k, v in parts.items()}}

    # 2. Python cost per loop, minus the simulated devices' own time
    n_cycles = 40 if quick else 2000
    currents = base * (1.0 + 0.1 * rng.random((n_cycles, 9)))
    bus.model_time_s = 0.0
    t0 = time.perf_counter()
    for k in range(n_cycles):
        arrays.read()
        coils.command(currents[k])
    total_s = (time.perf_counter() - t0) / n_cycles
    model_s = bus.model_time_s / n_cycles
    driver_s = max(total_s - model_s, 0.0)
    assert not bus.violations(), bus.violations()

    # 3. loop rates
    rows = []
    for f in SCL_HZ:
        w = wire[f]["total_s"]
        row = {"scl_hz": f, "wire_ms": w * 1e3, "transactions": n_tx, "python_ms": driver_s * 1e3,
               "mux_in_spec": f <= TCA9548A_MAX_SCL_HZ}
        for name, ov in IOCTL_OVERHEAD_S.items():
            row[f"loop_hz_{name}"] = 1.0 / (w + n_tx * ov + driver_s)
        rows.append(row)
    # split: sensors + selects at 400 kHz on one adapter, PWM at 1 MHz on another, in parallel
    n_sensor_tx = counts["sensor_read"] + counts["mux_select"]
    sensor_wire = wire[400e3]["sensor_read_s"] + wire[400e3]["mux_select_s"]
    pwm_wire = wire[1e6]["pwm_write_s"]
    split = {"scl_hz": "400k sensors | 1M PWM", "wire_ms": max(sensor_wire, pwm_wire) * 1e3,
             "transactions": n_tx, "python_ms": driver_s * 1e3, "mux_in_spec": True}
    for name, ov in IOCTL_OVERHEAD_S.items():
        split[f"loop_hz_{name}"] = 1.0 / max(sensor_wire + n_sensor_tx * ov + driver_s,
                                             pwm_wire + counts["pwm_write"] * ov)
    rows.append(split)

    result = {
        "transactions_per_loop": n_tx,
        "transactions_by_kind": counts,
        "wire_time_s": {f"{int(f)}": v for f, v in wire.items()},
        "python_total_per_loop_s": total_s,
        "python_sim_models_per_loop_s": model_s,
        "python_driver_per_loop_s": driver_s,
        "cycles_timed": n_cycles,
        "ioctl_overhead_s": IOCTL_OVERHEAD_S,
        "rows": rows,
    }
    header = (f"{'SCL':>22} {'wire ms':>8} {'tx':>4} {'py ms':>6} {'mux ok':>6} "
              f"{'loop Hz (0.05 ms/ioctl)':>24} {'loop Hz (0.3 ms/ioctl)':>23}")
    lines = [header]
    for r in rows:
        scl = r["scl_hz"] if isinstance(r["scl_hz"], str) else f"{r['scl_hz'] / 1e3:.0f} kHz"
        lines.append(f"{scl:>22} {r['wire_ms']:8.3f} {r['transactions']:4d} {r['python_ms']:6.3f} "
                     f"{str(r['mux_in_spec']):>6} {r['loop_hz_optimistic']:24.1f} "
                     f"{r['loop_hz_pessimistic']:23.1f}")
    lines.append(f"transactions per loop: {counts} ({n_tx} total); Python per loop on this host: "
                 f"{total_s * 1e3:.3f} ms, of which simulated devices {model_s * 1e3:.3f} ms "
                 f"(driver {driver_s * 1e3:.3f} ms, {n_cycles} loops)")
    table = "\n".join(lines)
    result["table"] = table
    write_json_atomic(out_dir / "bench_io.json", result)
    write_text_atomic(out_dir / "bench_io.txt", table + "\n")
    return result


if __name__ == "__main__":
    from studies._common import study_parser

    a = study_parser(__doc__, Path(__file__).resolve().parents[1] / "out" / "bench_io",
                     quick="40 cycles instead of 2000").parse_args()
    res = run(a.out, quick=a.quick)
    print(res["table"])
    print(f"written to {a.out}")
