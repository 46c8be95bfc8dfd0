"""Smoke test of studies/core_vs_fem.py (quick mode: coarse FEM, one core, 6 A)."""

import shutil

import pytest

from conftest import shared_fem_solves

# slow (CI runs it): the study's live FEM; the model against the FEM is in the default suite
# through the cached references (test_core_fem_cache.py, 0.2 %; this one checks 3 %)
pytestmark = [pytest.mark.skipif(shutil.which("getdp") is None,
                                 reason="GetDP not installed (apt-get install getdp)"),
              pytest.mark.slow]


@pytest.fixture(autouse=True)
def _shared_fem_solves(monkeypatch, fem_solve_memo):
    """Identical FEM models solved once per run (conftest.fem_solve_memo)."""
    shared_fem_solves(monkeypatch, fem_solve_memo)


def test_core_vs_fem_quick(tmp_path, monkeypatch):
    import designkit.fem.compare as compare
    from studies.core_vs_fem import print_table, run

    # the comparison figure is drawn and checked by test_fem.py::test_cli_fem_writes_everything
    monkeypatch.setattr(compare, "plot_comparison", lambda *a, **k: None)

    res = run(tmp_path, quick=True)
    print_table(res)
    assert abs(res["air"]["bz_rel"]) < 2e-4 and abs(res["air"]["l_rel"]) < 1e-4
    e = res["linear"][1000.0]["surface-current"]
    assert max(e["axis"] + e["off_axis"]) < 0.03
    nl = res["nonlinear"][-1]
    assert abs(nl["dbz_model"] / nl["dbz_fem"] - 1) < 0.10
    for row in res["around"].values():
        assert row["worst_b"] < 0.03 and row["worst_dbz"] < 0.03
    assert (tmp_path / "core_vs_fem.json").exists()
