"""How far a force can be pushed along a ray and stay renderable: the reachable set's faces.

For many positions at once (m points), with F (m, k, n) N/A, the direction d (m, k) N and the
bias f0 (m, k) N, the reachable set R = {F I : I in X}, X = {|I_i| <= u_i (or 0 <= I_i <= u_i),
sum |I_i| <= I_t}, is a polytope with support function h(w) = max_{I in X} w.F I (a fractional
knapsack on the coils' |w.F_i|, closed form). Then (LP duality, R convex)

    lambda* = max {lambda : lambda d - f0 in R} = min over w.d > 0 of (h(w) + w.f0) / (w.d),

every w giving an upper bound, attained at R's facet normal where the ray leaves R. h is
linear between the planes where its formula has a kink -- w.F_i = 0 (a coil changes sign or
switches on) and, when the budget binds, w.(F_j -+ F_l) = 0 (two coils swap places in the
knapsack) -- so for k = 3 every facet normal is the cross product of two such planes' normals,
and for k = 1 it is +-1. The minimum over these candidates is lambda* for any F whose facets
are in general position; the caller confirms it with one allocation (docs/allocation.md).

Also returned: the largest separation of -f0 from R along the candidates, N (> 0: -f0, the
target at lambda = 0, is not renderable; a lower bound of its distance to R).
"""

from __future__ import annotations

import numpy as np

_PAIRS = {}  # facet_pairs per (n, limits, budget, drive mode)
_BIG = np.finfo(float).max


