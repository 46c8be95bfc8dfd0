"""Smoke test of studies/array_coupling.py (quick mode, no FEM)."""

import importlib.util
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def test_array_coupling_study_quick(tmp_path):
    spec = importlib.util.spec_from_file_location("array_coupling",
                                                  ROOT / "studies" / "array_coupling.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    from designkit import default_design
    from designkit.design import GridLayout

    # two coils: every code path of the study at a fraction of the 3x3 solve
    d = default_design()
    res = mod.run(tmp_path, quick=True, design=d.replace(array=GridLayout(rows=1, columns=2)))
    assert (tmp_path / "array_coupling.json").exists()
    assert (tmp_path / "array_coupling_f0.png").stat().st_size > 10_000
    assert res["table_centre_coil"][0]["fem"] == mod.FEM_NOT_RUN
    # the magnet pulls the magnet down onto the centre core
    assert res["f0"]["fz_at_30mm_centre_n"] < 0
    assert all(np.isfinite(r["subtraction_error_t"]) for r in res["sensor_subtraction"])
    assert res["cost"]["n_unknowns"] > 0
    mod._print(res)
