"""Smoke tests of the field studies (quick mode): they run, write their files and the numbers
they report satisfy the issue's targets where a quick run can show them."""

import pytest

from studies import bench_field, stress_field, winding_accuracy


# slow (CI runs it): the kernels' finiteness at adversarial points is in the default suite
# (test_field_stability.py), their accuracy against mpmath in test_field_loop/_winding.py
@pytest.mark.slow
def test_stress_field_quick(tmp_path):
    res = stress_field.run(tmp_path, quick=True)
    assert res["nonfinite"] == 0
    assert res["total_points"] > 10_000
    far = res["regions"]["far 1..1e6 m"]["worst"]
    assert far["winding B vs dipole, minus 10 (size/R)^2"] < 1e-13
    assert (tmp_path / "stress_field.txt").exists()


@pytest.mark.slow  # a benchmark's smoke test (the accuracy it reports: test_field_winding.py)
def test_bench_field_quick(tmp_path):
    res = bench_field.run(tmp_path, quick=True)
    assert (tmp_path / "bench_field.png").stat().st_size > 1000
    rows = {(r["method"], r["rtol"]): r for r in res["rows"]}
    # accuracy of the sweep (not timings): each rtol is met
    for (method, rtol), r in rows.items():
        if method.startswith("designkit B") and rtol:
            assert r["err_b"] <= rtol and (r["err_g"] is None or r["err_g"] <= rtol)
    # random windings: each region and rtol meets the target against the mpmath table
    for r in res["random_rows"]:
        assert r["err_b"] <= r["rtol"] and r["err_g"] <= 10 * r["rtol"], r
    assert {r["region"] for r in res["random_rows"]} >= {"axis", "corner", "ulp", "far"}


def test_winding_accuracy_quick(tmp_path):
    res = winding_accuracy.run(tmp_path, quick=True)
    assert res["max_b_ratio"] <= 1.0 and res["max_g_ratio"] <= 10.0
    assert (tmp_path / "winding_accuracy.txt").exists()
