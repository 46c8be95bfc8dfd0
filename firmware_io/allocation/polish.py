"""The two exact finishing stages after the eps-regularized active set.

:func:`polish`: the eps -> 0 limit on the final face (least residual, then least energy), kept
when it stays on the face and is no worse. :func:`least_energy`: for a reachable target, the
least-energy exact fit x = proj_X(F^T y) with F x = f by Newton on y, which resolves the
tie-break the eps-sized multipliers leave open (docs/allocation.md). Scaled units.
"""

from __future__ import annotations

import math

import numpy as np

from .faces import face_minimizer
from .feasible import project
from .linalg import eye, eye_bordered, fast_solve, lsolve
from .workspace import FaceSystems


def polish(ws, x, face, kept, eps):
    """(x, accepted, y, residual^2): the eps = 0 face minimizer if it stays on ``face`` (box
    and budget) and is no worse; y its kernel coefficients (None in the primal form); the
    residual^2 of the returned x (None when not accepted and not computed). Bipolar without
    the budget in the working set, a free coil may take either sign (see
    :mod:`.active_set`). ``kept``: this face's system as the active set last solved it
    (:func:`.faces.face_minimizer`'s ``keep``; empty if it did not), whose eps part is taken
    out."""
    fs, ft, usl = ws.fs, ws.ft, ws.usl
    free, bud = face.free, face.bud
    if not any(free):
        r = fs.dot(x) - ft
        return x, True, None, float(r.dot(r))
    if kept:
        j, mat, rhs, aj, m = kept
        size = mat.shape[0]
        mat = mat - eps * (eye(size) if m == size else eye_bordered(m))
        sol = lsolve(mat, rhs, False)
        xp = np.array(face.fixv)
        if aj is None:
            xp.put(j, sol)
            y = None
        else:
            xp.put(j, aj.T.dot(sol))
            y = sol[:ws.k]
    else:
        xp, y = face_minimizer(ws, face, 0.0, FaceSystems(ws.h, ws.q), want_y=True)
    xpl = xp.tolist()
    slack = 1e-12 * max(usl)
    signfree = not (ws.unipolar or bud)
    clamped = False
    sg = face.sg
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
    if not bud and math.fsum(map(abs, xpl)) > ws.ts * (1 + 1e-12):
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


def least_energy(ws, y, lim, c2, steps=6):
    """The least-energy exact fit: min ||x||^2 over {x in X, F x = f} for a reachable f.

    Its optimality conditions are x = proj_X(F^T y) with F x = f (y the multiplier of the fit),
    a k-dimensional piecewise-linear equation solved by Newton from the polished face's y
    (usually 0-1 steps). Unlike the eps-regularized active set, whose tie-break multipliers
    are eps-small and so resolved only to ~1e-3 relative, this is exact. ``lim``: the fit's
    tolerance on ||F x - f||; ``c2``: the largest squared column norm of F. Returns None if
    Newton does not land within ``steps`` (the caller keeps its answer)."""
    fs, ft, usl, tsb, unipolar, k = ws.fs, ws.ft, ws.usl, ws.tsb, ws.unipolar, ws.k
    shift = (1e-14 * c2) * eye(k)
    lim2 = lim * lim
    for _ in range(steps):
        xl, tau = project(fs.T.dot(y).tolist(), usl, tsb, unipolar)
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
        y = y + fast_solve(m, r)
    return None
