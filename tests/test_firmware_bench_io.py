"""Smoke test of studies/bench_io.py; the wire-time budget is checked against a hand count.

One loop = 18 sensor reads of 6 bytes, 18 mux selects + 3 mux disables (1 byte), one PCA9685
write of 64 channel bytes (coils 0-7) and one of 8 (coil 8), each with its register byte.
Bits per transaction = 9 (bytes + address byte) + 2 (START and STOP; NXP UM10204, 3.1).
"""

import json

import pytest

from conftest import load_study


def test_bench_io_quick(tmp_path):
    result = load_study("bench_io").run(tmp_path, quick=True)
    bits = 18 * (9 * 7 + 2) + 21 * (9 * 2 + 2) + (9 * 66 + 2) + (9 * 10 + 2)
    assert bits == 2278
    for f in (100e3, 400e3, 1e6):
        assert result["wire_time_s"][str(int(f))]["total_s"] == pytest.approx(bits / f, rel=1e-12)
    assert result["transactions_by_kind"] == {"sensor_read": 18, "mux_select": 21, "pwm_write": 2}
    rows = result["rows"]
    assert len(rows) == 4
    for r in rows:
        assert r["loop_hz_optimistic"] > r["loop_hz_pessimistic"] > 0
    assert [r["mux_in_spec"] for r in rows] == [True, True, False, True]
    saved = json.loads((tmp_path / "bench_io.json").read_text())
    assert saved["transactions_per_loop"] == 41
    assert (tmp_path / "bench_io.txt").read_text().startswith(" " * 19 + "SCL")
