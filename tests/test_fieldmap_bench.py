"""Smoke test of studies/bench_map.py (quick mode: air coils, small box)."""

from conftest import load_study


def test_bench_map_quick(tmp_path):
    res = load_study("bench_map").run(tmp_path, quick=True)["air_quick"]
    assert (tmp_path / "bench_map.json").is_file()
    assert not list(tmp_path.glob("*.npz"))  # the study cleans up its map
    q, lin, tab = res["quadratic"], res["linear"], res["tables"]
    # 4 mm grid over a small box: the quadratic-exact scheme must beat trilinear
    assert 0 < q["max_rel"] < lin["max_rel"]
    assert q["max_rel"] < 5e-3
    # the (rho, z) tables do not depend on the 3-D spacing: within the 1e-3 target
    assert 0 < tab["max_rel"] < 1e-3
    assert res["file_mb"] > res["tables_mb"] > 0 and q["t_1_us"] > 0 and tab["t_1e4_ms"] > 0
