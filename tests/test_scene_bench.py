"""Smoke test of studies/bench_scene.py (quick mode: air coils, 20 mm grid)."""

import importlib.util
from pathlib import Path


def _load():
    path = Path(__file__).resolve().parents[1] / "studies" / "bench_scene.py"
    spec = importlib.util.spec_from_file_location("bench_scene", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_bench_scene_quick(tmp_path):
    res = _load().run(tmp_path, quick=True)
    assert (tmp_path / "bench_scene.json").is_file()
    rows = {(r["tolerance"], r["outputs"], r["variant"]): r for r in res["rows"]}
    assert len(rows) == 30
    for (tol, outs, var), r in rows.items():
        assert r["max_rel_error"] <= (1e-12 if var == "direct" else tol)
        if var.startswith("tables"):
            assert r["table_nodes"] > 0
