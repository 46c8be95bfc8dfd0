"""Smoke test of studies/render_thesis.py (quick: plane + mesh, 5 x 5 points, coarse grid)."""

import importlib.util
from pathlib import Path


def test_render_thesis_quick(tmp_path):
    path = Path(__file__).resolve().parents[1] / "studies" / "render_thesis.py"
    spec = importlib.util.spec_from_file_location("render_thesis", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    res = mod.run(tmp_path, quick=True, progress=False)
    for name in ("render_thesis.json", "render_thesis.md", "render_lambda.png",
                 "render_flat.png", "render_mesh.png"):
        assert (tmp_path / name).stat().st_size > 0
    for r in res["objects"]:
        # bipolar drive can only widen the allocation set
        assert r["lambda_bipolar_n_per_m"] >= r["lambda_unipolar_n_per_m"] * (1 - 1e-6)
        assert 0 <= r["met5_unipolar_at_18"] <= 1
    lams = [b["unipolar"] for b in res["plane_budgets"]]
    assert all(a >= b * (1 - 1e-6) for a, b in zip(lams, lams[1:]))  # tighter budget: lower
