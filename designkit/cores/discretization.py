"""Meridian panels of a core and their influence matrix, shared by the single-core and the
coupled array solve.

A core (radius R, axial span [offset - length/2, offset + length/2] of the winding's local
frame) carries piecewise-constant azimuthal surface current K (A/m) on panels of its meridian
contour: side panels at r = R (exact current sheets, :func:`designkit.field.kernels.sheet_rz`)
and annular panels in the end faces and slice interfaces (Gauss rules of loops,
:func:`designkit.field.kernels.loop_rz`), graded towards the rims where K has the r^(-1/3)
corner singularity of a high-mu edge. The collocation equation
``K = f (H0_t + PV[H_K]_t)``, f = 2 (mu_in - mu_out) / (mu_in + mu_out), is derived in
docs/core_model.md.
"""

from __future__ import annotations

import functools

import numpy as np

from ..field.kernels import loop_rz, sheet_rz

N_SIDE = 48
"""Side panels of the m = 0 contour (split among axial slices for a nonlinear core)."""
N_CAP = 16
"""Annular panels per end face or slice interface."""


@functools.lru_cache(maxsize=64)
def gauss(n: int):
    """Gauss-Legendre nodes and weights on [-1, 1] (cached, read-only: the core rules ask for
    the same few orders many times)."""
    x, w = np.polynomial.legendre.leggauss(n)
    x.flags.writeable = False
    w.flags.writeable = False
    return x, w


def graded_edges(lo, hi, n, ends="both"):
    """Panel edges on [lo, hi] clustered like Chebyshev points towards the rims ('both') or
    towards hi only ('hi'), shape (n + 1,)."""
    u = np.linspace(0.0, 1.0, n + 1)
    if ends == "both":
        t = 0.5 * (1.0 - np.cos(np.pi * u))
    else:  # clustered at hi only
        t = np.sin(0.5 * np.pi * u)
    e = lo + (hi - lo) * t
    e[0], e[-1] = lo, hi
    return e


def disc_nodes(r_lo, r_hi, n):
    """Gauss-Legendre radii and weights of annular panels [r_lo, r_hi] (nd,): (nd, n) each."""
    x, w = gauss(n)
    h = 0.5 * (r_hi - r_lo)
    c = 0.5 * (r_hi + r_lo)
    return c[:, None] + h[:, None] * x[None, :], h[:, None] * w[None, :]


def panel_geometry(radius, length, offset, slice_edges=None, n_side=N_SIDE, n_cap=N_CAP):
    """Panels of the core contour (and of the interfaces between axial slices).

    Returns ``side`` (ns, 2) z edges, ``side_slice`` (ns,) slice index of each side panel and
    ``discs`` (nd, 5) rows (z, r_lo, r_hi, slice_below, slice_above), -1 meaning air.
    """
    lo, hi = offset - length / 2, offset + length / 2
    if slice_edges is None:
        slice_edges = np.array([lo, hi])
    nsl = len(slice_edges) - 1
    side_edges = []
    side_slice = []
    per = max(4, int(round(n_side / nsl))) if nsl > 1 else n_side
    for k in range(nsl):
        # every slice is graded towards both of its ends, not only the core's: each interface
        # between slices carries disc currents too, and the side current varies fastest there
        e = graded_edges(slice_edges[k], slice_edges[k + 1], per, "both")
        side_edges.append(np.column_stack([e[:-1], e[1:]]))
        side_slice.append(np.full(len(e) - 1, k))
    side = np.concatenate(side_edges)
    side_slice = np.concatenate(side_slice)
    re = graded_edges(0.0, radius, n_cap, "hi")
    discs = []  # (z, r_lo, r_hi, slice_below, slice_above)  (-1 = air)
    for j, ze in enumerate(slice_edges):
        below = j - 1 if j > 0 else -1
        above = j if j < nsl else -1
        for i in range(n_cap):
            discs.append((ze, re[i], re[i + 1], below, above))
    discs = np.array(discs)
    return side, side_slice, discs


def panel_basis_rz(radius, side, discs, rho, z, nodes, gradient=False):
    """Field per mu0 at (rho, z) (n,) of every panel at unit K: side sheets, then face panels
    by ``nodes``-point Gauss rules. Returns the 2 (or with ``gradient`` 7) cylindrical
    components of :func:`designkit.field.kernels.loop_rz`, each (n, ns + nd)."""
    n = len(rho)
    h = 0.5 * (side[:, 1] - side[:, 0])
    c = 0.5 * (side[:, 1] + side[:, 0])
    ns = len(h)
    rs = sheet_rz(radius, np.tile(h, n), np.repeat(rho, ns), np.repeat(z, ns) - np.tile(c, n),
                  gradient=gradient)
    rq, wq = disc_nodes(discs[:, 1], discs[:, 2], nodes)
    nd = len(discs)
    m = nd * nodes
    rl = loop_rz(np.tile(rq.ravel(), n), np.repeat(rho, m),
                 np.repeat(z, m) - np.tile(np.repeat(discs[:, 0], nodes), n), gradient=gradient)
    ww = wq.ravel()
    return [np.hstack([a.reshape(n, ns), (b.reshape(n, m) * ww).reshape(n, nd, nodes)
                       .sum(axis=2)]) for a, b in zip(rs, rl)]


def influence_system(radius, side, discs, winding):
    """Influence matrix A (tangential field per mu0 per unit K at the collocation points) and
    the applied tangential H per ampere of ``winding`` (:class:`WindingGeometry`).

    Returns (A (n, n), h_t (n,) 1/m, rho (n,) m, z (n,) m), n = ns + nd.
    """
    ns = len(side)
    # collocation points: panel centres; tangents +z on the side, -r on the faces
    cz_side = 0.5 * (side[:, 0] + side[:, 1])
    cr_disc = 0.5 * (discs[:, 1] + discs[:, 2])
    rho = np.concatenate([np.full(ns, radius), cr_disc])
    z = np.concatenate([cz_side, discs[:, 0]])
    # side panels: exact sheets (mean of the two sides on the sheet = PV); disc panels:
    # 16-node Gauss rules of loops
    br, bz = panel_basis_rz(radius, side, discs, rho, z, 16)
    a = np.concatenate([bz[:ns], -br[ns:]])
    # same-plane disc-disc: tangential (radial) field of a loop vanishes in its own plane
    same = np.abs(discs[:, 0][:, None] - discs[:, 0][None, :]) < 1e-15
    a[ns:, ns:][same] = 0.0
    hr, hz = winding.h_rz(rho, z)
    h_t = np.concatenate([hz[:ns], -hr[ns:]])
    return a, h_t, rho, z


def interface_factor(mu_in, mu_out):
    """f = 2 (mu_in - mu_out) / (mu_in + mu_out) of the interface equation (relative mu)."""
    return 2.0 * (mu_in - mu_out) / (mu_in + mu_out)
