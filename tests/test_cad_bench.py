"""Smoke test of studies/bench_cad.py (timings are reported by the study, never asserted)."""

import importlib.util
import json
from pathlib import Path

import pytest

pytest.importorskip("build123d")

STUDY = Path(__file__).resolve().parents[1] / "studies" / "bench_cad.py"


def test_bench_cad_quick(tmp_path):
    spec = importlib.util.spec_from_file_location("bench_cad", STUDY)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
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