def support(c, u, tl, unipolar):
    """h(w) for the coil responses c = F^T w (..., n) (N/A): the largest w.F I over X, N."""
    a = np.maximum(c, 0.0) if unipolar else np.abs(c)
    if tl >= float(np.sum(u)):
        return a.dot(u)
    n = a.shape[-1]
    if np.all(u == u[0]) and u[0] > 0.0:  # equal limits: the top floor(I_t / u) coils, and a
        full = min(int(tl // u[0]), n - 1)  # fraction of the next (I_t < sum u: full < n)
        a.partition(n - full - 1, axis=-1)  # in place: a is ours
        wv = np.zeros(n)
        wv[n - full:] = u[0]
        wv[n - full - 1] = tl - full * u[0]
        return a.dot(wv)
    order = np.argsort(-a, axis=-1)
    s = np.take_along_axis(a, order, axis=-1)
    us = u[order]
    before = np.cumsum(us, axis=-1) - us
    return (s * np.clip(tl - before, 0.0, us)).sum(axis=-1)


def kink_planes(fm, u, tl, unipolar):
    """Normals (m, p, 3) of the planes where h has a kink: the columns, and their pairwise
    differences (and sums, bipolar) when the budget binds."""
    cols = np.swapaxes(fm, 1, 2)  # (m, n, 3)
    if not tl < float(np.sum(u)):
        return cols
    i, j = np.triu_indices(cols.shape[1], 1)
    parts = [cols, cols[:, i] - cols[:, j]]
    if not unipolar:
        parts.append(cols[:, i] + cols[:, j])
    return np.concatenate(parts, axis=1)


def all_pairs(p):
    """Every pair (i < j) of p planes, (p (p - 1) / 2, 2) int."""
    return np.stack(np.triu_indices(p, 1), axis=1)


def facet_pairs(n, u, tl, unipolar):
    """See :func:`_facet_pairs` (cached per n, limits, budget and drive mode)."""
    u = np.broadcast_to(np.asarray(u, float), (n,))
    key = (n, tuple(u.tolist()), float(tl), bool(unipolar))
    if key not in _PAIRS:
        if len(_PAIRS) > 32:
            _PAIRS.clear()
        _PAIRS[key] = _facet_pairs(*key)
    return _PAIRS[key]


def _facet_pairs(n, u, tl, unipolar):
    """The pairs of :func:`kink_planes` that can meet in a facet normal, (q, 2) int.

    Without a binding budget: every pair of columns. With one and equal limits, h changes
    slope across a tie only when it involves the knapsack's boundary coil, so two active ties
    share a coil; bipolar, a coil switching sign matters only when at most floor(I_t / u)
    coils have a non-zero response, which two planes through w cannot produce for
    n - floor(I_t / u) > 2 (unipolar, every coil with a negative response is off: the
    columns stay). Unequal limits: every pair."""
    u = np.broadcast_to(np.asarray(u, float), (n,))
    if not tl < float(np.sum(u)):
        return all_pairs(n)
    i, j = np.triu_indices(n, 1)
    ties = np.concatenate([np.stack([i, j], 1)] * (1 if unipolar else 2))  # coils of each tie
    p = n + len(ties)
    if not (np.all(u == u[0]) and u[0] > 0.0):
        return all_pairs(p)
    a, b = np.triu_indices(len(ties), 1)
    share = (ties[a, :, None] == ties[b, None, :]).any(axis=(1, 2))
    pairs = [np.stack([a[share] + n, b[share] + n], 1)]
    if unipolar or n - int(tl // u[0]) <= 2:  # a coil switching on can be in the top set
        pairs.insert(0, all_pairs(p)[: n * (n - 1) // 2 + n * len(ties)])
    return np.concatenate(pairs)


def ray_limits(force_matrices, directions, bias, current_limit, total_limit, *,
               unipolar=False, pairs=None, chunk=None):
    """(lambda_up (m,), separation (m,) N, best pair (m, 2), conditioning (m,)) for F (m, k, n),
    d (m, k), f0 (m, k).

    lambda_up: min over the candidate facet normals with w.d > 0 of (h(w) + w.f0) / (w.d), an
    upper bound of the largest lambda with lambda d - f0 reachable, equal to it when the
    candidates hold the facet the ray leaves by (always for k = 1; for k = 3 with ``pairs``
    None -- :func:`facet_pairs` -- and F of rank 3); the largest float if no candidate
    faces d (no bound found; then -that as the separation if no candidate is non-zero).
    separation: max over the unit candidates of w.(-f0) - h(w) (> 0: -f0 is outside R by at
    least that). best pair: the kink planes (indices into :func:`kink_planes`) of the
    minimizing normal (-1 for k = 1). conditioning: sin(angle of the two planes) x cos(angle
    of w and d) of that normal (1 for k = 1); small -> its rounding matters."""
    fm = np.asarray(force_matrices, float)
    d = np.asarray(directions, float)
    f0 = np.asarray(bias, float)
    m, k, n = fm.shape
    if k not in (1, 3):
        raise ValueError("ray limits need k = 1 or 3 rows")
    u = np.broadcast_to(np.asarray(current_limit, float), (n,))
    tl = float(total_limit)
    lam, sep, cond = np.empty(m), np.empty(m), np.ones(m)
    best = np.full((m, 2), -1)
    if k == 3:
        pr0 = facet_pairs(n, u, tl, unipolar) if pairs is None else np.asarray(pairs)
    if chunk is None:  # about 2e5 candidate responses at a time
        chunk = max(1, 200_000 // (n * (2 if k == 1 else 2 * len(pr0))))
    for s in range(0, m, chunk):
        sl = slice(s, s + chunk)
        if k == 1:
            w = np.ones((len(fm[sl]), 1, 1))
        else:
            p = kink_planes(fm[sl], u, tl, unipolar)
            pr = pr0
            w = np.cross(p[:, pr[:, 0]], p[:, pr[:, 1]])
        # the candidates w and -w: bipolar h(-w) = h(w), and the rest changes sign
        c = np.matmul(w, fm[sl])
        hp = support(c, u, tl, unipolar)
        h = np.concatenate([hp, support(-c, u, tl, True) if unipolar else hp], axis=1)
        wf = np.matmul(w, f0[sl, :, None])[..., 0]
        wf = np.concatenate([wf, -wf], axis=1)
        wd = np.matmul(w, d[sl, :, None])[..., 0]
        wd = np.concatenate([wd, -wd], axis=1)
        wn = np.sqrt((w * w).sum(axis=-1))
        wn = np.concatenate([wn, wn], axis=1)
        dn = np.sqrt((d[sl] * d[sl]).sum(axis=-1))
        face = wd > 1e-12 * wn * dn[:, None]
        num = h + wf
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(face, num / np.where(face, wd, 1.0), np.inf)
            unit = np.where(wn > 0.0, -num / np.where(wn > 0.0, wn, 1.0), -np.inf)
        arg = ratio.argmin(axis=1)
        rows = np.arange(len(arg))
        lam[sl] = np.minimum(ratio[rows, arg], _BIG)
        sep[sl] = np.maximum(unit.max(axis=1), -_BIG)
        if k == 3:
            q = arg % len(pr)
            best[sl] = pr[q]
            pa = np.linalg.norm(p[rows, pr[q, 0]], axis=1)
            pb = np.linalg.norm(p[rows, pr[q, 1]], axis=1)
            with np.errstate(divide="ignore", invalid="ignore"):
                c = wd[rows, arg] / (pa * pb * dn)
            cond[sl] = np.where(np.isfinite(c), c, 0.0)
    return lam, sep, best, cond
