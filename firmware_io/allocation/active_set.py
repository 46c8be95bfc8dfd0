"""The primal active-set method on the eps-regularized allocation problem, and its cold start.

From a feasible point and its working set (which coils are free and with which sign, which are
fixed at 0 or +-u, whether the budget holds with equality) each iteration solves the working
face (:mod:`.faces`), steps towards its minimizer up to the first blocking constraint (ratio
test) and, at the face minimizer, releases the constraint with the most negative multiplier.
Bipolar, while the budget is not in the working set, a coil crosses 0 in one step. Scaled
units; the method and its bias bound: docs/allocation.md.
"""

from __future__ import annotations

import math

import numpy as np

from .faces import _face_minimizer
from .feasible import _budget_hit, _proj_list
from .linalg import _eye

_INF = math.inf


def _active_set(fs, ft, h, q, usl, ts, eps, tol, unipolar, budget_possible, k, n, max_iter,
                x, free, sg, fixv, bud, at_face=None):
    """Primal active-set iterations from a feasible point x and its working set: ``free``
    (list of bool), the sign ``sg`` of each free coil, the value ``fixv`` of each fixed one and
    ``bud`` (the budget held with equality). ``at_face``: x is already this face's minimizer,
    and this (a list, maybe empty) its system from `_face_minimizer`'s ``keep``. Returns
    (x, free, sg, fixv, bud, system of the final face as ``keep`` has it, or [])."""
    heps = h + eps * _eye(n)
    if not budget_possible:  # no budget face will be solved
        return _active_set_loop(fs, ft, heps, q, usl, ts, tol, unipolar, False, k, n,
                                max_iter, x, free, sg, fixv, bud, at_face, eps, None)
    aug_a = np.empty((k + 1, n))
    aug_a[:k] = fs
    aug_a[k] = sg
    aug_b = np.empty(k + 1)
    aug_b[:k] = ft
    aug_b[k] = ts
    # the bordered [[F^T F + eps I, sg], [sg^T, 0]] and [F^T f; I_t]: a budget face's primal
    # system is their (free coils + budget) slice
    hb = np.empty((n + 1, n + 1))
    hb[:n, :n] = heps
    hb[n, :n] = sg
    hb[:n, n] = sg
    hb[n, n] = 0.0
    qb = np.empty(n + 1)
    qb[:n] = q
    qb[n] = ts
    aug = (aug_a, aug_b, hb, qb)
    return _active_set_loop(fs, ft, heps, q, usl, ts, tol, unipolar, True, k, n,
                            max_iter, x, free, sg, fixv, bud, at_face, eps, aug)


def _active_set_loop(fs, ft, heps, q, usl, ts, tol, unipolar, budget_possible, k, n, max_iter,
                     x, free, sg, fixv, bud, at_face, eps, aug):
    """The iterations of `_active_set`: face solve, ratio test and step, or pricing and
    release. ``aug``: the kept [F; sg], [f; I_t] and bordered systems (None without a budget),
    whose sign entries follow ``sg``."""
    xl = x.tolist()
    keep = at_face if at_face is not None else []  # the last face system solved (the polish)
    j = [i for i in range(n) if free[i]]  # the free coils and [fixv, 0], kept with free and fixv
    fe = np.array(fixv + [0.0])
    for _ in range(max_iter):
        if at_face is not None:
            xh, at_face = x, None
        else:
            xh = _face_minimizer(fs, ft, eps, free, sg, fixv, bud, ts, k, heps=heps, q=q,
                                 aug=aug, keep=keep, jfe=(j, fe))
        if j:
            hl = xh.tolist()
            if unipolar or bud:
                alpha, block, kind = _ratio_signed(xl, hl, j, sg, usl, ts,
                                                   budget_possible and not bud)
            else:
                alpha, block, kind, bsign = _ratio_bipolar(xl, hl, j, usl, ts, budget_possible)
                if kind == 1:
                    sg = _set_sign(sg, block, bsign, aug, k, n)
            if alpha < 1.0:
                xl, j, free, sg, fixv, bud = _step(xl, hl, j, free, sg, fixv, fe, bud, alpha,
                                                   block, kind, usl, unipolar, aug, k, n)
                x = None
                continue
            xl = hl
        else:
            xl = xh.tolist()
        x = xh
        # ---- at the face minimizer: multipliers of the working constraints
        g = (heps.dot(x) - q).tolist()
        best, m, lam_b = _pricing(g, j, free, sg, fixv, usl, bud, unipolar)
        if min(best, lam_b) >= -tol:
            break
        if lam_b < best:
            bud = False
        else:
            free, sg, fixv, j = _release(m, g, j, free, sg, fixv, fe, unipolar, aug, k, n)
    if x is None:  # the iteration cap hit after a step: the current feasible point
        x = np.array(xl)
        keep = []
    return x, free, sg, fixv, bud, keep


