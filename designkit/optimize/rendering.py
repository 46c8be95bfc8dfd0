"""The rendering objective: the smallest upward force an array of cored coils can render.

Each coil is its winding (exact kernel) plus its 1010-steel core magnetized as the fast slice
model of :mod:`designkit.cores.rod` gives at the operating current; the force per ampere on
the finger magnet (a z-axis dipole) of every coil at every point feeds one bounded LP per point
(:func:`designkit.model.array.max_vertical_force`: |I_k| <= the coil limit, sum |I_k| <= the total,
Fx = Fy = 0). The bipolar drive makes the result independent of the magnet's polarity.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..constants import MU0
from ..cores.rod import solve_rod
from ..design import Design, pose_on_axis
from ..design.layouts import Layout
from ..errors import BadInputError
from ..field import cylindrical_to_cartesian
from ..field.kernels import sheet_rz
from ..field.winding import winding_rz
from ..model.array import max_vertical_force
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
    ri, ro, ln, a, lc, prot, _ = [float(q) for q in coil.x]
    off = ln / 2 + prot - lc / 2
    current = coil.current_a
    sol = solve_rod(ri, ro, ln, coil.turns, min(a, ri), lc, off, current,
                    n_slices=coil.n_slices, quadrature="bessel")
    pts = np.asarray(points_m, dtype=float)
    tops, axes = layout.top_centres_m(), layout.axes()
    nc, npt = len(tops), len(pts)
    upright = np.all(np.abs(axes - (0.0, 0.0, 1.0)) <= 1e-12, axis=1)
    rots = [None if up else pose_on_axis((0.0, 0.0, 0.0), ax).matrix
            for up, ax in zip(upright, axes)]
    rel = np.empty((nc, npt, 3))
    for k in range(nc):
        centre = tops[k] - axes[k] * ln / 2  # winding centre, ln/2 below the top face
        d = pts - centre
        rel[k] = d if rots[k] is None else d @ rots[k]
    rel = rel.reshape(-1, 3)
    rho = np.hypot(rel[:, 0], rel[:, 1])
    z = rel[:, 2]
    j = coil.turns / ((ro - ri) * ln)
    wres = winding_rz(ri, ro, ln / 2, rho, z, gradient=True, rtol=1e-8)
    comps = [np.asarray(q) * j for q in wres]
    e = sol.edges_m
    for k in range(len(e) - 1):
        zc, hk = 0.5 * (e[k] + e[k + 1]), 0.5 * (e[k + 1] - e[k])
        sres = sheet_rz(sol.radius_m, hk, rho, z - zc, gradient=True)
        kk = sol.m_a_per_m[k] / current * coil.core_force_ratio
        comps = [c + np.asarray(q) * kk for c, q in zip(comps, sres)]
    with np.errstate(invalid="ignore", divide="ignore"):
        cphi = np.where(rho > 0, rel[:, 0] / np.where(rho > 0, rho, 1.0), 1.0)
        sphi = np.where(rho > 0, rel[:, 1] / np.where(rho > 0, rho, 1.0), 0.0)
    _, g = cylindrical_to_cartesian(cphi, sphi, MU0, comps, True)
    g = g.reshape(nc, npt, 3, 3)
    for k, r in enumerate(rots):
        if r is not None:
            g[k] = r @ g[k] @ r.T
    f = moment_a_m2 * g[:, :, 2, :]  # F_j = m dBz/dx_j for m along z (curl B = 0 outside)
    return f.transpose(1, 2, 0)


def array_render_forces(coil: RodCoil, layout: Layout, points_m: np.ndarray,
                        moment_a_m2: float, total_current_a: float) -> np.ndarray:
    """Largest upward force the array renders at each point (N, (n,)): |I_k| <=
    ``coil.current_a``, sum |I_k| <= total_current_a, Fx = Fy = 0
    (:func:`designkit.model.array.max_vertical_force`, one LP per point) with the coils of
    :func:`array_force_per_amp`."""
    f = array_force_per_amp(coil, layout, points_m, moment_a_m2)
    return max_vertical_force(f, coil.current_a, total_current_a, lateral="zero")


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
    :func:`designkit.model.array.max_vertical_force` with ``lateral='zero'``).

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
