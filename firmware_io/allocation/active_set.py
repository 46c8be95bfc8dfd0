"""The primal active-set method on the eps-regularized allocation problem.

From a feasible point and its working set (:class:`.working_set.Face`: which coils are free
and with which sign, which are fixed at 0 or +-u, whether the budget holds with equality) each
iteration solves the working face (:mod:`.faces`), steps towards its minimizer up to the first
blocking constraint (ratio test) and, at the face minimizer, releases the constraint with the
most negative multiplier. Bipolar, while the budget is not in the working set, a coil crosses
0 in one step. Scaled units; the method and its bias bound: docs/allocation.md.
"""

from __future__ import annotations

import math

import numpy as np

from .faces import face_minimizer
from .feasible import budget_hit
from .workspace import FaceSystems


def active_set(ws, eps, x, face, at_face=None):
    """Primal active-set iterations at Tikhonov weight ``eps`` from a feasible point x (n,)
    and its working set ``face``, which they take over and move (its lists are replaced, not
    changed, so a stored copy of them stays valid). ``at_face``: x is already this face's
    minimizer, and this (a list, maybe empty) its system from
    :func:`.faces.face_minimizer`'s ``keep``. Returns (x, face, system of the final face as
    ``keep`` has it, or [])."""
    systems = FaceSystems.build(ws, eps, face.sg)
    heps = systems.heps
    q = ws.q
    tol, usl, ts = ws.tol, ws.usl, ws.ts
    budget_possible = ws.budget_possible
    unipolar = ws.unipolar
    xl = x.tolist()
    keep = at_face if at_face is not None else []  # the last face system solved (the polish)
    for _ in range(ws.max_iter):
        if at_face is not None:
            xh, at_face = x, None
        else:
            xh = face_minimizer(ws, face, eps, systems, keep)
        j = face.j
        if j:
            hl = xh.tolist()
            bud = face.bud
            if unipolar or bud:
                alpha, block, kind = _ratio_signed(xl, hl, j, face.sg, usl, ts,
                                                   budget_possible and not bud)
            else:
                alpha, block, kind, bsign = _ratio_bipolar(xl, hl, j, usl, ts, budget_possible)
                if kind == 1:
                    _set_sign(face, systems, block, bsign, ws)
            if alpha < 1.0:
                _step(ws, systems, face, xl, hl, (alpha, block, kind))
                x = None
                continue
            xl = hl
        else:
            xl = xh.tolist()
        x = xh
        # ---- at the face minimizer: multipliers of the working constraints
        g = (heps.dot(x) - q).tolist()
        best, m, lam_b = _pricing(g, face, usl, unipolar)
        if min(best, lam_b) >= -tol:
            break
        if lam_b < best:
            face.bud = False
        else:
            _release(ws, systems, face, m, g)
    if x is None:  # the iteration cap hit after a step: the current feasible point
        x = np.array(xl)
        keep = []
    return x, face, keep


def _ratio_signed(xl, hl, j, sg, usl, ts, budget_free):
    """Ratio test from x towards h (lists) when every free coil (indices ``j``, signs ``sg``)
    keeps its sign (unipolar, or on the budget): (alpha, blocking coil or -1, kind 0: at 0,
    1: at +-u, 2: the budget). ``budget_free``: the budget ``ts`` may block (possible, not yet
    in the working set)."""
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
        a = budget_hit(xl, hl, alpha, ts)
        if a < alpha:
            alpha, block, kind = a, -1, 2
    return alpha, block, kind, bsign


def _set_sign(face, systems, i, s, ws):
    """Coil i's sign s: a new ``face.sg``, written into the kept systems too."""
    sg = list(face.sg)
    sg[i] = s
    face.sg = sg
    aug = systems.aug
    if aug is not None:
        k, n = ws.k, ws.n
        aug[0][k, i] = aug[2][n, i] = aug[2][i, n] = s


def _step(ws, systems, face, xl, hl, ratio):
    """Step a fraction alpha < 1 from x towards the face minimizer h (lists; xl changes in
    place) and add the blocking constraint to the working set ``face``; ``ratio`` = (alpha,
    blocking coil, kind) of :func:`_ratio_signed`."""
    alpha, block, kind = ratio
    usl = ws.usl
    alpha = max(alpha, 0.0)
    j = face.j
    for i in j:  # (a fixed coil is at its value in both xl and hl)
        v = xl[i]
        xl[i] = v + alpha * (hl[i] - v)
    if kind == 2:
        if not face.bud and not ws.unipolar:
            # the budget face fixes each free coil's sign: the side it is on (or moving to,
            # at 0)
            sg = list(face.sg)
            for i in j:
                v = xl[i]
                sg[i] = (1.0 if v > 0.0 else -1.0) if v != 0.0 else (
                    1.0 if hl[i] >= 0.0 else -1.0)
            face.sg = sg
            systems.set_signs(sg, ws.k, ws.n)
        face.bud = True
    else:
        free = list(face.free)
        fixv = list(face.fixv)
        free[block] = False
        fixv[block] = face.fe[block] = xl[block] = (0.0 if kind == 0
                                                     else face.sg[block] * usl[block])
        face.free, face.fixv = free, fixv
        face.j = j = [i for i in j if i != block]
    # keep free coordinates on their side and inside the box under round-off
    if ws.unipolar or face.bud:
        sg = face.sg
        for i in j:
            s = sg[i]
            xl[i] = s * min(max(s * xl[i], 0.0), usl[i])
    else:
        for i in j:
            ui = usl[i]
            xl[i] = min(max(xl[i], -ui), ui)
    if face.bud and not j:
        face.bud = False  # implied by the bounds: a redundant working constraint


def _pricing(g, face, usl, unipolar):
    """Multipliers of the working constraints of ``face`` at its minimizer (gradient ``g``,
    list): (the most negative bound multiplier, its coil or -1, the budget's multiplier or
    inf)."""
    free, fixv, j = face.free, face.fixv, face.j
    bud = face.bud
    nu = 0.0
    if bud and j:
        sg = face.sg
        acc = 0.0
        for i in j:
            acc += sg[i] * g[i]
        nu = -acc / len(j)
    best, m = math.inf, -1
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
    return best, m, (nu if bud else math.inf)


def _release(ws, systems, face, m, g):
    """Free coil m (its sign: the side its gradient pulls it to, or the bound it leaves)."""
    free = list(face.free)
    fixv = list(face.fixv)
    free[m] = True
    fv = fixv[m]
    if fv == 0.0:
        s = 1.0 if (ws.unipolar or g[m] < 0.0) else -1.0
    else:
        s = 1.0 if fv > 0.0 else -1.0
    _set_sign(face, systems, m, s, ws)
    fixv[m] = face.fe[m] = 0.0
    face.free, face.fixv = free, fixv
    face.j = sorted(face.j + [m])
