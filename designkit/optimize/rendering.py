"""The rendering objective: the smallest upward force an array of cored coils can render.

Each coil is its winding (exact kernel) plus its 1010-steel core magnetized as the fast slice
model of :mod:`designkit.cores.rod` gives at the operating current; the force per ampere on
the finger magnet (a z-axis dipole) of every coil at every point feeds one bounded LP per point
(:func:`designkit.model.metrics.max_vertical_force`: |I_k| <= the coil limit, sum |I_k| <= the total,
Fx = Fy = 0). The bipolar drive makes the result independent of the magnet's polarity.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import sparse
from scipy.optimize import linprog

from ..constants import MU0
from ..cores.rod import RodGeometry, RodSettings, solve_rods
from ..design import Design, pose_on_axis
from ..design.layouts import Layout
from ..errors import BadInputError
from ..field import cylindrical_to_cartesian
from ..field.kernels import sheet_rz
from ..field.winding import winding_rz
from ..model.metrics import max_vertical_force
from .workspace import workspace_region


@dataclass(frozen=True)
class RodCoil:
    """One cored coil of the device problem at its operating point (SI).

    ``x``: the physical variables :data:`designkit.optimize.DEVICE_VARIABLES` (winding radii and
    length, core radius, length and protrusion above the winding top, bare wire), m;
    ``current_a``: the operating current, A (the core's secant: field per ampere = field at
    ``current_a`` / ``current_a``); ``core_force_ratio`` scales the core's share (e.g. the
    panel / fast ratio at the design point); ``n_slices``: slices of the fast core model."""

    x: tuple[float, ...]
    turns: float
    current_a: float
    core_force_ratio: float = 1.0
    n_slices: int = 12


def array_force_per_amp(coil: RodCoil, layout: Layout, points_m: np.ndarray,
                        moment_a_m2: float) -> np.ndarray:
    """Force per ampere on a z-axis dipole of |m| = moment_a_m2 from each coil, (n, 3, n_coils).

    Every coil of ``layout`` (its top-face centres and axes: :mod:`designkit.design.layouts`)
    is ``coil``: its winding (exact kernel) plus its 1010-steel core magnetized as the fast
    slice model gives at ``coil.current_a``, times ``coil.core_force_ratio``. Coils do not
    couple (each core sees only its own winding). The gradient of a tilted coil is rotated
    into the array frame (G = R G_local R^T); F_j = |m| dBz/dx_j (curl B = 0 outside).
    """
    return forces_per_amp_many([coil], [layout], points_m, moment_a_m2)[0]


@functools.lru_cache(maxsize=4096)
def _rotation(axis: tuple[float, float, float]) -> np.ndarray:
    """The coil frame whose local z is ``axis`` (:func:`designkit.design.pose_on_axis`)."""
    return pose_on_axis((0.0, 0.0, 0.0), axis).matrix


def _relative(layout: Layout, length_m: float, points: np.ndarray):
    """Points in each coil's frame (n_coils * n, 3) and the coils' rotations (None: upright)."""
    tops, axes = layout.top_centres_m(), layout.axes()
    upright = np.all(np.abs(axes - (0.0, 0.0, 1.0)) <= 1e-12, axis=1)
    rots = [None if up else _rotation(tuple(map(float, ax))) for up, ax in zip(upright, axes)]
    rel = np.empty((len(tops), len(points), 3))
    for k in range(len(tops)):
        d = points - (tops[k] - axes[k] * length_m / 2)  # winding centre, L/2 below the top
        rel[k] = d if rots[k] is None else d @ rots[k]
    return rel.reshape(-1, 3), rots


def forces_per_amp_many(coils: list[RodCoil], layouts: list[Layout], points_m: np.ndarray,
                        moment_a_m2: float) -> np.ndarray:
    """:func:`array_force_per_amp` of several coil designs (each on its own layout) at the
    same points, (B, n, 3, n_coils): one batched core solve and one kernel call for every
    core slice of every design (an optimizer's finite-difference stencil costs about one)."""
    pts = np.asarray(points_m, dtype=float)
    xs = np.array([c.x[:7] for c in coils], dtype=float)
    ri, ro, ln, a, lc, prot = xs[:, :6].T
    current = coils[0].current_a
    sols = solve_rods(RodGeometry(ri, ro, ln, [c.turns for c in coils], np.minimum(a, ri), lc,
                                  ln / 2 + prot - lc / 2), current,
                      RodSettings(n_slices=coils[0].n_slices, quadrature="bessel"))
    frames = [_relative(lay, ln[b], pts) for b, lay in enumerate(layouts)]
    rel = np.concatenate([f[0] for f in frames])
    n_each = len(frames[0][0])
    rho, z = np.hypot(rel[:, 0], rel[:, 1]), rel[:, 2]
    comps = np.empty((7, len(rel)))
    for b, c in enumerate(coils):
        sel = slice(b * n_each, (b + 1) * n_each)
        j = c.turns / ((ro[b] - ri[b]) * ln[b])
        wres = winding_rz(ri[b], ro[b], ln[b] / 2, rho[sel], z[sel], gradient=True, rtol=1e-8)
        comps[:, sel] = [np.asarray(q) * j for q in wres]
    # every slice of every core at every point in one kernel call
    e = sols.edges_m  # (B, n_slices + 1)
    zc, hk = 0.5 * (e[:, :-1] + e[:, 1:]), 0.5 * (e[:, 1:] - e[:, :-1])
    n_sl = zc.shape[1]
    rad = np.repeat(sols.radius_m, n_each)
    sres = sheet_rz(np.tile(rad, n_sl), np.repeat(hk.T, n_each, axis=1).ravel(),
                    np.tile(rho, n_sl), (z[None, :] - np.repeat(zc.T, n_each, axis=1)).ravel(),
                    gradient=True)
    sres = [np.asarray(q).reshape(n_sl, len(rel)) for q in sres]
    ratio = np.repeat([c.core_force_ratio for c in coils], n_each)
    for k in range(n_sl):
        kk = np.repeat(sols.m_a_per_m[:, k], n_each) / current * ratio
        comps = comps + np.array([q[k] for q in sres]) * kk
    with np.errstate(invalid="ignore", divide="ignore"):
        cphi = np.where(rho > 0, rel[:, 0] / np.where(rho > 0, rho, 1.0), 1.0)
        sphi = np.where(rho > 0, rel[:, 1] / np.where(rho > 0, rho, 1.0), 0.0)
    _, g = cylindrical_to_cartesian(cphi, sphi, MU0, list(comps), True)
    nc, npt = n_each // len(pts), len(pts)
    g = g.reshape(len(coils), nc, npt, 3, 3)
    for b, (_, rots) in enumerate(frames):
        for k, r in enumerate(rots):
            if r is not None:
                g[b, k] = r @ g[b, k] @ r.T
    f = moment_a_m2 * g[:, :, :, 2, :]  # F_j = m dBz/dx_j for m along z (curl B = 0 outside)
    return f.transpose(0, 2, 3, 1)


def pure_push_forces(f: np.ndarray, max_current_a: float, total_current_a: float) -> np.ndarray:
    """Largest upward force at each point with no lateral force, N (P,): maximize
    Fz = f[p, 2] . I s.t. f[p, :2] . I = 0, |I_k| <= max_current_a, sum |I_k| <= total_current_a,
    from force per ampere ``f`` (P, 3, n_coils) N/A: the LP of
    :func:`designkit.model.metrics.max_vertical_force` (``lateral='zero'``) for every point in
    one block-diagonal linear program (HiGHS; I = I+ - I-, both >= 0)."""
    n_pts, _, nc = f.shape
    nv = 2 * nc
    gain = np.concatenate([f[:, 2, :], -f[:, 2, :]], axis=1)  # (P, 2 nc)
    a_ub = sparse.kron(sparse.eye(n_pts), np.ones((1, nv)), format="csr")
    a_eq = sparse.block_diag([np.c_[f[k, :2], -f[k, :2]] for k in range(n_pts)], format="csr")
    res = linprog(-gain.ravel(), A_ub=a_ub, b_ub=np.full(n_pts, float(total_current_a)),
                  A_eq=a_eq, b_eq=np.zeros(2 * n_pts), bounds=(0.0, float(max_current_a)),
                  method="highs")
    if res.status != 0:  # a point the LP cannot solve: each alone (0 N where infeasible)
        return max_vertical_force(f, max_current_a, total_current_a, lateral="zero")
    return np.maximum(np.einsum("pk,pk->p", res.x.reshape(n_pts, nv), gain), 0.0)


def array_render_forces(coil: RodCoil, layout: Layout, points_m: np.ndarray,
                        moment_a_m2: float, total_current_a: float) -> np.ndarray:
    """Largest upward force the array renders at each point (N, (n,)): |I_k| <=
    ``coil.current_a``, sum |I_k| <= total_current_a, Fx = Fy = 0 (:func:`pure_push_forces`)
    with the coils of :func:`array_force_per_amp`."""
    f = array_force_per_amp(coil, layout, points_m, moment_a_m2)
    return pure_push_forces(f, coil.current_a, total_current_a)


def render_forces_many(coils: list[RodCoil], layouts: list[Layout], points_m: np.ndarray,
                       moment_a_m2: float, total_current_a: float) -> np.ndarray:
    """:func:`array_render_forces` of several designs, (B, n) N: one batched field evaluation
    (:func:`forces_per_amp_many`) and one linear program for every point of every design."""
    f = forces_per_amp_many(coils, layouts, points_m, moment_a_m2)
    b, n = f.shape[:2]
    return pure_push_forces(f.reshape(b * n, 3, -1), coils[0].current_a,
                            total_current_a).reshape(b, n)


def design_coil_x(design: Design) -> list[float]:
    """The physical variables (:data:`designkit.optimize.DEVICE_VARIABLES`) of a design's own
    coil and core, m (BadInputError without a core)."""
    c, k = design.coil, design.core
    if k is None:
        raise BadInputError("design.core", "a core (rendering uses the core model)", None)
    prot = k.offset_m + k.length_m / 2 - c.length_m / 2
    return [c.inner_radius_m, c.outer_radius_m, c.length_m, k.radius_m, k.length_m,
            prot, design.wire.diameter_m]


def rendering_force(design: Design, *, coil_x: Sequence[float] | None = None,
                    turns: float | None = None, points_m: np.ndarray | None = None,
                    core_force_ratio: float = 1.0) -> dict:
    """The rendering objective: the smallest upward force the array can render over the
    workspace region with the bounded allocation (|I_k| <= drive.max_current_a,
    sum |I_k| <= drive.total_current_a, Fx = Fy = 0: one LP per point,
    :func:`designkit.model.metrics.max_vertical_force` with ``lateral='zero'``).

    The bipolar drive makes the result independent of the magnet's polarity (I -> -I).
    Default coil: the design's own. Returns min_upward_force_n, per-point forces (N) and the
    points (m).
    """
    if coil_x is None:
        coil_x, turns = design_coil_x(design), design.coil.turns
    pts = workspace_region(design) if points_m is None else np.asarray(points_m, dtype=float)
    coil = RodCoil(tuple(float(q) for q in coil_x), float(turns), design.drive.max_current_a,
                   core_force_ratio)
    fz = array_render_forces(coil, design.array, pts, design.magnet.moment_a_m2,
                             design.drive.total_current_a)
    return {"min_upward_force_n": float(fz.min()), "upward_force_n": fz.tolist(),
            "points_m": pts.tolist(), "core_force_ratio": core_force_ratio,
            "allocation": "LP per point: |I_k| <= max_current_a, sum |I_k| <= total_current_a, "
                          "Fx = Fy = 0"}
