"""The README's headline numbers of the coupled thesis array, asserted to the digits the README
prints, each next to the command that prints it.

Single-coil numbers (299 / 3154 mN, 185 mH): tests/test_core_fem_cache.py. Against the FEM:
tests/test_coupling_fem_cache.py.
"""

import numpy as np
import pytest

from designkit.design import default_design
from designkit.fieldmap import default_box
from designkit.render import ArrayActuation, Plane, force_constant

D = default_design()
M = np.asarray(D.magnet.moment_vector_a_m2, float)


def _gzz(a5):
    """dBz/dz = -dBx/dx - dBy/dy from the rows of A (..., 8, n)."""
    return -a5[..., 3, :] - a5[..., 6, :]


def test_pull_with_every_coil_off(thesis_array):
    # README: "the magnet is pulled down by 62.7 mN at 30 mm with every coil off"
    # (python studies/array_coupling.py OUT: f0.fz_at_30mm_centre_n)
    f = thesis_array.bias_force([0.0, 0.0, 0.03], M)
    assert f[2] == pytest.approx(-0.0627, abs=0.06e-3)
    assert abs(f[0]) < 1e-9 and abs(f[1]) < 1e-9


def test_coupling_gain_at_the_design_point(thesis_array):
    # README: "Against the thesis' coil-by-coil model the centre coil's dBz/dz at the design
    # point is +12.4 %" (studies/array_coupling.py, table_centre_coil, 30 mm)
    p = np.array([[0.0, 0.0, 0.03]])
    g_c = _gzz(thesis_array.actuation_matrix(p))[0, 4]
    g_u = _gzz(thesis_array.uncoupled_actuation_matrix(p))[0, 4]
    assert 100 * (g_c / g_u - 1) == pytest.approx(12.4, abs=0.06)


def test_centre_coil_force_at_30_mm(thesis_array):
    # README: "~4.5x the force the thesis reports (3.54 N vs 0.78 N at 30 mm, 6 A in the
    # centre coil)" -- the coupled array, linear cores
    a = thesis_array.actuation_matrix(np.array([[0.0, 0.0, 0.03]]))[0]
    fz = 6.0 * M[2] * _gzz(a)[4]
    assert fz == pytest.approx(3.54, abs=0.006)


class _Window(Plane):
    """The thesis' flat surface (61 x 61 points over 100 mm, 50 mm high) cut to a window of
    its grid around the limiting points of eq. 4.3: the four README lambdas are minima over
    the whole grid at these points (quadrant runs of 961 points found them; the array's
    symmetry repeats them in the other quadrants)."""

    def surface_points(self, n_side: int = 61):
        p, n = super().surface_points(n_side)
        keep = (p[:, 0] > 0.019) & (p[:, 0] < 0.034) & (p[:, 1] > 0.022) & (p[:, 1] < 0.044)
        return p[keep], n[keep]


@pytest.mark.parametrize("unipolar, rows, readme", [(True, "fz", 14.2), (True, "force", 13.8),
                                                    (False, "fz", 19.0),
                                                    (False, "force", 18.1)])
def test_force_constant_of_the_flat_surface(thesis_array, unipolar, rows, readme):
    # README (Rendering): "lambda = 14.2 N/m with the thesis' Fz-only eq. 4.2 and unipolar
    # drive, 13.8 N/m when the whole force lambda h n must be met, 19.0 / 18.1 N/m bipolar"
    # (python studies/render_thesis.py OUT: plane_thesis_form); 6 A per coil, 54 A total,
    # coupled cores, F0 subtracted
    src = ArrayActuation(thesis_array, M, D.spec_hash(), default_box(D))
    fc = force_constant(_Window(), src, current_limit_a=6.0, total_current_a=54.0,
                        unipolar=unipolar, rows=rows, n_side=61, progress=False)
    assert fc.lam_n_per_m == pytest.approx(readme, abs=0.05)
    # the minimum lies inside the window, not on its rim (else the grid beyond could be lower)
    lp = fc.limiting_point_m
    assert 0.02 < lp[0] < 0.033 and 0.023 < lp[1] < 0.043
