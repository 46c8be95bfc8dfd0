"""Smoke test of studies/bench_allocation.py (quick: 12 positions, 300 timed/certified problems)."""

import importlib.util
import sys
from pathlib import Path

import pytest


@pytest.mark.slow  # a benchmark's smoke test (CI runs it); certified solves: test_allocation.py
def test_bench_allocation_quick(tmp_path):
    path = Path(__file__).resolve().parents[1] / "studies" / "bench_allocation.py"
    sys.path.insert(0, str(path.parent))
    spec = importlib.util.spec_from_file_location("bench_allocation", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    res = mod.run(tmp_path, quick=True, progress=False)
    assert (tmp_path / "bench_allocation.json").is_file()
    v = res["verify"]
    assert v["n"] == 30 and v["max_kkt_rel"] <= 1e-9 and v["max_bound_violation_a"] <= 1e-9
    assert v["n_mismatch_ours_higher"] == 0
    c = res["certify"]
    assert c["n"] == 300 and c["max_kkt_rel"] <= 1e-9 and c["max_bound_violation_a"] <= 1e-9
    assert res["mix_median_us"] > 0 and res["speedup_vs_lsq_linear_median"] > 0
    for p in res["path"].values():  # warm start: the same answers as cold
        assert p["max_difference_a"] <= 1e-9 and p["warm_median_us"] > 0
