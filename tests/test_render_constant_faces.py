"""The force constant's per-point lambda from the reachable set's faces
(firmware_io.allocation.reach, designkit.render.constant's default path) against independent
references: scipy's HiGHS LP (the ray-shooting LP max lambda s.t. F I = lambda d - F0, I in
the bounds) and the secant search on the allocator's residual (the reference path)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

from designkit.errors import BadInputError
from designkit.render import Plane, force_constant
from designkit.render.constant import _faces_lambdas, _secant_lambdas, force_matrices
from firmware_io.allocation.reach import facet_pairs, kink_planes, ray_limits

CASES = [(k, uni, tl) for k in (3, 1) for uni in (False, True) for tl in (54.0, 20.0, 8.0)]


def _lp(fm, d, f0, u, tl, unipolar):
    """max lambda with F (I+ - I-) = lambda d - F0, 0 <= I+- <= u, sum I+ + I- <= I_t (None:
    infeasible at every lambda >= 0)."""
    k, n = fm.shape
    a_eq = np.c_[fm, -fm, -d[:, None]]
    bounds = [(0, ui) for ui in u] + [(0, 0.0 if unipolar else ui) for ui in u] + [(0, None)]
    a_ub = np.r_[np.ones(2 * n), 0.0][None, :]
    r = linprog(-np.eye(2 * n + 1)[-1], A_ub=a_ub, b_ub=[tl], A_eq=a_eq, b_eq=-f0,
                bounds=bounds, method="highs")
    return r.x[-1] if r.status == 0 else None


def _random(rng, m, k, n=9, smooth=False):
    fm = rng.normal(size=(m, k, n)) * np.exp(rng.normal(size=(1, 1, n)))
    if smooth:  # neighbouring points with neighbouring matrices (a surface's grid)
        fm = fm[0] + 0.3 * np.cumsum(rng.normal(size=(m, k, n)), axis=0) / np.sqrt(m)
    d = rng.normal(size=(m, k))
    f0 = 0.3 * rng.normal(size=(m, k))
    return fm, d, f0


@pytest.mark.parametrize("k,unipolar,tl", CASES)
def test_ray_limits_equal_linprog(k, unipolar, tl):
    rng = np.random.default_rng(10 * k + 3 * unipolar + int(tl))
    fm, d, f0 = _random(rng, 25, k)
    u = rng.uniform(2.0, 6.0, 9) if tl == 8.0 else np.full(9, 6.0)  # unequal limits: all pairs
    lam, sep, _, _ = ray_limits(fm, d, f0, u, tl, unipolar=unipolar)
    for j in range(len(fm)):
        ref = _lp(fm[j], d[j], f0[j], u, tl, unipolar)
        if sep[j] > 0:  # -F0 is outside the reachable set: the ray starts outside
            assert ref is None or ref > 0  # (it may enter later: the LP's lambda, not ours)
            continue
        assert ref is not None
        assert lam[j] == pytest.approx(ref, rel=1e-9, abs=1e-12)


def test_facet_pairs_is_a_subset_that_keeps_the_answer():
    rng = np.random.default_rng(5)
    fm, d, f0 = _random(rng, 40, 3)
    for unipolar in (False, True):
        p = kink_planes(fm[:1], np.full(9, 6.0), 20.0, unipolar).shape[1]
        q = facet_pairs(9, 6.0, 20.0, unipolar)
        assert len(q) < p * (p - 1) // 2
        every = np.stack(np.triu_indices(p, 1), 1)
        a = ray_limits(fm, d, f0, 6.0, 20.0, unipolar=unipolar)[0]
        b = ray_limits(fm, d, f0, 6.0, 20.0, unipolar=unipolar, pairs=every)[0]
        np.testing.assert_allclose(a, b, rtol=1e-12)


@pytest.mark.parametrize("k,unipolar,tl", [c for c in CASES if c[2] != 8.0])
def test_faces_equal_secant(k, unipolar, tl):
    """The default path equals the reference path within its tolerance, on random and on
    smooth families (the latter exercise the pool of neighbours' faces)."""
    rng = np.random.default_rng(100 + 10 * k + 3 * unipolar + int(tl))
    u = np.full(9, 6.0)
    for smooth in (False, True):
        fm, d, f0 = _random(rng, 16, k, smooth=smooth)
        d[3] = 0.0  # no force asked: inf in both
        f0[5] = -2.0 * f0[5] / max(np.abs(f0[5]).max(), 1e-9) * 60  # -F0 beyond reach: 0
        a = _faces_lambdas(fm, d, f0, u, tl, unipolar, 1e-6, False)
        b = _secant_lambdas(fm, d, f0, u, tl, unipolar, 1e-6, False)
        np.testing.assert_array_equal(np.isinf(a), np.isinf(b))
        np.testing.assert_array_equal(a == 0.0, b == 0.0)
        fin = np.isfinite(b)
        np.testing.assert_allclose(a[fin], b[fin], rtol=2e-6, atol=0)


def test_rank_deficient_and_bias_along_d_fall_back_or_agree():
    """F of rank 2 (the faces are incomplete: the allocator's check sends the point to the
    secant search) and F0 with a large part along d (the secant's upper bound must count it)."""
    rng = np.random.default_rng(7)
    fm, d, f0 = _random(rng, 12, 3)
    fm[:6, 2] = 0.4 * fm[:6, 0] - 1.3 * fm[:6, 1]
    d[:6, 2] = 0.4 * d[:6, 0] - 1.3 * d[:6, 1]  # d and F0 in the plane: lambda > 0 exists
    f0[:6, 2] = 0.4 * f0[:6, 0] - 1.3 * f0[:6, 1]
    u = np.full(9, 6.0)
    for j in range(6, 12):  # -F0 = F I with the three coils strongest along d at -3 A: F0
        c = d[j] @ fm[j]    # has a large part along d, and lambda = 0 is renderable
        top = np.argsort(-np.abs(c))[:3]
        f0[j] = 3.0 * fm[j][:, top] @ np.sign(c[top])
    for tl in (54.0, 20.0):
        a = _faces_lambdas(fm, d, f0, u, tl, False, 1e-6, False)
        b = _secant_lambdas(fm, d, f0, u, tl, False, 1e-6, False)
        ref = [_lp(fm[j], d[j], f0[j], u, tl, False) for j in range(len(fm))]
        np.testing.assert_allclose(a, b, rtol=2e-6)
        assert None not in ref
        np.testing.assert_allclose(a, ref, rtol=2e-6)


def test_method_argument():
    with pytest.raises(BadInputError, match="method"):
        force_constant(Plane(), object(), current_limit_a=6.0, total_current_a=54.0,
                       method="lp")


@pytest.mark.slow
def test_faces_equal_secant_on_the_device():
    """The default design's coupled model (ArrayActuation) on the hemisphere: both paths, both
    drives, the design's budget (not binding) and a binding one (slow: the coupled model's
    solve; tests/test_render_constant.py checks the default path on it against HiGHS)."""
    from designkit.design import default_design
    from designkit.render import ArrayActuation, Hemisphere

    src = ArrayActuation.from_design(default_design())
    obj = Hemisphere()
    pts, nrm = obj.surface_points(5)
    fms = force_matrices(src, pts, "force")
    bias = src.bias_force(pts)
    d = obj.height(pts)[:, None] * nrm
    u = np.full(fms.shape[2], 6.0)
    for unipolar in (False, True):
        for tl in (54.0, 15.0):
            a = _faces_lambdas(fms, d, bias, u, tl, unipolar, 1e-6, False)
            b = _secant_lambdas(fms, d, bias, u, tl, unipolar, 1e-6, False)
            np.testing.assert_array_equal(a == 0.0, b == 0.0)
            np.testing.assert_allclose(a, b, rtol=2e-6)