def _ratio_signed(xl, hl, j, sg, usl, ts, budget_free):
    """Ratio test when every free coil keeps its sign (unipolar, or on the budget): (alpha,
    blocking coil or -1, kind 0: at 0, 1: at +-u, 2: the budget). ``budget_free``: the budget
    may block (possible, not yet in the working set)."""
    alpha, block, kind, rate = 1.0, -1, 0, 0.0
    for i in j:
        s = sg[i]
        sp = s * (hl[i] - xl[i])
        rate += sp
        if sp < 0.0:
            a = s * xl[i] / -sp
            if a < alpha:
                alpha, block, kind = a, i, 0
        elif sp > 0.0:
            a = (usl[i] - s * xl[i]) / sp
            if a < alpha:
                alpha, block, kind = a, i, 1
    if budget_free and rate > 0.0:
        a = (ts - math.fsum(map(abs, xl))) / rate
        if a < alpha:
            alpha, block, kind = max(a, 0.0), -1, 2
    return alpha, block, kind


def _ratio_bipolar(xl, hl, j, usl, ts, budget_possible):
    """Ratio test bipolar, budget not in the working set: (alpha, block, kind, sign of the
    bound at +-u that blocks). The face does not depend on a free coil's sign, so a coil
    crosses 0 in one step (the split form's -u -> 0 -> +u would cost two extra faces); only
    +-u block, and the budget, whose sum |x| is piecewise linear along the step."""
    alpha, block, kind, bsign = 1.0, -1, 0, 1.0
    for i in j:
        d = hl[i] - xl[i]
        if d > 0.0:
            a = (usl[i] - xl[i]) / d
            if a < alpha:
                alpha, block, kind, bsign = a, i, 1, 1.0
        elif d < 0.0:
            a = (usl[i] + xl[i]) / -d
            if a < alpha:
                alpha, block, kind, bsign = a, i, 1, -1.0
    if budget_possible:
        a = _budget_hit(xl, hl, alpha, ts)
        if a < alpha:
            alpha, block, kind = a, -1, 2
    return alpha, block, kind, bsign


def _set_sign(sg, i, s, aug, k, n):
    """A copy of ``sg`` with coil i's sign s, written into the kept systems too."""
    sg = list(sg)
    sg[i] = s
    if aug is not None:
        aug[0][k, i] = aug[2][n, i] = aug[2][i, n] = s
    return sg


