"""Smoke test of studies/bench_cad.py (timings are reported by the study, never asserted)."""

import json

import build123d  # noqa: F401  (a required dependency: no skip)
import pytest

from conftest import load_study


@pytest.mark.slow  # a benchmark's smoke test (CI runs it); the meshes: test_cad.py
def test_bench_cad_quick(tmp_path):
    mod = load_study("bench_cad")
    res = mod.run(tmp_path, quick=True)
    assert res["formats"] == ["stl"]
    assert res["files"]["core.stl"] == (tmp_path / "full" / "core.stl").stat().st_size
    # binary STL: 84-byte header + 50 bytes per triangle
    assert (res["files"]["core.stl"] - 84) % 50 == 0
    (row,) = res["tolerance_sweep"]
    assert 0 < row["max_rel_volume_error"] <= row["max_rel_bound"]
    assert json.loads((tmp_path / "bench_cad.json").read_text())["quick"] is True
    assert all(p.is_relative_to(tmp_path) for p in tmp_path.rglob("*"))
    assert "full export" in mod._table(res)
