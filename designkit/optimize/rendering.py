"""The rendering objective: the smallest upward force an array of cored coils can render.

Each coil is its winding (exact kernel) plus its 1010-steel core magnetized as the fast slice
model of :mod:`designkit.cores.rod` gives at the operating current; the force per ampere on
the finger magnet (a z-axis dipole) of every coil at every point feeds one bounded LP per point
(:func:`designkit.model.metrics.max_vertical_force`: |I_k| <= the coil limit, sum |I_k| <= the total,
Fx = Fy = 0). The bipolar drive makes the result independent of the magnet's polarity.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..constants import MU0
from ..cores.rod import RodGeometry, RodSettings, solve_rod
from ..design import Design
from ..errors import BadInputError
from ..field import cylindrical_to_cartesian
from ..field.kernels import sheet_rz
from ..field.winding import winding_rz
from ..model.metrics import max_vertical_force
from .workspace import workspace_region


def array_force_per_amp(coil_x: Sequence[float], turns: float, current_a: float,
                        centres_xy_m: np.ndarray, points_m: np.ndarray, moment_a_m2: float, *,
                        core_force_ratio: float = 1.0, n_slices: int = 12) -> np.ndarray:
    """Force per ampere on a z-axis dipole of |m| = moment_a_m2 from each coil, (n, 3, n_coils).

    Each coil: its winding (exact kernel) plus its 1010-steel core magnetized as the fast slice
    model gives at ``current_a`` (secant: field per ampere = field at current_a / current_a),
    times ``core_force_ratio`` (e.g. the panel/fast ratio at the design point). Coils do not
    couple (each core sees only its own winding). Physical x as
    :data:`designkit.optimize.DEVICE_VARIABLES`.
    """
    ri, ro, ln, a, lc, prot, _ = [float(q) for q in coil_x]
    off = ln / 2 + prot - lc / 2
    sol = solve_rod(RodGeometry(ri, ro, ln, turns, min(a, ri), lc, off), current_a,
                    RodSettings(n_slices=n_slices, quadrature="bessel"))
    pts = np.asarray(points_m, dtype=float)
    cen = np.asarray(centres_xy_m, dtype=float)
    nc, npt = len(cen), len(pts)
    rel = np.repeat(pts[None, :, :], nc, axis=0).reshape(-1, 3)
    rel[:, 0] -= np.repeat(cen[:, 0], npt)
    rel[:, 1] -= np.repeat(cen[:, 1], npt)
    rel[:, 2] += ln / 2  # winding centre at z = -ln/2 (top faces at z = 0)
    rho = np.hypot(rel[:, 0], rel[:, 1])
    z = rel[:, 2]
    j = turns / ((ro - ri) * ln)
    wres = winding_rz(ri, ro, ln / 2, rho, z, gradient=True, rtol=1e-8)
    comps = [np.asarray(q) * j for q in wres]
    e = sol.edges_m
    for k in range(len(e) - 1):
        zc, hk = 0.5 * (e[k] + e[k + 1]), 0.5 * (e[k + 1] - e[k])
        sres = sheet_rz(sol.radius_m, hk, rho, z - zc, gradient=True)
        kk = sol.m_a_per_m[k] / current_a * core_force_ratio
        comps = [c + np.asarray(q) * kk for c, q in zip(comps, sres)]
    with np.errstate(invalid="ignore", divide="ignore"):
        cphi = np.where(rho > 0, rel[:, 0] / np.where(rho > 0, rho, 1.0), 1.0)
        sphi = np.where(rho > 0, rel[:, 1] / np.where(rho > 0, rho, 1.0), 0.0)
    _, g = cylindrical_to_cartesian(cphi, sphi, MU0, comps, True)
    f = moment_a_m2 * g[:, 2, :]  # F_j = m dBz/dx_j for m along z (curl B = 0 outside)
    return f.reshape(nc, npt, 3).transpose(1, 2, 0)


def array_render_forces(coil_x: Sequence[float], turns: float, current_a: float,
                        total_current_a: float, centres_xy_m: np.ndarray, points_m: np.ndarray,
                        moment_a_m2: float, *, core_force_ratio: float = 1.0,
                        n_slices: int = 12) -> np.ndarray:
    """Largest upward force the array renders at each point (N, (n,)): |I_k| <= current_a,
    sum |I_k| <= total_current_a, Fx = Fy = 0 (:func:`designkit.model.metrics.max_vertical_force`,
    one LP per point) with the coils of :func:`array_force_per_amp`."""
    f = array_force_per_amp(coil_x, turns, current_a, centres_xy_m, points_m, moment_a_m2,
                            core_force_ratio=core_force_ratio, n_slices=n_slices)
    return max_vertical_force(f, current_a, total_current_a, lateral="zero")


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
        c, k = design.coil, design.core
        if k is None:
            raise BadInputError("design.core", "a core (rendering uses the core model)", None)
        prot = k.offset_m + k.length_m / 2 - c.length_m / 2
        coil_x = [c.inner_radius_m, c.outer_radius_m, c.length_m, k.radius_m, k.length_m,
                  prot, design.wire.diameter_m]
        turns = c.turns
    pts = workspace_region(design) if points_m is None else np.asarray(points_m, dtype=float)
    cen = np.array([[x, y] for x, y, _ in design.coil_centres_m()])
    fz = array_render_forces(coil_x, turns, design.drive.max_current_a,
                             design.drive.total_current_a, cen, pts, design.magnet.moment_a_m2,
                             core_force_ratio=core_force_ratio)
    return {"min_upward_force_n": float(fz.min()), "upward_force_n": fz.tolist(),
            "points_m": pts.tolist(), "core_force_ratio": core_force_ratio,
            "allocation": "LP per point: |I_k| <= max_current_a, sum |I_k| <= total_current_a, "
                          "Fx = Fy = 0"}


