"""The two exact finishing stages after the eps-regularized active set.

:func:`_polish`: the eps -> 0 limit on the final face (least residual, then least energy),
kept when it stays on the face and is no worse. :func:`_least_energy`: for a reachable target,
the least-energy exact fit x = proj_X(F^T y) with F x = f by Newton on y, which resolves the
tie-break the eps-sized multipliers leave open (docs/allocation.md). Scaled units.
"""

from __future__ import annotations

import math

import numpy as np

from .faces import _face_minimizer
from .feasible import _proj_list
from .linalg import _eye, _eye_bordered, _fast_solve, _lsolve


def _polish(fs, ft, h, q, usl, ts, k, unipolar, x, free, sg, fixv, bud, kept, eps):
    """(x, accepted, y): the eps = 0 face minimizer if it stays on the face (box and budget)
    and is no worse; y its kernel coefficients (None in the primal form). Bipolar without the
    budget in the working set, a free coil may take either sign (see `_active_set`). ``h``,
    ``q``: F^T F and F^T f. ``kept``: this face's system as the active set last solved it
    (`_face_minimizer`'s ``keep``; empty if it did not), whose eps part is taken out."""
    if not any(free):
        r = fs.dot(x) - ft
        return x, True, None, float(r.dot(r))
    if kept:
        j, mat, rhs, aj, m = kept
        size = mat.shape[0]
        mat = mat - eps * (_eye(size) if m == size else _eye_bordered(m))
        sol = _lsolve(mat, rhs, False)
        xp = np.array(fixv)
        if aj is None:
            xp.put(j, sol)
            y = None
        else:
            xp.put(j, aj.T.dot(sol))
            y = sol[:k]
    else:
        xp, y = _face_minimizer(fs, ft, 0.0, free, sg, fixv, bud, ts, k, want_y=True, heps=h,
                                q=q)
    xpl = xp.tolist()
    slack = 1e-12 * max(usl)
    signfree = not (unipolar or bud)
    clamped = False
    for i, fr in enumerate(free):
        if fr:
            a, ui = xpl[i], usl[i]
            if signfree:
                if not -ui - slack <= a <= ui + slack:
                    return x, False, None, None
                if not -ui <= a <= ui:
                    xpl[i] = min(max(a, -ui), ui)
                    clamped = True
                continue
            s = sg[i]
            if not -slack <= s * a <= ui + slack:
                return x, False, None, None
            if not 0.0 <= s * a <= ui:
                xpl[i] = s * min(max(s * a, 0.0), ui)
                clamped = True
    if not bud and math.fsum(map(abs, xpl)) > ts * (1 + 1e-12):
        return x, False, None, None  # the Tikhonov bias kept it inside the budget; eps -> 0 does not
    if clamped:
        xp = np.array(xpl)
    rp, rx = fs.dot(xp) - ft, fs.dot(x) - ft
    ep, ex = float(rp.dot(rp)), float(rx.dot(rx))
    # "no worse" up to rounding: the two objectives often agree to 1e-16 relative (eps only
    # shifts a determined face by ~1e-10), and a coin flip there would send a third of the
    # hard problems through the continuation pass for nothing
    if ep <= ex * (1.0 + 1e-12) + 1e-24 * float(ft.dot(ft)):
        return xp, True, y, ep
    return x, False, None, ex


def _least_energy(fs, ft, usl, ts, unipolar, y, lim, c2, k, steps=6):
    """The least-energy exact fit: min ||x||^2 over {x in X, F x = f} for a reachable f.

    Its optimality conditions are x = proj_X(F^T y) with F x = f (y the multiplier of the fit),
    a k-dimensional piecewise-linear equation solved by Newton from the polished face's y
    (usually 0-1 steps). Unlike the eps-regularized active set, whose tie-break multipliers
    are eps-small and so resolved only to ~1e-3 relative, this is exact. Returns None if
    Newton does not land within ``steps`` (the caller keeps its answer)."""
    shift = (1e-14 * c2) * _eye(k)
    lim2 = lim * lim
    for _ in range(steps):
        xl, tau = _proj_list(fs.T.dot(y).tolist(), usl, ts, unipolar)
        x = np.array(xl)
        r = ft - fs.dot(x)
        if float(r.dot(r)) <= lim2:
            return x
        j = [i for i, (v, ui) in enumerate(zip(xl, usl)) if 0.0 < abs(v) < ui]
        if not j:
            return None
        fj = fs.take(j, 1)
        m = fj.dot(fj.T) + shift
        if tau > 0.0:
            wv = fj.dot(np.array([1.0 if xl[i] > 0.0 else -1.0 for i in j]))
            m -= np.outer(wv, wv) / len(j)
        y = y + _fast_solve(m, r)
    return None
