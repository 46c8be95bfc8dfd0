"""The iron's field at output points from its FEM magnetization (``outputs='iron'``).

M = (1 - 1/mu_r) b / mu0 in each core tetrahedron (b linear there: the second-order face
functions) is integrated by a conical product rule into point dipoles; their field and its
exact derivatives, plus the windings' exact field, give B (T) and G (T/m, G[i, j] =
dB_i/dx_j) at points that need no mesh of their own. The mirror images of the symmetric
models are added as dipoles. Reference: Stroud, Approximate Calculation of Multiple
Integrals (1971), the conical product rule; derivation in docs/fem.md.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import roots_jacobi

from ...constants import MU0
from ...field import winding_field
from .bodies import CORE0, WIND0


def conical_rule(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Stroud's conical product rule on a tetrahedron: barycentric coordinates (n^3, 4) and
    weights (n^3,) summing to 1 (fractions of the volume); exact for polynomials of degree
    2 n - 1 (Gauss-Jacobi nodes in the collapsed coordinates)."""
    u, wu = roots_jacobi(n, 2, 0)  # weight (1 - u)^2 of the collapsed coordinate
    v, wv = roots_jacobi(n, 1, 0)
    w, ww = roots_jacobi(n, 0, 0)
    u, v, w = (u + 1) / 2, (v + 1) / 2, (w + 1) / 2
    U, V, W = np.meshgrid(u, v, w, indexing="ij")
    x, y, z = U.ravel(), ((1 - U) * V).ravel(), ((1 - U) * (1 - V) * W).ravel()
    wt = (wu[:, None, None] / 8 * wv[None, :, None] / 4 * ww[None, None, :] / 2).ravel() * 6.0
    return np.column_stack([1 - x - y - z, x, y, z]), wt


def core_dipoles(xyz: np.ndarray, b: np.ndarray, mu_r: float, symmetry: str = "none",
                 n: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Point dipoles equivalent to a linear core's FEM solution.

    xyz (e, 4, 3) m: the tetrahedra's vertices; b (e, 4, 3) T: the FEM's b at them (linear in
    each tetrahedron); M = (1 - 1/mu_r) b / mu0. Returns positions (k, 3) m and moments (k, 3)
    A m^2 (the :func:`conical_rule` nodes, weights times volume), with the mirror images of
    the symmetric models (``'half'``: y -> -y, ``'quarter'``: also x -> -x; the mirrored
    moment's component along the mirror axis flips, as B's does)."""
    bary, wt = conical_rule(n)
    e1, e2, e3 = (xyz[:, k] - xyz[:, 0] for k in (1, 2, 3))
    vol = np.abs(np.einsum("ei,ei->e", np.cross(e1, e2), e3)) / 6.0
    m_vert = b * ((1.0 - 1.0 / mu_r) / MU0)
    pos = np.einsum("qk,ekj->eqj", bary, xyz).reshape(-1, 3)
    mom = (np.einsum("qk,ekj->eqj", bary, m_vert)
           * (vol[:, None] * wt[None, :])[:, :, None]).reshape(-1, 3)
    for ax in {"none": (), "half": (1,), "quarter": (1, 0)}[symmetry]:
        flip = np.ones(3)
        flip[ax] = -1.0
        pos = np.vstack([pos, pos * flip])
        mom = np.vstack([mom, mom * flip])
    return pos, mom


def dipoles_field(points: np.ndarray, pos: np.ndarray, mom: np.ndarray,
                  chunk: int = 65536) -> tuple[np.ndarray, np.ndarray]:
    """B (n, 3) T and G (n, 3, 3) T/m (G[i, j] = dB_i/dx_j) of point dipoles ``mom`` (k, 3)
    A m^2 at ``pos`` (k, 3) m, at points (n, 3) m away from them."""
    c = MU0 / (4.0 * math.pi)
    b = np.zeros((len(points), 3))
    g = np.zeros((len(points), 3, 3))
    for i, p in enumerate(points):
        for a in range(0, len(pos), chunk):
            r = p - pos[a:a + chunk]
            m = mom[a:a + chunk]
            r2 = np.einsum("ij,ij->i", r, r)
            ir3 = r2 ** -1.5
            ir5 = ir3 / r2
            mr = np.einsum("ij,ij->i", m, r)
            b[i] += c * (3.0 * (mr * ir5) @ r - ir3 @ m)
            rm = (r * ir5[:, None]).T @ m  # sum r_i m_j / r^5
            g[i] += c * (3.0 * (rm + rm.T + np.eye(3) * np.sum(mr * ir5))
                         - 15.0 * (r * (mr * ir5 / r2)[:, None]).T @ r)
    return b, g


def _frame(axis) -> np.ndarray:
    """A rotation (3, 3) whose third column is the unit ``axis`` (the winding field is
    axisymmetric: the first two columns are any orthonormal pair)."""
    z = np.asarray(axis, float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def iron_field(work, stats, bodies, points, symmetry):
    """B (n, 3) T, G (n, 3, 3) T/m at points: the windings' exact field plus the cores' (from
    the ``bcore_<tag>.txt`` tables :func:`problem_text` prints with ``core_table``)."""
    b = np.zeros((len(points), 3))
    g = np.zeros((len(points), 3, 3))
    for t in stats["cores"]:
        body = bodies[t - (WIND0 if t >= WIND0 else CORE0)]
        if t >= WIND0:
            rot = _frame(body.axis)  # columns: local x, y, z (the axis) in the global frame
            loc = (points - body.centre()) @ rot
            length = body.z1 - body.z0
            amp_turns = body.current_density * (body.radius - body.inner_radius) * length
            bw, gw = winding_field(loc, body.inner_radius, body.radius, length, 1.0,
                                   amp_turns, gradient=True)
            b += bw @ rot.T
            g += np.einsum("ia,nab,jb->nij", rot, gw, rot)
        else:
            d = np.loadtxt(work / f"bcore_{t}.txt", ndmin=2)
            pos, mom = core_dipoles(d[:, :12].reshape(-1, 4, 3), d[:, 12:24].reshape(-1, 4, 3),
                                    body.mu_r, symmetry)
            bc, gc = dipoles_field(points, pos, mom)
            b += bc
            g += gc
    return b, g
