"""The bounded allocation with extra linear constraints on the currents, G I <= h.

Thesis eq. 4.9 plus a caller's rows (e.g. keep chosen Hall sensors in their linear range:
|C_s I + b_s| <= limit per axis, :class:`firmware_io.runner.SensorHeadroom`)::

    minimize ||F I - f||^2 + eps ||I||^2   subject to   the box, sum |I_i| <= I_t,   G I <= h

When the answer of :func:`.solve.allocate` (the exact least-energy minimizer without G)
satisfies G I <= h it is the answer: the usual step pays one product. Otherwise a primal
active set on the split currents I = I+ - I- (bipolar; I itself unipolar), strictly convex
through the same eps as the main solver (:data:`.problem.EPS_REL`, its bias bound holds),
starts from that answer scaled back into G I <= h (feasible: the set is convex and holds 0 when
h >= 0) and adds or releases one constraint at a time (Nocedal & Wright, Numerical
Optimization, 2nd ed., algorithm 16.3). Every iterate is feasible, so an iteration cap still
returns currents within every bound. Scaled units inside (currents / u_max, forces / the
largest column force); SI outside (A, N).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import BadInputError
from .problem import EPS_REL, check_inputs
from .solve import allocate

MAX_ITER = 200
"""Cap on the active-set iterations (each adds or releases one constraint)."""


def check_inequalities(inequalities, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(G (r, n), h (r,)) as float arrays, finite, h >= 0 (zero currents must satisfy them:
    a row the rest already violates cannot be kept), else BadInputError."""
    try:
        g, h = (np.asarray(a, dtype=float) for a in inequalities)
    except (TypeError, ValueError):
        raise BadInputError("inequalities", "a pair (G (r, n), h (r,)) of numbers",
                            type(inequalities).__name__) from None
    h = h.reshape(-1)
    if g.shape != (len(h), n) or not (np.all(np.isfinite(g)) and np.all(np.isfinite(h))):
        raise BadInputError("inequalities", f"G (r, {n}) and h (r,) finite, one h per row",
                            f"shapes {g.shape}, {h.shape}")
    if np.any(h < 0):
        raise BadInputError("inequalities", "h >= 0 (zero currents must satisfy G I <= h)",
                            float(h.min()))
    return g, h


def allocate_within(force_matrix, target, current_limit, total_limit, inequalities, *,
                    unipolar: bool = False, bias=None, warm=None):
    """Currents that render ``target`` as closely as the bounds and G I <= h allow.

    Parameters as :func:`firmware_io.allocation.allocate` (``warm``: its warm start, for the
    solve without G), plus ``inequalities`` = (G (r, n), h (r,)) in the currents' units (A)
    with h >= 0.

    Returns
    -------
    currents : ndarray (n,), A -- within the box, the budget and G I <= h (to round-off)
    residual : float -- ||F I - (target - bias)||^2, N^2
    """
    x, res = allocate(force_matrix, target, current_limit, total_limit, unipolar=unipolar,
                      bias=bias, warm=warm)
    fm, t, u, tl, scale_e = check_inputs(force_matrix, target, current_limit, total_limit, bias)
    g, h = check_inequalities(inequalities, fm.shape[1])
    if not len(h) or _holds(g, h, x):
        return x, res
    x = _solve(fm, t, (np.asarray(u), tl, unipolar), (g, h), x)
    r = fm.dot(x) - t        # fm, t as check_inputs scaled them (exactly, by 2^-scale_e)
    return x, math.ldexp(float(r.dot(r)), 2 * scale_e)


def _holds(g, h, x) -> bool:
    """G x <= h up to round-off (1e-12 of the terms)."""
    gx = g.dot(x)
    return bool(np.all(gx <= h + 1e-12 * (np.abs(h) + np.abs(g).dot(np.abs(x)))))


