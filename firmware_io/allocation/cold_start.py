"""The active set's cold start: a feasible point near the answer when no warm face fits.

The least-residual point on the segment between two feasible projections (feasible too: the
set is convex), of the least-norm exact fit and of a far multiple of F^T f (the bang-bang
guess: coils at their limits with the sign of their correlation with the target, the budget
spent on the best-correlated ones). Unreachable targets end at such a pattern; starting from
the least-norm fit alone, each coil whose sign is wrong there costs 2-4 faces to flip
(docs/allocation.md). Scaled units.
"""

from __future__ import annotations

import numpy as np

from .feasible import project


def cold_start(ws, xl):
    """The start point (list of n floats) from the least-norm fit ``xl`` (list): the residual
    is quadratic along the segment (its minimum from the two end residuals); within 5 % of an
    end, that end itself."""
    fs, ft, q = ws.fs, ws.ft, ws.q
    usl, tsb, unipolar = ws.usl, ws.tsb, ws.unipolar
    cand = project(xl, usl, tsb, unipolar)[0]
    fq = fs.dot(q)
    den = float(fq.dot(fq))
    if not den > 0.0:
        return cand
    c = min(1e3 * float(ft.dot(fq)) / den, 1e290)  # scaled |q_i| <= k: no overflow below
    cand2 = project([c * v for v in q.tolist()], usl, tsb, unipolar)[0]
    r = np.array([cand, cand2]).dot(fs.T) - ft
    r1, d = r[0], r[1] - r[0]
    dd = float(d.dot(d))
    t = -float(r1.dot(d)) / dd if dd > 0.0 else 0.0
    if t < 0.05:
        return cand
    if t > 0.95:
        return cand2
    return [a + t * (b - a) for a, b in zip(cand, cand2)]
