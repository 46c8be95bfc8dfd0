"""The feasible set X = {lo <= I <= u, sum |I| <= I_t} of the scaled problem, on plain lists.

Membership (:func:`inside`, :func:`on_face`), the Euclidean projection onto X
(:func:`project`) and the first step at which a segment reaches the budget
(:func:`budget_hit`). Currents are in units of u_max; n ~ 9, so plain Python floats are cheaper
than numpy calls here.
"""

from __future__ import annotations

import math


def inside(xl, usl, ts, unipolar):
    """x (list) inside the box and the budget."""
    tot = 0.0
    if unipolar:
        for v, ui in zip(xl, usl):
            if not 0.0 <= v <= ui:
                return False
            tot += v
    else:
        for v, ui in zip(xl, usl):
            a = abs(v)
            if not a <= ui:
                return False
            tot += a
    return tot <= ts


def on_face(xl, face, usl, ts, unipolar):
    """x (list) feasible and on the working ``face`` (:class:`.working_set.Face`): free coils
    on their side inside the box (either side, bipolar without the budget), fixed ones where
    they were put, the budget kept."""
    tot = 0.0
    bud = face.bud
    signfree = not (unipolar or bud)
    for v, fr, s, ui in zip(xl, face.free, face.sg, usl):
        a = abs(v) if signfree else s * v
        if fr and not 0.0 <= a <= ui:
            return False
        tot += abs(v)
    return bud or tot <= ts


def budget_hit(xl, hl, alpha, ts):
    """The first step a in [0, alpha] at which sum |x + a (h - x)| reaches ts (lists; convex
    and piecewise linear in a, breakpoints where a coordinate crosses 0); inf if it stays
    within ts up to alpha."""
    if math.fsum(map(abs, hl)) <= ts:  # x is feasible and sum |.| convex: never above ts
        return math.inf
    d = [w - v for v, w in zip(xl, hl)]
    t0 = math.fsum(map(abs, xl))
    tend = math.fsum(abs(v + alpha * e) for v, e in zip(xl, d))
    if tend <= ts:
        return math.inf
    bps = sorted(-v / e for v, e in zip(xl, d) if e != 0.0 and 0.0 < -v / e < alpha)
    a0 = 0.0
    for a1 in bps + [alpha]:
        t1 = tend if a1 == alpha else math.fsum(abs(v + a1 * e) for v, e in zip(xl, d))
        if t1 > ts and t1 > t0:  # convex: once rising, it keeps rising
            return max(a0, a0 + (a1 - a0) * (ts - t0) / (t1 - t0))
        a0, t0 = a1, t1
    return alpha


def project(v, us, ts, unipolar):
    """Euclidean projection of v (list) onto {lo <= x <= u, sum |x| <= ts} in plain Python
    floats (n ~ 9: a loop is cheaper than a dozen numpy calls). Returns (x, tau), tau the
    budget's soft threshold."""
    if unipolar:
        a = v
        c = [(ai if ai < ui else ui) if ai > 0.0 else 0.0 for ai, ui in zip(a, us)]
    else:
        a = list(map(abs, v))
        c = list(map(min, a, us))
    s = math.fsum(c)
    tau = 0.0
    if s > ts:
        # sum_i clip(a_i - tau, 0, u_i) is piecewise linear and decreasing in tau: sweep its
        # breakpoints (coil i enters the sloped part at max(a_i - u_i, 0), leaves it at a_i)
        ev = []
        for ai, ui in zip(a, us):
            if ai > 0.0 and ui > 0.0:
                lo = ai - ui
                ev.append((lo if lo > 0.0 else 0.0, -1))
                ev.append((ai, 1))
        ev.sort()
        t0, s0, slope = 0.0, s, 0
        tau = ev[-1][0]
        for t, e in ev:
            st = s0 + slope * (t - t0)
            if st <= ts:
                tau = t0 + (s0 - ts) / -slope
                break
            t0, s0 = t, st
            slope += e
        c = [min(max(ai - tau, 0.0), ui) for ai, ui in zip(a, us)]
    if unipolar:
        return c, tau
    return list(map(math.copysign, c, v)), tau
