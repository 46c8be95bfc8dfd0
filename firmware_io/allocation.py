"""Exact bounded current allocation (thesis eq. 4.9) -- numpy only, it runs on the controller.

Problem, for one magnet position p with the force matrix F = F(p) (k, n) of the caller's rows
(k = 1: Fz only as in the thesis; k = 3: the force; k = 6: force and torque) and the target f::

    minimize    ||F I - f||^2                       (N^2, or the caller's row units squared)
    subject to  -u_i <= I_i <= u_i                   (bipolar, default: the MD10C reverses)
                 0   <= I_i <= u_i                   (unipolar=True: the thesis' drive)
                 sum_i |I_i| <= I_t                  (supply budget)

Among the minimizers (F has a null space as soon as n > k) the least-energy one (min sum I^2)
is returned, so the answer is unique and continuous in p.

Method: a primal active-set method on the strictly convex problem

    minimize ||F I - f||^2 + eps ||I||^2,   eps = 1e-10 * max_i ||F[:, i]||^2 * (u_max / s)^2

(in scaled units, see ``_solve``), written on the bipolar split I = I+ - I- (2n non-negative
variables, box + one linear inequality; each coil is free with a sign, at +-u, or at 0). The
Tikhonov term makes the solution unique and equal, up to the bias below, to the
lexicographic answer (least residual first, least energy second). Bias bound: if I* is the
least-energy minimizer, the returned I_eps satisfies

    ||F I_eps - f||^2 - ||F I* - f||^2 <= eps (||I*||^2 - ||I_eps||^2) <= eps * u_max * I_t',

with I_t' = min(I_t, sum u_i), i.e. <= 1e-10 of (max column force x u_max)^2 x n, and the
stationarity conditions of the unregularized problem hold up to eps ||I|| (1e-10 relative).
Each equality-constrained sub-problem is solved in the smaller of two exact forms: the primal
normal equations when at most k coils are free, otherwise the kernel form I_J = F_J^T y (+ t s),
which keeps the solution exactly in the row space (the least-energy direction) by construction.

The bias force: the magnet's pull on the iron cores at zero current, F0(p), is not produced by
the currents, so the currents must render ``f - F0(p)``. Pass ``bias=F0`` (same rows as
``target``) or subtract it yourself; with map v2 it is ``MapFile.bias_force(points)``.

Usage::

    from firmware_io.allocation import allocate
    currents_a, residual = allocate(F, f_n, 6.0, 54.0)               # bipolar
    currents_a, residual = allocate(F, f_n, 6.0, 54.0, unipolar=True)
"""

from __future__ import annotations

import math

import numpy as np

from .errors import BadInputError

EPS_REL = 1e-10
"""Tikhonov weight relative to the largest squared column norm of the scaled F (see above)."""

_MULT_TOL = 1e-13
"""Multipliers above -_MULT_TOL x (gradient scale) count as non-negative (rounding level,
three decades below the eps-level multipliers of the tie-break)."""


def _as_matrix(force_matrix) -> np.ndarray:
    try:
        f = np.asarray(force_matrix, dtype=float)
    except (TypeError, ValueError):
        raise BadInputError("force_matrix", "a (k, n) array of finite numbers, N/A",
                            type(force_matrix).__name__) from None
    if f.ndim == 1:
        f = f[None, :]
    if f.ndim != 2 or f.shape[0] < 1 or f.shape[1] < 1:
        raise BadInputError("force_matrix", "a (k, n) array with k, n >= 1, N/A",
                            f"shape {f.shape}")
    if not np.all(np.isfinite(f)):
        bad = np.argwhere(~np.isfinite(f))[0]
        raise BadInputError("force_matrix", "finite (no NaN or Inf), N/A",
                            f"{f[tuple(bad)]} at index {tuple(int(b) for b in bad)}")
    return f


