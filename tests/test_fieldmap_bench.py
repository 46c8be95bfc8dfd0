"""Smoke test of studies/bench_map.py (quick mode: air coils, small box)."""

import importlib.util
from pathlib import Path


def _load():
    path = Path(__file__).resolve().parents[1] / "studies" / "bench_map.py"
    spec = importlib.util.spec_from_file_location("bench_map", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_bench_map_quick(tmp_path):
    res = _load().run(tmp_path, quick=True)["air_quick"]
    assert (tmp_path / "bench_map.json").is_file()
    assert not list(tmp_path.glob("*.npz"))  # the study cleans up its map
    q, lin, tab = res["quadratic"], res["linear"], res["tables"]
    # 4 mm grid over a small box: the quadratic-exact scheme must beat trilinear
    assert 0 < q["max_rel"] < lin["max_rel"]
    assert q["max_rel"] < 5e-3
    # the (rho, z) tables do not depend on the 3-D spacing: within the 1e-3 target
    assert 0 < tab["max_rel"] < 1e-3
    assert res["file_mb"] > res["tables_mb"] > 0 and q["t_1_us"] > 0 and tab["t_1e4_ms"] > 0
