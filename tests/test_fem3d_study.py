"""Smoke test of studies/fem3d_array.py (quick: coarse 3-D meshes, no corner case)."""

import shutil

import numpy as np
import pytest

pytestmark = [pytest.mark.skipif(shutil.which("getdp") is None,
                                 reason="GetDP not installed (apt-get install getdp)"),
              pytest.mark.slow]


def test_fem3d_array_quick(tmp_path):
    from studies.fem3d_array import print_table, run

    s = run(tmp_path, quick=True)
    print_table(s)
    data = np.load(tmp_path / "fem3d_array.npz")
    assert data["centre_b"].shape == data["centre_points"].shape
    assert data["centre_g"].shape == data["centre_points"].shape + (3,)
    assert np.all(np.isfinite(data["centre_g"]))
    e = s["single_L-2"]  # the iron-integral outputs: measured 0.61 / 0.7 %
    assert e["b_err_max"] < 0.015 and e["g_err_max"] < 0.015
    assert abs(s["block_L-2"]["rel"]) < 0.05
    assert np.all(data["pull_L-2_fz"] < 0)  # the iron pulls the magnet down
    # the coupled model against this coarse FEM in the workspace (z >= 20 mm; measured: two
    # cores 1.1 / 1.6 %, the 3x3 array 3.4 / 4.1 %, of which ~2 % is the L-2 mesh: its
    # median against level 1 is ~2 %) and the pull (+5..7 % at L-2, +2 % at L0)
    two = s["two_cores"]["model_vs_fem"]
    assert two["b_max_in_workspace"] < 0.025 and two["g_max_in_workspace"] < 0.03
    arr = s["array_centre"]["model_vs_fem"]
    assert arr["b_max_in_workspace"] < 0.05 and arr["g_max_in_workspace"] < 0.06
    np.testing.assert_allclose(s["pull_L-2"]["model_fz_n"], s["pull_L-2"]["fz_n"], rtol=0.1)
    assert (tmp_path / "fem3d_array.json").exists()