def _check_inputs(force_matrix, target, current_limit, total_limit, bias):
    fm = _as_matrix(force_matrix)
    k, n = fm.shape
    try:
        t = np.asarray(target, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise BadInputError("target", f"{k} finite numbers (N)", target) from None
    if t.shape != (k,):
        raise BadInputError("target", f"{k} values (one per row of force_matrix), N",
                            f"shape {np.shape(target)}")
    if not np.all(np.isfinite(t)):
        raise BadInputError("target", "finite (no NaN or Inf), N", t.tolist())
    if bias is not None:
        b = np.asarray(bias, dtype=float).reshape(-1)
        if b.shape != (k,) or not np.all(np.isfinite(b)):
            raise BadInputError("bias", f"{k} finite values (the map's F0 in the target's "
                                "rows), N", np.asarray(bias).tolist())
        t = t - b
    try:
        u = np.broadcast_to(np.asarray(current_limit, dtype=float), (n,)).astype(float)
    except (TypeError, ValueError):
        raise BadInputError("current_limit", f"a number or {n} numbers >= 0, A",
                            current_limit) from None
    if not np.all(np.isfinite(u)) or np.any(u < 0):
        bad = u[~(np.isfinite(u) & (u >= 0))][0]
        raise BadInputError("current_limit", "finite and >= 0 (per coil), A", float(bad))
    try:
        tl = float(total_limit)
    except (TypeError, ValueError):
        raise BadInputError("total_limit", ">= 0 A (inf: no budget)", total_limit) from None
    if math.isnan(tl) or tl < 0:
        raise BadInputError("total_limit", ">= 0 A (inf: no budget); a negative budget "
                            "makes sum |I| <= I_t infeasible", tl)
    return fm, t, u, tl


def allocate(force_matrix, target, current_limit, total_limit, *, unipolar: bool = False,
             bias=None, max_iter: int | None = None):
    """Currents that render ``target`` as closely as the bounds allow (thesis eq. 4.9).

    Parameters
    ----------
    force_matrix : array-like, shape (k, n)
        Force (and/or torque) per ampere of each coil at the magnet, N/A (N m/A for torque
        rows). A 1-D array is one row.
    target : array-like, shape (k,)
        Wanted force (torque), N (N m), in the same rows.
    current_limit : float or array-like (n,)
        Per-coil limit u_i >= 0, A.
    total_limit : float
        Budget I_t >= 0 on sum |I_i|, A (``inf``: none).
    unipolar : bool
        ``True``: 0 <= I_i <= u_i (the thesis); default ``False``: |I_i| <= u_i.
    bias : array-like (k,), optional
        The bias force F0(p) (magnet on the cores at zero current); the currents then render
        ``target - bias``.
    max_iter : int, optional
        Active-set iteration cap (default 50 + 10 n); the returned currents are feasible even
        if it is hit.

    Returns
    -------
    currents : ndarray (n,), A
        Always inside the bounds (clamped to them; the budget holds to 1e-12 relative).
    residual : float
        ||F I - (target - bias)||^2, N^2.

    Raises
    ------
    BadInputError (a ValueError)
        Non-finite matrix/target/bias, wrong shapes, negative or NaN limits, I_t < 0.
    """
    fm, t, u, tl = _check_inputs(force_matrix, target, current_limit, total_limit, bias)
    x = _solve(fm, t, u, tl, bool(unipolar), max_iter)
    r = fm @ x - t
    return x, float(r @ r)


def _solve(fm, f, u, tl, unipolar, max_iter):
    k, n = fm.shape
    umax = float(u.max())
    tl_eff = min(tl, float(_add(u)))
    if umax == 0.0 or tl_eff == 0.0:
        return np.zeros(n)
    # scale currents by u_max and forces by the largest achievable column force
    cs = math.sqrt(float((fm * fm).sum(axis=0).max())) * umax
    fscale = max(cs, float(np.abs(f).max()))
    if fscale == 0.0:
        return np.zeros(n)
    fs = fm * (umax / fscale)
    ft = f / fscale
    rows = _or(fs != 0.0, axis=1)
    if not _and(rows):  # an all-zero row (e.g. torque about m) adds a constant residual only
        if not _or(rows):
            return np.zeros(n)
        fs, ft = fs[rows], ft[rows]
        k = fs.shape[0]
    us = u / umax
    ts = tl_eff / umax
    budget_possible = ts < _add(us) * (1 - 1e-15)
    c2 = float((fs * fs).sum(axis=0).max())
    eps = EPS_REL * max(c2, 1e-300)
    h = fs.T @ fs
    q = fs.T @ ft
    gscale = c2 + math.sqrt(float(q @ q)) + 1e-300
    tol = _MULT_TOL * gscale
    lo = 0.0 if unipolar else -1.0
    if max_iter is None:
        max_iter = 50 + 10 * n

    # ---- start: a few semismooth-Newton steps on the k-dimensional dual guess the active set
    x = _dual_guess(fs, ft, us, ts if budget_possible else np.inf, eps, unipolar)
    ab = np.abs(x)
    sg = np.where(x >= 0, 1.0, -1.0)
    free = (ab > 0.0) & (ab < us)
    bud = bool(budget_possible and _add(ab) >= ts * (1 - 1e-12))
    if bud and not _or(free):
        bud = False
    fixed_val = np.where(free, 0.0, x)

    state = _active_set(fs, ft, h, q, us, ts, eps, tol, unipolar, budget_possible, k, n,
                        max_iter, x, free, sg, fixed_val, bud)
    # ---- polish: the eps -> 0 limit on the final face (the lexicographic answer: least residual,
    # then least energy) removes the Tikhonov bias when it stays on the face; if it leaves the
    # face, a continuation pass with eps 1e4 x smaller (warm started, usually 1 face) first
    x, ok = _polish(fs, ft, h, q, us, ts, k, *state)
    if not ok:
        state = _active_set(fs, ft, h, q, us, ts, eps * 1e-4, tol, unipolar, budget_possible,
                            k, n, max_iter, *state)
        x, _ = _polish(fs, ft, h, q, us, ts, k, *state)
    # ---- guarantee: never outside the bounds, whatever round-off did
    x = _clip(x, lo * us, us)
    tot = float(_add(np.abs(x)))
    if tot > ts:
        x *= ts / tot
    return x * umax



def _polish(fs, ft, h, q, us, ts, k, x, free, sg, fixed_val, bud):
    """(x, accepted): the eps = 0 face minimizer if it stays on the face and is no worse."""
    if not _or(free):
        return x, True
    xp = _face_minimizer(fs, ft, h, q, 0.0, free, sg, fixed_val, bud, ts, k)
    a = sg[free] * xp[free]
    slack = 1e-12 * float(us.max())
    if _and(a >= -slack) and _and(a <= us[free] + slack):
        xp[free] = sg[free] * _clip(a, 0.0, us[free])
        rp, rx = fs @ xp - ft, fs @ x - ft
        if rp @ rp <= rx @ rx:
            return xp, True
    return x, False


def _active_set(fs, ft, h, q, us, ts, eps, tol, unipolar, budget_possible, k, n, max_iter,
                x, free, sg, fixed_val, bud):
    """Primal active-set iterations from a feasible point and its working set."""
    idx = np.arange(n)
    solve_face = True
    for _ in range(max_iter):
        if solve_face:
            xh = _face_minimizer(fs, ft, h, q, eps, free, sg, fixed_val, bud, ts, k)
            p = xh - x
            j = idx[free]
            if j.size:
                sp = sg[j] * p[j]
                ax = sg[j] * x[j]
                alpha, block, kind = 1.0, -1, 0
                neg = sp < 0
                if _or(neg):
                    a = ax[neg] / -sp[neg]
                    m = int(np.argmin(a))
                    if a[m] < alpha:
                        alpha, block, kind = float(a[m]), int(j[neg][m]), 0
                pos = sp > 0
                if _or(pos):
                    a = (us[j[pos]] - ax[pos]) / sp[pos]
                    m = int(np.argmin(a))
                    if a[m] < alpha:
                        alpha, block, kind = float(a[m]), int(j[pos][m]), 1
                if budget_possible and not bud:
                    rate = float(_add(sp))
                    if rate > 0:
                        a = (ts - float(_add(np.abs(x)))) / rate
                        if a < alpha:
                            alpha, block, kind = max(a, 0.0), -1, 2
                if alpha < 1.0:
                    alpha = max(alpha, 0.0)
                    # projected full step: may fix several coils at once; taken when it beats
                    # the blocked step (keeps descent and feasibility)
                    xt, _ = _project(xh, us, ts if budget_possible else np.inf, unipolar)
                    xb = x + alpha * p
                    if _phi(fs, ft, eps, xt) < _phi(fs, ft, eps, xb):
                        x = xt
                        ab = np.abs(x)
                        free = (ab > 0.0) & (ab < us)
                        sg = np.where(x >= 0, 1.0, -1.0)
                        fixed_val = np.where(free, 0.0, x)
                        bud = bool(budget_possible and _add(ab) >= ts * (1 - 1e-12)
                                   and _or(free))
                        continue
                    x = xb
                    if kind == 2:
                        bud = True
                    else:
                        free[block] = False
                        fixed_val[block] = 0.0 if kind == 0 else sg[block] * us[block]
                        x[block] = fixed_val[block]
                    # keep free coordinates on their side and inside the box under round-off
                    jj = idx[free]
                    x[jj] = sg[jj] * _clip(sg[jj] * x[jj], 0.0, us[jj])
                    if bud and not _or(free):
                        bud = False  # implied by the bounds: a redundant working constraint
                    continue
            x = xh
        # ---- at the face minimizer: multipliers of the working constraints
        g = h @ x - q + eps * x
        j = idx[free]
        nu = 0.0
        if bud and j.size:
            nu = float(-(sg[j] * g[j]).mean())
        lam = np.full(n, np.inf)
        zero = ~free & (fixed_val == 0.0)
        if unipolar:
            lam[zero] = g[zero] + nu
        else:
            lam[zero] = nu - np.abs(g[zero])
        up = ~free & (fixed_val != 0.0)
        lam[up] = -(np.sign(fixed_val[up]) * g[up] + nu)
        lam[us == 0.0] = np.inf  # a coil with u_i = 0 is off: nothing to release
        m = int(np.argmin(lam))
        lam_b = nu if bud else np.inf
        if min(lam[m], lam_b) >= -tol:
            break
        if lam_b < lam[m]:
            bud = False
        else:
            free[m] = True
            if fixed_val[m] == 0.0:
                sg[m] = 1.0 if (unipolar or g[m] < 0) else -1.0
            else:
                sg[m] = 1.0 if fixed_val[m] > 0 else -1.0
            fixed_val[m] = 0.0
        solve_face = True
    return x, free, sg, fixed_val, bud

def _face_minimizer(fs, ft, h, q, eps, free, sg, fixed_val, bud, ts, k):
    """Minimizer of the regularized objective on the working face (free coils keep their sign;
    with ``bud`` the budget holds with equality)."""
    x = fixed_val.copy()
    j = np.flatnonzero(free)
    nf = j.size
    if nf == 0:
        return x
    r = ft - fs @ fixed_val
    s = sg[j]
    fj = fs[:, j]
    if nf > k + bud:
        # kernel form: x_J = F_J^T y (+ t s), exact in the row space
        if bud:
            gmat = np.concatenate([fj.T, s[:, None]], axis=1)
            top = fj @ gmat
            top[:, :k] += eps * np.eye(k)
            mat = np.concatenate([top, (s @ gmat)[None, :]], axis=0)
            c = ts - float(_add(np.abs(fixed_val)))
            w = _lsolve(mat, np.append(r, c), eps > 0)
            x[j] = gmat @ w
        else:
            y = _lsolve(fj @ fj.T + eps * np.eye(k), r, eps > 0)
            x[j] = fj.T @ y
        return x
    hj = h[np.ix_(j, j)] + eps * np.eye(nf)
    b = fj.T @ r
    if bud:
        c = ts - float(_add(np.abs(fixed_val)))
        mat = np.empty((nf + 1, nf + 1))
        mat[:nf, :nf] = hj
        mat[:nf, nf] = s
        mat[nf, :nf] = s
        mat[nf, nf] = 0.0
        sol = _lsolve(mat, np.append(b, c), eps > 0)
        x[j] = sol[:nf]
    else:
        x[j] = _lsolve(hj, b, eps > 0)
    return x


_add = np.add.reduce
_and = np.logical_and.reduce
_or = np.logical_or.reduce


def _clip(a, lo, hi):
    """np.clip without its Python wrapper (this module's inner loops are call-bound)."""
    return np.minimum(np.maximum(a, lo), hi)


def _phi(fs, ft, eps, x):
    r = fs @ x - ft
    return float(r @ r + eps * (x @ x))


try:  # the gufunc behind np.linalg.solve without its Python wrapper and errstate (tiny systems)
    from numpy.linalg import _umath_linalg as _ul

    def _fast_solve(mat, rhs):
        return _ul.solve1(mat, rhs, signature="dd->d")
except (ImportError, AttributeError):  # pragma: no cover - other numpy layouts
    _fast_solve = np.linalg.solve


def _lsolve(mat, rhs, regularized=True):
    """Solve; ``regularized`` systems (eps > 0) are never singular, so they skip the
    floating-point guards; others fall back to least squares on an exactly singular face."""
    if regularized:
        out = _fast_solve(mat, rhs)
        if _and(np.isfinite(out)):
            return out
    try:
        with np.errstate(invalid="raise", divide="raise", over="ignore"):
            out = _fast_solve(mat, rhs)
        if _and(np.isfinite(out)):
            return out
    except (np.linalg.LinAlgError, FloatingPointError):
        pass
    return np.linalg.lstsq(mat, rhs, rcond=None)[0]


def _project(v, us, ts, unipolar):
    """Euclidean projection of v onto {lo <= x <= u, sum |x| <= ts}; also the threshold tau."""
    a = v if unipolar else np.abs(v)
    c = _clip(a, 0.0, us)
    if _add(c) <= ts:
        tau = 0.0
    else:
        # sum clip(a - tau, 0, u) is piecewise linear and decreasing in tau: bracket, interpolate
        bp = np.concatenate([a - us, a])
        bp = np.unique(bp[bp > 0.0])
        sums = _clip(a[None, :] - bp[:, None], 0.0, us).sum(axis=1)
        i = int(np.searchsorted(-sums, -ts))  # first breakpoint with sum <= ts
        t_hi, s_hi = bp[i], sums[i]
        t_lo, s_lo = (bp[i - 1], sums[i - 1]) if i > 0 else (0.0, _add(c))
        tau = t_lo + (s_lo - ts) * (t_hi - t_lo) / max(s_lo - s_hi, 1e-300)
        c = _clip(a - tau, 0.0, us)
    return (c if unipolar else np.copysign(c, v)), tau


def _dual_guess(fs, ft, us, ts, eps, unipolar, steps=6):
    """x = proj_X(F^T y) with y from semismooth Newton on F proj_X(F^T y) + eps y = f (the
    optimality condition of the regularized problem, y = (f - F x) / eps). Feasible always;
    exact when the pattern of free/bound coils it finds is the optimal one."""
    k = fs.shape[0]
    eye = eps * np.eye(k)
    y = _lsolve(fs @ fs.T + eye, ft)
    v = fs.T @ y
    x, tau = _project(v, us, ts, unipolar)
    if tau == 0.0 and np.array_equal(x, v):
        return x  # the unconstrained minimizer is feasible
    seen = None
    for _ in range(steps):
        ax = np.abs(x)
        fr = (ax > 0.0) & (ax < us)
        key = fr.tobytes() + (x > 0).tobytes() + (x < 0).tobytes()
        if key == seen:
            break
        seen = key
        ff = fs[:, fr]
        jac = ff @ ff.T + eye
        if tau > 0.0 and _or(fr):
            w = ff @ np.sign(x[fr])
            jac -= np.outer(w, w) / _add(fr)
        y = y - _lsolve(jac, fs @ x + eps * y - ft)
        x, tau = _project(fs.T @ y, us, ts, unipolar)
    return x
