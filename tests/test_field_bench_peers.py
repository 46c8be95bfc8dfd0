"""Smoke test of studies/bench_peers.py (quick mode): it runs, writes its table and figure, and
its accuracy columns make sense (no timing asserts)."""

import pytest

from studies import bench_peers


@pytest.mark.slow  # a benchmark's smoke test (CI runs it); the accuracy: test_field_winding.py
def test_bench_peers_quick(tmp_path):
    res = bench_peers.run(tmp_path, quick=True)
    assert (tmp_path / "bench_peers.png").stat().st_size > 1000
    assert "matched achieved error" in (tmp_path / "bench_peers.txt").read_text()
    rows = res["rows"]
    assert {r["set"] for r in rows} == {"workspace", "near", "far"}
    for r in rows:
        if r["method"] == "designkit":
            rtol = float(r["config"].split()[1])
            assert r["err_b"] <= rtol, r
            if r["gradient"]:
                assert r["err_g"] <= 10 * rtol, r
    # cfsem's finest grid converges to designkit's reference (an independent check of both)
    fine = [r for r in rows if r["method"] == "cfsem" and r["config"] == "6x12"
            and r["set"] == "workspace" and not r["gradient"]]
    assert fine and fine[0]["err_b"] < 1e-7
    assert "workspace B designkit/cfsem at 1e-04" in res["ratios"]