def _step(xl, hl, j, free, sg, fixv, fe, bud, alpha, block, kind, usl, unipolar, aug, k, n):
    """Step a fraction alpha < 1 towards the face minimizer and add the blocking constraint
    (kind as `_ratio_signed`) to the working set. Returns (xl, j, free, sg, fixv, bud); ``xl``
    and ``fe`` are updated in place, the lists that change are new."""
    alpha = max(alpha, 0.0)
    for i in j:  # (a fixed coil is at its value in both xl and hl)
        v = xl[i]
        xl[i] = v + alpha * (hl[i] - v)
    if kind == 2:
        if not bud and not unipolar:
            # the budget face fixes each free coil's sign: the side it is on (or moving to,
            # at 0)
            sg = list(sg)
            for i in j:
                v = xl[i]
                sg[i] = (1.0 if v > 0.0 else -1.0) if v != 0.0 else (
                    1.0 if hl[i] >= 0.0 else -1.0)
            aug_a, hb = aug[0], aug[2]
            aug_a[k] = sg
            hb[n, :n] = sg
            hb[:n, n] = sg
        bud = True
    else:
        free = list(free)
        fixv = list(fixv)
        free[block] = False
        fixv[block] = fe[block] = xl[block] = (0.0 if kind == 0 else sg[block] * usl[block])
        j = [i for i in j if i != block]
    # keep free coordinates on their side and inside the box under round-off
    if unipolar or bud:
        for i in j:
            s = sg[i]
            xl[i] = s * min(max(s * xl[i], 0.0), usl[i])
    else:
        for i in j:
            ui = usl[i]
            xl[i] = min(max(xl[i], -ui), ui)
    if bud and not j:
        bud = False  # implied by the bounds: a redundant working constraint
    return xl, j, free, sg, fixv, bud


def _pricing(g, j, free, sg, fixv, usl, bud, unipolar):
    """Multipliers of the working constraints at the face minimizer (gradient ``g``, list):
    (the most negative bound multiplier, its coil or -1, the budget's multiplier or inf)."""
    nu = 0.0
    if bud and j:
        acc = 0.0
        for i in j:
            acc += sg[i] * g[i]
        nu = -acc / len(j)
    best, m = _INF, -1
    for i in range(len(fixv)):
        if free[i] or usl[i] == 0.0:  # a coil with u_i = 0 is off: nothing to release
            continue
        fv = fixv[i]
        if fv == 0.0:
            lam = g[i] + nu if unipolar else nu - abs(g[i])
        else:
            lam = -(g[i] + nu) if fv > 0.0 else g[i] - nu
        if lam < best:
            best, m = lam, i
    return best, m, (nu if bud else _INF)


def _release(m, g, j, free, sg, fixv, fe, unipolar, aug, k, n):
    """Free coil m (its sign: the side its gradient pulls it to, or the bound it leaves).
    Returns new (free, sg, fixv, j); ``fe`` is updated in place."""
    free = list(free)
    fixv = list(fixv)
    free[m] = True
    fv = fixv[m]
    if fv == 0.0:
        s = 1.0 if (unipolar or g[m] < 0.0) else -1.0
    else:
        s = 1.0 if fv > 0.0 else -1.0
    sg = _set_sign(sg, m, s, aug, k, n)
    fixv[m] = fe[m] = 0.0
    return free, sg, fixv, sorted(j + [m])


def _cold_start(fs, ft, q, xl, usl, ts, unipolar):
    """The cold start: the least-residual point on the segment between two feasible
    projections (feasible too: the set is convex), of the least-norm exact fit ``xl`` and of a
    far multiple of F^T f (the bang-bang guess: coils at their limits with the sign of their
    correlation with the target, the budget spent on the best-correlated ones). Unreachable
    targets end at such a pattern; starting from the least-norm fit alone, each coil whose sign
    is wrong there costs 2-4 faces to flip. The residual is quadratic along the segment (its
    minimum from the two end residuals); within 5 % of an end, that end itself."""
    cand = _proj_list(xl, usl, ts, unipolar)[0]
    fq = fs.dot(q)
    den = float(fq.dot(fq))
    if not den > 0.0:
        return cand
    c = min(1e3 * float(ft.dot(fq)) / den, 1e290)  # scaled |q_i| <= k: no overflow below
    cand2 = _proj_list([c * v for v in q.tolist()], usl, ts, unipolar)[0]
    r = np.array([cand, cand2]).dot(fs.T) - ft
    r1, d = r[0], r[1] - r[0]
    dd = float(d.dot(d))
    t = -float(r1.dot(d)) / dd if dd > 0.0 else 0.0
    if t < 0.05:
        return cand
    if t > 0.95:
        return cand2
    return [a + t * (b - a) for a, b in zip(cand, cand2)]
