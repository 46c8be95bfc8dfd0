"""Independent references for the allocator (tests and studies/bench_allocation.py): a KKT certificate and an SLSQP QP solve.

Nothing here imports firmware_io.allocation: the checker only reads (F, f, u, I_t, I).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from designkit.support.blas import one_blas_thread


def kkt_violation(fm, f, u, tl, x, unipolar=False, *, zero_tol=None):
    """Largest violation of the KKT conditions of min ||F x - f||^2 over the allocation set,
    relative to the gradient scale ||F||_2 (||F||_2 ||x|| + ||f||) (dimensionless).

    Conditions with g = F^T (F x - f), budget multiplier nu >= 0 (0 unless sum |x| = I_t):
    free coil (0 < |x_i| < u_i): g_i + nu sign(x_i) = 0; at +-u_i: -sign(x_i) g_i - nu >= 0;
    at 0: nu >= |g_i| (bipolar) or g_i + nu >= 0 (unipolar). nu is chosen to minimize the
    largest violation (a 1-D convex piecewise-linear problem: its breakpoints are checked).
    Also returns the primal infeasibility in A.
    """
    fm = np.atleast_2d(np.asarray(fm, float))
    f = np.asarray(f, float)
    u = np.broadcast_to(np.asarray(u, float), x.shape)
    g = fm.T @ (fm @ x - f)
    nrm = np.linalg.norm(fm, 2)
    scale = nrm * (nrm * np.linalg.norm(x) + np.linalg.norm(f)) + 1e-300
    umax = float(u.max()) if u.size else 1.0
    ztol = 1e-12 * umax if zero_tol is None else zero_tol
    ax = np.abs(x)
    lo = 0.0 if unipolar else -1.0
    infeas = max(float(np.max(np.maximum(x - u, lo * u - x), initial=0.0)),
                 float(ax.sum() - tl), 0.0)
    off = u == 0.0  # no condition on a coil whose limit is 0 A
    at_zero = (ax <= ztol) & ~off
    at_up = (ax >= u - ztol) & ~at_zero & ~off
    fr = ~at_zero & ~at_up & ~off
    s = np.sign(x)
    budget_tight = tl < np.inf and ax.sum() >= tl - 1e-9 * max(tl, umax)

    def viol(nu):
        v = [np.abs(g[fr] + nu * s[fr])]
        v.append(np.maximum(0.0, s[at_up] * g[at_up] + nu))
        if unipolar:
            v.append(np.maximum(0.0, -(g[at_zero] + nu)))
        else:
            v.append(np.maximum(0.0, np.abs(g[at_zero]) - nu))
        return max((float(a.max()) for a in v if a.size), default=0.0)

    if budget_tight:
        cands = np.concatenate([[0.0], -s[fr] * g[fr], -s[at_up] * g[at_up],
                                np.abs(g[at_zero]), -g[at_zero]])
        cands = cands[cands >= 0]
        best = min(viol(c) for c in cands)
    else:
        best = viol(0.0)
    return best / scale, infeas


def slsqp_reference(fm, f, u, tl, unipolar=False, *, starts=2, ftol=1e-16, maxiter=1000):
    """min ||F x - f||^2 with SLSQP on the split x = P - N (scaled to O(1)); the objective.
    ``ftol`` is SLSQP's (absolute) precision goal on the scaled objective, ``maxiter`` its cap."""
    fm = np.atleast_2d(np.asarray(fm, float))
    k, n = fm.shape
    u = np.broadcast_to(np.asarray(u, float), (n,))
    umax = u.max()
    fs = max(np.abs(fm).max() * umax, np.abs(f).max(), 1e-300)
    a = fm * umax / fs
    b = np.asarray(f, float) / fs
    us = u / umax
    ts = min(tl, u.sum()) / umax
    if unipolar:
        d = a
        bounds = [(0, ui) for ui in us]
    else:
        d = np.concatenate([a, -a], axis=1)
        bounds = [(0, ui) for ui in us] * 2
    def fun(z):
        r = d @ z - b
        return r @ r, 2 * d.T @ r

    cons = [{"type": "ineq", "fun": lambda z: ts - z.sum(),
             "jac": lambda z: -np.ones_like(z)}]
    with one_blas_thread():  # tiny products: a multithreaded BLAS of a busy machine only waits
        best = _slsqp_runs(fun, d, b, us, ts, unipolar, bounds, cons, starts, ftol, maxiter)
    return best * fs * fs


def _slsqp_runs(fun, d, b, us, ts, unipolar, bounds, cons, starts, ftol, maxiter):
    best = None
    for z0 in (np.zeros(d.shape[1]), np.clip(np.linalg.lstsq(d, b, rcond=None)[0], 0, None))[:starts]:
        z0 = np.minimum(z0, np.concatenate([us] * (1 if unipolar else 2)))
        if z0.sum() > ts:
            z0 *= ts / z0.sum()
        res = minimize(fun, z0, jac=True, method="SLSQP", bounds=bounds, constraints=cons,
                       options={"ftol": ftol, "maxiter": maxiter})
        z = np.clip(res.x, 0, None)
        z = np.minimum(z, np.concatenate([us] * (1 if unipolar else 2)))
        if z.sum() > ts:
            z *= ts / z.sum()
        val = fun(z)[0]
        if best is None or val < best:
            best = val
    return best

