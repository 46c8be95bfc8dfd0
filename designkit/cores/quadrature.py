"""Quadrature rules for the field of solved panel currents, with the error bounds that choose
them per point (derivation: docs/core_model.md, "Field evaluation").

For a point and a group of panels the kernel, as a function of the source coordinate s along
the group, is analytic except where the source ring would pass through the point. The
Bernstein ellipse of the group's interval through that singularity (parameter rho_s; the
bounds use the half-way ellipse rho = (1 + rho_s) / 2) bounds the error of n-node
interpolation by 4 rho^-n / (rho - 1) and of n-node Gauss quadrature by
64/15 rho^-2n / (rho^2 - 1) (Trefethen, Approximation Theory and Approximation Practice,
ch. 8 and 19). All distances are in units of the group's or panel's own size, so the choice
holds for any geometry. Fields are per mu0 (A/m per A/m of K) in the winding's local frame.
"""

from __future__ import annotations

import numpy as np

from ..field import cylindrical_to_cartesian
from ..field.kernels import loop_rz, sheet_rz
from .discretization import disc_nodes, gauss

EVAL_RTOL = 1e-5
"""Quadrature error bound of the field evaluation, relative to the size of each source group's
contribution (docs/core_model.md, "Field evaluation"); far below the model's discretization
error."""
FAR_NODES = (4, 6, 8, 12, 16, 24)
"""Ring counts of the compressed product rules, tried in this order."""
PANEL_NODES = 4
"""Gauss nodes per end-face panel when the point is far from the panel (else refined)."""
NEAR_NODES = 10
"""Gauss nodes per piece of the geometric near-point refinement of a face panel."""
RHO_CAP = 1e3


def usable_rho(lo, hi, s):
    """Usable Bernstein-ellipse parameter of [lo, hi] for the kernel singularity ``s`` (complex).

    rho_s is the ellipse (foci lo, hi) through s; the bounds use the ellipse half-way in,
    rho = (1 + rho_s) / 2, on which the kernel stays within a small factor of its size on the
    interval."""
    x = (2.0 * np.asarray(s) - lo - hi) / (hi - lo)
    w = x + np.sqrt(x - 1.0 + 0j) * np.sqrt(x + 1.0 + 0j)
    r = np.abs(w)
    r = np.maximum(r, 1.0 / np.maximum(r, 1e-300))
    return np.minimum(0.5 * (1.0 + r), RHO_CAP)


def cancellation(k, w, cap=1e4):
    """sum |k| w / |sum k w| (>= 1, capped): the interpolation error scales with the integral of
    |K| while the group's contribution may be the much smaller integral of K (currents of both
    signs), so the bound is multiplied by this factor."""
    total = abs(float(np.sum(k * w)))
    mag = float(np.sum(np.abs(k) * w))
    return min(mag / total, cap) if total > 0 else cap


def interp_bound(rho, n):
    """Relative error bound of n-point Gauss-node interpolation: 4 rho^-n / (rho - 1)."""
    with np.errstate(divide="ignore", over="ignore"):
        return 4.0 * rho ** (-float(n)) / np.maximum(rho - 1.0, 1e-300)


def quad_bound(rho, n):
    """Relative error bound of n-point Gauss-Legendre quadrature: 64/15 rho^-2n / (rho^2 - 1)."""
    with np.errstate(divide="ignore", over="ignore"):
        return 64.0 / 15.0 * rho ** (-2.0 * n) / np.maximum(rho * rho - 1.0, 1e-300)


