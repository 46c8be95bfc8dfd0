"""studies/pose_integrity.py: a small run writes its table and JSON with every condition and
mode, the shares are shares, and no fix it trusts lies beyond its protection level;
studies/bench_pose.py: a small run times every kind of fix and writes its JSON."""

from __future__ import annotations

import pytest

from conftest import load_study


@pytest.mark.slow
def test_pose_integrity_study_smoke(tmp_path, capsys):
    study = load_study("pose_integrity")
    res = study.run(tmp_path, n=6, conditions=study.CONDITIONS, modes=study.MODES)
    assert [(r["condition"], r["mode"]) for r in res["rows"]] == [
        (c, m) for m in study.MODES for c in study.CONDITIONS]
    for r in res["rows"]:
        assert r["n"] == 6 and 0 <= r["availability"] <= 1
        assert r["trusted_beyond_pl"] == 0 and r["trusted_above_5mm"] == 0
    assert (tmp_path / "pose_integrity.json").is_file()
    assert "availability by height" in (tmp_path / "pose_integrity.txt").read_text()
    assert study.main([str(tmp_path), "--conditions", "nonsense"]) == 2
    assert "conditions" in capsys.readouterr().err


@pytest.mark.slow
def test_bench_pose_smoke(tmp_path, capsys):
    study = load_study("bench_pose")
    res = study.run(n=3, runs=1, out_dir=tmp_path)
    assert set(res["median_s"]) == {"cold", "warm", "warm_fault", "cold_fault"}
    assert all(v > 0 for v in res["median_s"].values()) and res["matmul_s"] > 0
    assert (tmp_path / "bench_pose.json").is_file()
    assert "median of 1 runs" in capsys.readouterr().out
    assert study.main([str(tmp_path), "--n", "1"]) == 2
