"""firmware_io.allocation: exact bounded allocation (thesis eq. 4.9).

References (independent of the solver): a KKT certificate (studies/alloc_reference.py), scipy SLSQP
on the split formulation, the pseudo-inverse (least-energy exact fit) and the closed-form
fractional knapsack for the largest reachable Fz.
"""

from __future__ import annotations

import pathlib
import sys

import numpy as np
import pytest

sys.path.insert(0, str(pathlib.Path(__file__).parents[1] / "studies"))
from alloc_reference import kkt_violation, slsqp_reference  # noqa: E402
from conftest import top_level_imports  # noqa: E402

from firmware_io.allocation import allocate  # noqa: E402
from firmware_io.errors import BadInputError  # noqa: E402

ROWS = {1: [2], 3: [0, 1, 2], 6: [0, 1, 2, 3, 4, 5]}


@pytest.fixture(scope="module")
def wrench_matrices(thesis_array):
    """(m, 6, 9) force+torque per ampere of the default design at random workspace points."""
    from designkit.model.array import force_matrix, skew_matrix
    from designkit.design import default_design

    d = default_design()
    rng = np.random.default_rng(13)
    ws = d.workspace
    h = ws.half_width_m
    pts = rng.uniform([-h, -h, ws.z_min_m], [h, h, ws.z_max_m], (24, 3))
    a = thesis_array.actuation_matrix(pts, rtol=1e-8)
    m = np.asarray(d.magnet.moment_vector_a_m2)
    return np.concatenate([force_matrix(m) @ a[:, 3:, :], skew_matrix(m) @ a[:, :3, :]], axis=1)


def random_problem(rng, w):
    """Random rows, drive mode, per-coil limits, budget and a target inside or outside reach."""
    k = int(rng.choice([1, 3, 6]))
    fm = w[rng.integers(len(w))][ROWS[k]]
    uni = bool(rng.integers(2))
    u = rng.uniform(0.0, 6.0, fm.shape[1]) if rng.random() < 0.5 else 6.0
    tl = float(rng.choice([rng.uniform(0.5, 20.0), rng.uniform(20, 60), np.inf]))
    reach = np.abs(fm).sum(axis=1) * 6.0
    f = rng.normal(size=k) * reach * rng.choice([0.02, 0.2, 1.0, 5.0])
    return fm, f, u, tl, uni


def test_kkt_and_slsqp_reference_random(wrench_matrices):
    rng = np.random.default_rng(4)
    worst_kkt = 0.0
    for _ in range(60):
        fm, f, u, tl, uni = random_problem(rng, wrench_matrices)
        x, res = allocate(fm, f, u, tl, unipolar=uni)
        kv, infeas = kkt_violation(fm, f, u, tl, x, uni)
        assert infeas <= 1e-9, (infeas, x)
        worst_kkt = max(worst_kkt, kv)
        ref = slsqp_reference(fm, f, u, tl, uni)
        # never worse than the reference beyond 1e-6 relative (floor: 1e-12 of ||f||^2)
        assert res <= ref + 1e-6 * ref + 1e-12 * (f @ f), (res, ref)
        r = fm @ x - f
        assert res == pytest.approx(r @ r, rel=1e-12, abs=1e-300)
    assert worst_kkt <= 1e-9


def test_least_energy_exact_fit_equals_pseudoinverse(wrench_matrices):
    """Reachable target whose minimum-norm fit is inside the bounds: I = pinv(F) f."""
    rng = np.random.default_rng(5)
    for _ in range(100):
        k = int(rng.choice([1, 3, 6]))
        fm = wrench_matrices[rng.integers(len(wrench_matrices))][ROWS[k]]
        ref = np.linalg.pinv(fm) @ (fm @ rng.uniform(-1, 1, 9))
        uni = bool(np.all(ref >= 0))
        x, res = allocate(fm, fm @ ref, 6.0, 54.0, unipolar=uni)
        scale = np.abs(ref).max()
        if scale > 6.0 or np.abs(ref).sum() > 54.0:
            continue
        np.testing.assert_allclose(x, ref, rtol=0, atol=1e-8 * scale)