def _lagrange_on_panels(lo_e, hi_e, a, b, n):
    """The n Gauss nodes of [a, b], the parts [p0, p1] of the panels [lo_e, hi_e] inside it,
    their (n + 2)-node Gauss rules and the Lagrange basis of the nodes at those points."""
    x, _ = gauss(n)
    xf, wf = gauss(n + 2)  # exact for K * (degree n-1) per panel
    nodes = 0.5 * (a + b) + 0.5 * (b - a) * x
    p0 = np.maximum(lo_e, a)
    p1 = np.minimum(hi_e, b)
    keep = p1 > p0
    p0, p1 = p0[keep], p1[keep]
    s = (0.5 * (p0 + p1)[:, None] + 0.5 * (p1 - p0)[:, None] * xf[None, :]).ravel()
    # Lagrange basis at s, scaled to [-1, 1] for conditioning
    t = (2.0 * s - a - b) / (b - a)
    lag = np.ones((len(s), n))
    for q in range(n):
        for j in range(n):
            if j != q:
                lag[:, q] *= (t - x[j]) / (x[q] - x[j])
    return nodes, keep, p0, p1, wf, lag


def product_rule(lo_e, hi_e, k, a, b, n, kind, fixed):
    """n rings at the Gauss nodes of [a, b] whose weights integrate the piecewise-constant K
    (panels [lo_e, hi_e]) times the Lagrange interpolant of the loop field exactly.

    Returns (r, z, current per ring) arrays, m and A."""
    nodes, keep, p0, p1, wf, lag = _lagrange_on_panels(lo_e, hi_e, a, b, n)
    ws = ((0.5 * (p1 - p0) * k[keep])[:, None] * wf[None, :]).ravel()
    weights = ws @ lag
    if kind == "side":
        return np.full(n, fixed), nodes, weights
    return nodes, np.full(n, fixed), weights


def product_matrix(lo_e, hi_e, intervals, n):
    """The product rule of :func:`product_rule` on each interval, linear in the panel values:
    ring nodes (n_int * n,) and W (n_int * n, n_panels) with ring currents = W @ k."""
    nodes_all, rows = [], []
    for a, b in intervals:
        nodes, keep, p0, p1, wf, lag = _lagrange_on_panels(lo_e, hi_e, a, b, n)
        ws = (0.5 * (p1 - p0))[:, None] * wf[None, :]  # (n_keep, n + 2)
        w = np.zeros((n, len(lo_e)))
        w[:, keep] = np.einsum("pf,pfq->qp", ws, lag.reshape(len(p0), len(wf), n))
        nodes_all.append(nodes)
        rows.append(w)
    return np.concatenate(nodes_all), np.vstack(rows)


def near_rule(lo, hi, s_re, delta, n=NEAR_NODES):
    """Gauss rule on [lo, hi] graded geometrically towards x0 = clip(s_re): pieces of length
    delta, 2 delta, 4 delta, ... on each side, so every piece sees the singularity (at distance
    >= delta from x0) through an ellipse of parameter >= 3.7. Returns (x, w)."""
    x, w = gauss(n)
    x0 = min(max(s_re, lo), hi)
    edges = [x0]
    step = delta
    while edges[-1] < hi:
        edges.append(min(edges[-1] + step, hi))
        step *= 2.0
    left = [x0]
    step = delta
    while left[-1] > lo:
        left.append(max(left[-1] - step, lo))
        step *= 2.0
    e = np.array(left[::-1] + edges[1:])
    e = e[np.concatenate([[True], np.diff(e) > 0])]
    a, b = e[:-1], e[1:]
    xs = (0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * x[None, :]).ravel()
    ws = (0.5 * (b - a)[:, None] * w[None, :]).ravel()
    return xs, ws


def _side_panels_rz(sol, side_idx, rho, z, gradient, acc):
    """Add the closed-form sheets of the side panels ``side_idx`` of ``sol`` to ``acc``."""
    n = rho.shape[0]
    lo, hi, k = sol.side_z_lo[side_idx], sol.side_z_hi[side_idx], sol.k_side[side_idx]
    h = 0.5 * (hi - lo)
    c = 0.5 * (hi + lo)
    ns = len(h)
    res = sheet_rz(sol.radius, np.tile(h, n), np.repeat(rho, ns),
                   np.repeat(z, ns) - np.tile(c, n), gradient=gradient)
    kk = np.tile(k, n)
    for q in range(len(acc)):
        acc[q] += (res[q] * kk).reshape(n, ns).sum(axis=1)


