"""Smoke test of studies/bench_scene.py (quick mode: air coils, 20 mm grid)."""

from conftest import load_study


def test_bench_scene_quick(tmp_path):
    res = load_study("bench_scene").run(tmp_path, quick=True)
    assert (tmp_path / "bench_scene.json").is_file()
    rows = {(r["tolerance"], r["outputs"], r["variant"]): r for r in res["rows"]}
    assert len(rows) == 30
    for (tol, outs, var), r in rows.items():
        assert r["max_rel_error"] <= (1e-12 if var == "direct" else tol)
        if var.startswith("tables"):
            assert r["table_nodes"] > 0
