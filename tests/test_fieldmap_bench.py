"""Smoke test of studies/bench_map.py (quick mode: air coils, small box)."""

from conftest import load_study


def test_bench_map_quick(tmp_path):
    res = load_study("bench_map").run(tmp_path, quick=True)["air_quick"]
    assert (tmp_path / "bench_map.json").is_file()
    assert not list(tmp_path.glob("*.npz"))  # the study cleans up its map
    # air coils: the tables carry everything; within the 1e-3 target
    assert 0 < res["max_rel"] < 1e-3
    assert res["bias_force_max_rel"] == 0 and res["sensor_induced_max_rel"] == 0
    assert 0 < res["file_mb"] and res["t_1_us_shape3"][0] > 0 and res["t_1e4_ms"][0] > 0