def _solve(fm, f, bounds, rows, x0):
    """The constrained currents (n,) A; ``bounds`` = (u (n,) A, I_t A, unipolar), ``rows`` =
    (G, h), ``x0`` the answer without G (A): the start, moved back into G I <= h."""
    u, tl, unipolar = bounds
    g, h = rows
    n = fm.shape[1]
    umax = float(u.max())
    if umax == 0.0 or tl == 0.0:
        return np.zeros(n)
    cn = math.sqrt(float((fm * fm).sum(axis=0).max()))
    fscale = max(cn * umax, float(np.abs(f).max()), 1e-300)
    fs, ft = fm * (umax / fscale), f / fscale
    us, ts = u / umax, min(tl, float(u.sum())) / umax
    split = not unipolar and ts < float(us.sum()) * (1 - 1e-15)
    # the split I = I+ - I- only where the budget sum |I| <= I_t can bind
    p = np.hstack([np.eye(n), -np.eye(n)]) if split else np.eye(n)
    fp = fs.dot(p)
    hq = fp.T.dot(fp) + EPS_REL * (cn * umax / fscale) ** 2 * np.eye(p.shape[1])
    c = fp.T.dot(ft)
    a, b = _constraints(p, (us, ts, unipolar, split), (g * umax, h))
    z = _start(a, b, p, np.asarray(x0, float) / umax)
    z = _active_set(hq, c, (a, b), z, float(ft.dot(ft)) + 1.0)
    x = p.dot(z) * umax
    lo = 0.0 if unipolar else -1.0
    x = np.clip(x, lo * u, u)
    tot = float(np.abs(x).sum())
    return x * (tl / tot) if tot > tl else x


def _constraints(p, box, sensor_rows):
    """All constraints as A z <= b (rows normalized), ``box`` = (u / u_max, I_t / u_max,
    unipolar, split): split, 0 <= z <= u for both halves and the budget; unipolar 0 <= I <= u;
    bipolar -u <= I <= u; then G P z <= h."""
    us, ts, unipolar, split = box
    nz = p.shape[1]
    eye = np.eye(nz)
    if split:
        rows, rhs = [-eye, eye, np.ones((1, nz))], [np.zeros(nz), np.tile(us, 2), [ts]]
    else:
        rows, rhs = [-eye, eye], [np.zeros(nz) if unipolar else us, us]
    gz = sensor_rows[0].dot(p)
    norm = np.maximum(np.sqrt((gz * gz).sum(axis=1)), 1e-300)
    rows.append(gz / norm[:, None])
    rhs.append(sensor_rows[1] / norm)
    return np.vstack(rows), np.concatenate(rhs)


def _start(a, b, p, x):
    """A feasible start: the currents ``x`` (scaled; split into their signs when ``p`` splits
    them) moved back towards 0 until every constraint holds (0 satisfies them all)."""
    z = np.concatenate([np.maximum(x, 0.0), np.maximum(-x, 0.0)]) if p.shape[1] > len(x) \
        else x
    az = a.dot(z)
    over = az > b
    s = 1.0
    if over.any():
        s = float(np.min(np.where(over, b / np.where(over, az, 1.0), 1.0)))
    return max(min(s, 1.0), 0.0) * (1 - 1e-12) * z


def _active_set(hq, c, ab, z, qscale):
    """Primal active set for min 1/2 z^T H z - c^T z, A z <= b from a feasible z; the working
    set starts as the constraints that hold with equality there. A step that lowers the
    objective by less than 1e-13 of ``qscale`` counts as none (H is eps-regular along F's
    null space: its solves are accurate in the objective, not in those directions)."""
    a, b = ab
    nz = len(z)
    slack = b - a.dot(z)
    work = [int(i) for i in np.flatnonzero(slack <= 0.0)]
    row_size = np.abs(a).sum(axis=1)
    for _ in range(MAX_ITER):
        grad = hq.dot(z) - c
        aw = a[work]
        m = len(work)
        kkt = np.zeros((nz + m, nz + m))
        kkt[:nz, :nz] = hq
        kkt[:nz, nz:] = aw.T
        kkt[nz:, :nz] = aw
        rhs = np.concatenate([-grad, np.zeros(m)])
        try:
            sol = np.linalg.solve(kkt, rhs)
            sol += np.linalg.solve(kkt, rhs - kkt.dot(sol))   # one refinement step
        except np.linalg.LinAlgError:
            sol = np.linalg.lstsq(kkt, rhs, rcond=None)[0]
        step, mult = sol[:nz], sol[nz:]
        if -(grad.dot(step) + 0.5 * step.dot(hq.dot(step))) <= 1e-13 * qscale:
            if m == 0 or float(mult.min()) >= -1e-10 * qscale:
                return z
            work.pop(int(np.argmin(mult)))
            continue
        ap = a.dot(step)
        slack = b - a.dot(z)
        alpha, block = 1.0, -1
        for i in np.flatnonzero(ap > 1e-15 * row_size):
            if i in work:
                continue
            ai = max(float(slack[i]), 0.0) / float(ap[i])
            if ai < alpha:
                alpha, block = ai, int(i)
        z = z + alpha * step
        if block >= 0:
            work.append(block)
    return z
