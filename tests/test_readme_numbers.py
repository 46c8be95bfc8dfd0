"""The README's headline numbers of the coupled thesis array, asserted to the digits the README
prints, each next to the command that prints it.

Single-coil numbers (299 / 3154 mN, 185 mH): tests/test_core_fem_cache.py. Against the FEM:
tests/test_coupling_fem_cache.py. Localization MAEs: a sample of the README's positions, held to
the README's numbers within the sample's standard error.
"""

import numpy as np
import pytest

from conftest import load_study
from designkit.design import default_design
from designkit.fieldmap import default_box
from designkit.render import ArrayActuation, Plane, force_constant
from designkit.sim.readings import SensorSimulator, case_currents, random_positions
from firmware_io.localization import POSITION_ONLY, ModelEstimator, SensorModel

D = default_design()
M = np.asarray(D.magnet.moment_vector_a_m2, float)
N_LOC = 100
"""Positions per localization case (the README's runs use 1000)."""


def _gzz(a5):
    """dBz/dz = -dBx/dx - dBy/dy from the rows of A (..., 8, n)."""
    return -a5[..., 3, :] - a5[..., 6, :]


def test_pull_with_every_coil_off(thesis_array):
    # README: "the magnet (the 10 x 10 mm cylinder; as a point dipole 62.7 mN) is pulled down
    # by 63.9 mN at 30 mm with every coil off" (python studies/array_coupling.py OUT:
    # f0.fz_at_30mm_centre_n, fz_at_30mm_centre_dipole_n)
    size = (D.magnet.radius_m, D.magnet.length_m)
    f = thesis_array.bias_force([0.0, 0.0, 0.03], M, magnet_size_m=size)
    assert f[2] == pytest.approx(-0.0639, abs=0.06e-3)
    assert abs(f[0]) < 1e-9 and abs(f[1]) < 1e-9
    assert thesis_array.bias_force([0.0, 0.0, 0.03], M)[2] == pytest.approx(-0.0627, abs=0.06e-3)


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


@pytest.fixture(scope="module")
def lower_half_errors(small_map):
    """Position errors (m) of 'model-cal' and of the noise-limited fit over N_LOC uniform
    positions of the lower half of the thesis' cube, per field case: the pipeline of
    studies/localization.py (its functions, the same seeds and calibration), on the small map."""
    study = load_study("localization")
    sim = SensorSimulator(D, errors="default", seed=0, induced="coupled")
    size = (D.magnet.radius_m, D.magnet.length_m)
    model = SensorModel.from_map(small_map, magnet_size_m=size)
    cal, _ = study._calibrate(sim, model, 1000, 1000)
    loc = ModelEstimator(model, POSITION_ONLY, calibration=cal)
    rng = np.random.default_rng(0)
    pos = random_positions(N_LOC, rng, z_range_m=(0.020, 0.045), half_width_m=0.025)
    mag = sim.magnet_part(pos)
    ind = np.stack([sim.induced_part(pos[k:k + 1])[0] for k in range(N_LOC)])
    h = 0.5e-3
    jac = np.stack([np.stack([(model.induced_field(p + h * e) - model.induced_field(p - h * e)).reshape(
        2, 9, 3) / (2 * h) for e in np.eye(3)], axis=-1) for p in pos])
    out = {}
    for case in ("off", "static"):
        cur = case_currents(case, rng.uniform(0, 20, N_LOC), model.n_coils, seed=7)
        rd = sim.read(pos, cur, parts=(mag, ind))
        fit, limit = np.empty(N_LOC), np.empty(N_LOC)
        for k in range(N_LOC):
            loc.reset()
            fit[k] = np.linalg.norm(loc.estimate(np.r_[rd.top_t[k], rd.bottom_t[k]],
                                                 cur[k]).position_m - pos[k])
            limit[k] = np.linalg.norm(study._noise_limited(sim, rd, k, pos[k], cur[k], ind[k],
                                                           jac[k]) - pos[k])
        out[case] = fit, limit
    return out


@pytest.mark.parametrize("case", ["off", "static"])
def test_localization_mae_in_the_lower_half_of_the_cube(lower_half_errors, case):
    # README (Localization; python studies/localization.py OUT --map MAP, 1000 positions per
    # case): 'model-cal' MAE 0.54 mm in the lower half of the cube (0.53-0.55 over the thesis'
    # four cases), noise limit 0.52 mm, 'model-cal' within 1.01-1.16x of the noise limit.
    # Here N_LOC positions: each MAE within 3 standard errors (std / sqrt(N_LOC), ~0.045 mm)
    # of the README's, the paired ratio within 3 of its standard errors of 1.16.
    fit, limit = lower_half_errors[case]
    for e, readme in ((fit, 0.54e-3), (limit, 0.52e-3)):
        se = e.std(ddof=1) / np.sqrt(N_LOC)
        assert abs(e.mean() - readme) < 3 * se, (case, e.mean(), readme, se)
    ratio_se = (fit - limit).std(ddof=1) / np.sqrt(N_LOC) / limit.mean()
    assert 1.0 - 3 * ratio_se < fit.mean() / limit.mean() < 1.16 + 3 * ratio_se