def test_fz_only_matches_fractional_knapsack(wrench_matrices):
    """k = 1, target far beyond reach: Fz = the knapsack optimum (sorted |a| x u till I_t)."""
    rng = np.random.default_rng(6)
    for _ in range(50):
        a = wrench_matrices[rng.integers(len(wrench_matrices))][2]
        u, tl = 6.0, float(rng.uniform(1, 60))
        srt = np.sort(np.abs(a))[::-1]
        full = int(min(9, tl // u))
        best = u * srt[:full].sum() + (tl - full * u) * (srt[full] if full < 9 else 0.0)
        x, res = allocate(a, [10 * np.abs(a).sum() * u], u, tl)
        assert a @ x == pytest.approx(best, rel=1e-12)
        assert np.abs(x).sum() <= tl * (1 + 1e-12)


def test_unipolar_cannot_pull():
    """A coil that only pulls (negative column) stays at 0 A unipolar; bipolar reverses it."""
    a = np.array([[-1.0, 0.5]])
    x, res = allocate(a, [2.0], 6.0, 54.0, unipolar=True)
    np.testing.assert_allclose(x, [0.0, 4.0], atol=1e-12)
    x, res = allocate(a, [2.0], 6.0, 54.0)
    # least energy exact fit: x = a^T (a a^T)^-1 f
    np.testing.assert_allclose(x, [-1.6, 0.8], atol=1e-12)
    assert res == pytest.approx(0.0, abs=1e-24)


def test_bounds_never_violated_extreme_scales():
    rng = np.random.default_rng(7)
    for _ in range(300):
        k, n = int(rng.integers(1, 7)), int(rng.integers(1, 12))
        fm = rng.normal(size=(k, n)) * 10.0 ** rng.uniform(-8, 4, size=(1, n))
        f = rng.normal(size=k) * 10.0 ** rng.uniform(-6, 6)
        u = rng.uniform(0, 10, n) * (rng.random(n) > 0.1)
        tl = float(rng.uniform(0, 30))
        uni = bool(rng.integers(2))
        x, res = allocate(fm, f, u, tl, unipolar=uni)
        assert np.all(np.isfinite(x)) and np.isfinite(res)
        lo = 0.0 if uni else -1.0
        assert np.all(x <= u + 1e-12 * u.max()) and np.all(x >= lo * u - 1e-12 * u.max())
        assert np.abs(x).sum() <= tl * (1 + 1e-12) + 1e-300
        kv, _ = kkt_violation(fm, f, u, tl, x, uni)
        assert kv <= 1e-7  # columns spanning 12 decades: rounding in g itself


def test_bias_is_subtracted():
    a = np.array([[1.0, 2.0, -1.0]])
    x1, r1 = allocate(a, [1.0], 6.0, 54.0, bias=[0.25])
    x2, r2 = allocate(a, [0.75], 6.0, 54.0)
    np.testing.assert_array_equal(x1, x2)


@pytest.mark.parametrize("args, name", [
    ((np.array([[1.0, np.nan]]), [1.0], 1.0, 2.0), "force_matrix"),
    ((np.array([[1.0, np.inf]]), [1.0], 1.0, 2.0), "force_matrix"),
    ((np.ones((1, 2)), [np.nan], 1.0, 2.0), "target"),
    ((np.ones((1, 2)), [1.0, 2.0], 1.0, 2.0), "target"),
    ((np.ones((1, 2)), [1.0], -1.0, 2.0), "current_limit"),
    ((np.ones((1, 2)), [1.0], [1.0, np.nan], 2.0), "current_limit"),
    ((np.ones((1, 2)), [1.0], 1.0, -0.5), "total_limit"),
    ((np.ones((1, 2)), [1.0], 1.0, np.nan), "total_limit"),
    ((np.ones((2, 3, 1)), [1.0], 1.0, 1.0), "force_matrix"),
])
def test_bad_input(args, name):
    with pytest.raises(BadInputError, match=name) as exc:
        allocate(*args)
    assert isinstance(exc.value, ValueError)


def test_numpy_only():
    package = pathlib.Path(__file__).parents[1] / "firmware_io" / "allocation"
    for path in sorted(package.glob("*.py")):
        mods = top_level_imports(path)
        assert mods <= {"numpy", "math", "__future__"}, (path.name, mods)


@pytest.mark.slow
def test_reference_1e3_problems(wrench_matrices):
    # 1e3 SLSQP references (~0.1-0.3 s each); studies/bench_allocation.py runs more
    rng = np.random.default_rng(8)
    for _ in range(1_000):
        fm, f, u, tl, uni = random_problem(rng, wrench_matrices)
        x, res = allocate(fm, f, u, tl, unipolar=uni)
        kv, infeas = kkt_violation(fm, f, u, tl, x, uni)
        assert kv <= 1e-9 and infeas <= 1e-9
        ref = slsqp_reference(fm, f, u, tl, uni)
        assert res <= ref + 1e-6 * ref + 1e-12 * (f @ f)


def _least_energy_reference(a, f, u, unipolar):
    """Fz only, no binding budget, reachable f: the least-energy currents are
    x_i = clip(a_i y, lo_i, u_i) with a . x(y) = f (KKT of min ||x||^2 s.t. a . x = f, box);
    a . x(y) is monotone in y: bisection (independent of the allocator)."""
    lo = np.zeros_like(u) if unipolar else -u

    def fit(y):
        return a @ np.clip(a * y, lo, u)

    hi = 1.0
    while fit(hi * np.sign(f)) * np.sign(f) < abs(f):
        hi *= 2.0
    y0, y1 = 0.0, hi * np.sign(f)
    for _ in range(200):
        ym = 0.5 * (y0 + y1)
        if (fit(ym) - f) * np.sign(f) < 0:
            y0 = ym
        else:
            y1 = ym
    return np.clip(a * 0.5 * (y0 + y1), lo, u)


def test_least_energy_with_saturation_matches_bisection(wrench_matrices):
    """Reachable Fz that saturates some coils: the tie-break (least energy) is exact, not just
    the residual (the eps-regularized active set alone resolved it to ~1e-3 only)."""
    rng = np.random.default_rng(11)
    for _ in range(60):
        a = wrench_matrices[rng.integers(len(wrench_matrices))][2]
        uni = bool(rng.integers(2))
        u = rng.uniform(0.5, 6.0, 9)
        lo = np.zeros(9) if uni else -u
        reach = a @ np.where(a > 0, u, lo)  # the largest reachable Fz
        f = reach * rng.uniform(0.3, 0.99)
        ref = _least_energy_reference(a, f, u, uni)
        x, res = allocate(a, [f], u, np.inf, unipolar=uni)
        np.testing.assert_allclose(x, ref, rtol=0, atol=1e-9 * u.max())
        assert res <= 1e-18 * f * f


def test_warm_start_gives_the_cold_answer(wrench_matrices):
    """Allocator (the last face as start) returns allocate's answer along a path of problems."""
    from firmware_io.allocation import Allocator

    rng = np.random.default_rng(12)
    w = wrench_matrices
    for rows, uni, tl in (([0, 1, 2], False, 12.0), ([2], True, 54.0), ([0, 1, 2, 3, 4, 5],
                                                                         False, 20.0)):
        alloc = Allocator()
        f0 = rng.normal(size=len(rows))
        for i in range(len(w) - 1):
            for t in np.linspace(0.0, 1.0, 6):  # nearby matrices and targets, like a control loop
                fm = (1 - t) * w[i][rows] + t * w[i + 1][rows]
                reach = np.abs(fm).sum(axis=1) * 6.0
                f = reach * (np.abs(f0) if uni else f0) * (0.3 + 0.4 * t)
                xc, rc = allocate(fm, f, 6.0, tl, unipolar=uni)
                xw, rw = alloc(fm, f, 6.0, tl, unipolar=uni)
                np.testing.assert_allclose(xw, xc, rtol=0, atol=1e-9)
                assert rw == pytest.approx(rc, rel=1e-9, abs=1e-12 * (f @ f))


def test_allocation_check_study_1e3():
    """The independent 1e5-problem check (studies/allocation_check.py) on a 1e3 subset."""
    import tempfile

    import allocation_check

    with tempfile.TemporaryDirectory() as tmp:
        res = allocation_check.run(tmp, n=1000, workers=1, n_pos=40, progress=False)
    a = res["all"]
    assert a["n"] == 1000 and a["n_ours_higher"] == 0 and a["n_bound_violations"] == 0
    assert a["max_rel_excess_over_reference"] <= 1e-6 and a["max_kkt_rel"] <= 1e-9


@pytest.mark.slow
def test_allocation_check_study_1e4(tmp_path):
    import allocation_check  # by name (studies/ is on sys.path): the workers unpickle it

    res = allocation_check.run(tmp_path, n=10_000, workers=2, n_pos=200, seed=7,
                               progress=False)
    a = res["all"]
    assert a["n"] == 10_000 and a["n_ours_higher"] == 0 and a["n_bound_violations"] == 0
    assert a["max_rel_excess_over_reference"] <= 1e-6 and a["max_kkt_rel"] <= 1e-9


@pytest.mark.parametrize("fm, f, u", [
    ([[1e300, 1e300]], [1e308], 1.0),       # F^T F beyond the float range
    ([[1e-300, 2e-300]], [1e-300], 1.0),    # F^T F below it
    ([[1.0, 2.0]], [1e300], 1e-300),        # a target 1e600 times the reach
    ([[1.0, 2.0]], [1.0], 1e300),           # limits near the float range
])
def test_float_range_ends_finite_and_silent(fm, f, u):
    """No overflow warning, no inf/NaN out, bounds kept, exact where the problem is exact."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        x, res = allocate(fm, f, u, np.inf)
    assert np.all(np.isfinite(x)) and np.isfinite(res) and np.all(np.abs(x) <= u)
    s = np.abs(fm[0]).max()
    a = np.asarray(fm[0]) / s  # the least-norm exact fit a f / |a|^2, computed in range
    if abs(f[0]) / s <= np.abs(a).sum() * u:  # reachable
        np.testing.assert_allclose(x, a * (f[0] / s) / (a @ a), rtol=1e-12)


@pytest.mark.parametrize("k", [1, 3, 6])
@pytest.mark.parametrize("uni", [False, True])
def test_binding_budget_far_targets_match_slsqp(wrench_matrices, k, uni):
    """The paths added for speed: far targets (the bang-bang cold start wins), a budget that
    binds (the kept bordered face system), bipolar coils that cross 0 with the budget out of
    the working set (the piecewise-linear budget ratio test) -- checked against SLSQP and the
    KKT certificate, with the budget verified to bind."""
    rng = np.random.default_rng(100 + 10 * k + uni)
    w = wrench_matrices
    n_bind = 0
    for _ in range(12):
        fm = w[rng.integers(len(w))][ROWS[k]]
        u = rng.uniform(0.5, 6.0, fm.shape[1]) if rng.random() < 0.5 else 6.0
        tl = float(rng.uniform(2.0, 30.0))
        reach = np.abs(fm).sum(axis=1) * 6.0
        f = rng.normal(size=k) * reach * rng.choice([0.5, 2.0, 5.0])
        x, res = allocate(fm, f, u, tl, unipolar=uni)
        kv, infeas = kkt_violation(fm, f, u, tl, x, uni)
        assert infeas <= 1e-9 and kv <= 1e-9, (kv, infeas)
        ref = slsqp_reference(fm, f, u, tl, uni)
        if res > ref + 1e-6 * ref + 1e-12 * (f @ f):  # SLSQP from 0 can stop early: 2nd start
            ref = slsqp_reference(fm, f, u, tl, uni, starts=2)
        assert res <= ref + 1e-6 * ref + 1e-12 * (f @ f), (res, ref)
        n_bind += abs(np.abs(x).sum() - min(tl, np.broadcast_to(u, (9,)).sum())) <= 1e-9 * tl
    assert n_bind >= 3  # the budget really is active in a good part of them


def test_budget_hit_is_the_first_crossing():
    """_budget_hit (the step at which sum |x + a d| reaches the budget, coils crossing 0 on
    the way) against a dense scan of the same function (independent: no breakpoints)."""
    from firmware_io.allocation.feasible import budget_hit

    rng = np.random.default_rng(7)
    grid = np.linspace(0.0, 1.0, 200001)
    for _ in range(40):
        x = rng.uniform(-1, 1, 9)
        h = rng.uniform(-1, 1, 9) * rng.choice([1.0, 3.0])
        ts = float(np.abs(x).sum() + rng.uniform(-0.3, 2.0))
        if np.abs(x).sum() > ts:  # the start must be feasible
            ts = float(np.abs(x).sum())
        alpha = float(rng.uniform(0.3, 1.0))
        a = budget_hit(x.tolist(), h.tolist(), alpha, ts)
        path = np.abs(x[None, :] + (grid * alpha)[:, None] * (h - x)[None, :]).sum(axis=1)
        over = np.nonzero(path > ts * (1 + 1e-12))[0]
        if len(over) == 0:
            assert a == np.inf
        else:
            first = grid[over[0]] * alpha
            assert first - alpha / 200000 - 1e-12 <= a <= first + 1e-12, (a, first)
            assert np.abs(x + a * (h - x)).sum() == pytest.approx(ts, rel=1e-12)