def _face_panels_rz(sol, disc_idx, rho, z, gradient, acc):
    """Add the face panels ``disc_idx`` of ``sol`` to ``acc``: PANEL_NODES-point Gauss rules
    where their quadrature bound holds, else the geometric near rule."""
    n = rho.shape[0]
    nout = len(acc)
    r_lo, r_hi = sol.disc_r_lo[disc_idx], sol.disc_r_hi[disc_idx]
    zp, kd = sol.disc_z[disc_idx], sol.k_disc[disc_idx]
    nd = len(disc_idx)
    dz = np.abs(z[:, None] - zp[None, :])
    rho_b = usable_rho(r_lo[None, :], r_hi[None, :], rho[:, None] + 1j * dz)
    ok = quad_bound(rho_b, PANEL_NODES) <= EVAL_RTOL
    nq = PANEL_NODES
    rq, wq = disc_nodes(r_lo, r_hi, nq)
    wk = (wq * kd[:, None])  # (nd, nq)
    m = nd * nq
    res = loop_rz(np.tile(rq.ravel(), n), np.repeat(rho, m),
                  np.repeat(z, m) - np.tile(np.repeat(zp, nq), n), gradient=gradient)
    ww = (ok[:, :, None] * wk[None, :, :]).ravel()
    for q in range(nout):
        acc[q] += (res[q] * ww).reshape(n, m).sum(axis=1)
    bad_i, bad_j = np.nonzero(~ok)
    if not len(bad_i):
        return
    xs, ws, pt, zs = [], [], [], []
    for i, j in zip(bad_i, bad_j):
        span = r_hi[j] - r_lo[j]
        gap = max(r_lo[j] - rho[i], rho[i] - r_hi[j], 0.0)
        # floor: a point on the face itself gets the principal value (finite)
        delta = max(dz[i, j], gap, 1e-9 * span)
        x, w = near_rule(r_lo[j], r_hi[j], rho[i], delta)
        xs.append(x)
        ws.append(w * kd[j])
        pt.append(np.full(len(x), i))
        zs.append(np.full(len(x), zp[j]))
    xs, ws, pt, zsrc = (np.concatenate(a) for a in (xs, ws, pt, zs))
    res = loop_rz(xs, rho[pt], z[pt] - zsrc, gradient=gradient)
    for q in range(nout):
        acc[q] += np.bincount(pt, weights=res[q] * ws, minlength=n)


def panels_rz(sol, side_idx, disc_idx, rho, z, gradient):
    """Exact panel sum of the given side and face panels of the solution ``sol``
    (:class:`designkit.cores.CoreSolution`) per mu0 at (rho, z) (n,): list of the 2 or 7
    cylindrical components (n,) each."""
    n = rho.shape[0]
    nout = 7 if gradient else 2
    acc = [np.zeros(n) for _ in range(nout)]
    if n == 0:
        return acc
    if len(side_idx):
        _side_panels_rz(sol, side_idx, rho, z, gradient, acc)
    if len(disc_idx):
        _face_panels_rz(sol, disc_idx, rho, z, gradient, acc)
    return acc


def azimuth_cos_sin(p, rho):
    """cos phi and sin phi of local points p (n, 3) at axis distance rho (n,); (1, 0) on the
    axis."""
    with np.errstate(invalid="ignore", divide="ignore"):
        cphi = np.where(rho > 0, p[:, 0] / np.where(rho > 0, rho, 1.0), 1.0)
        sphi = np.where(rho > 0, p[:, 1] / np.where(rho > 0, rho, 1.0), 0.0)
    return cphi, sphi


def rz_to_xyz(p, rho, comps, gradient, scale):
    """Cylindrical components (per unit) -> Cartesian B (n,3) and G (n,3,3), times ``scale``."""
    cphi, sphi = azimuth_cos_sin(p, rho)
    return cylindrical_to_cartesian(cphi, sphi, scale, comps[:7] if gradient else comps[:2],
                                    gradient)
