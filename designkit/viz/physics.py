"""The array's field and the force on the magnet at the points of a figure (design frame, m).

The force on the finger magnet is ``F = (grad B)^T m`` (:func:`designkit.model.array.force_matrix`,
thesis eq. 2.5) with ``m`` the design's magnet moment (MagnetSpec.direction, default -z) unless
another moment is given. The design point (:func:`design_point_m`) is the magnet's centre at the
design height above the coil nearest the layout's centre, on that coil's axis; default currents
(``currents=None``): the coil nearest the design point at the design's ``drive.max_current_a``
and every other coil at 0 A -- the situation of the design point in ``designkit report``.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import TYPE_CHECKING, Sequence

import numpy as np

from ..errors import BadInputError
from ..model.array import (CoilArray, array_for_design, force_matrix, g5_from_gradient,
                           gradient_from_g5)
from ..model.skipping import SkippingEvaluator
from ..support import validate as v
from .common import B_MT, B_T, F_MN, F_N, FZ_MN, GRAD_T_M

if TYPE_CHECKING:  # pragma: no cover
    from ..design import Design


TIE_M = 1e-9
"""Coils whose distances differ by less than this, m, are equally near: the lower index wins."""


def nearest_coil(design: "Design", point_m) -> int:
    """Index of the coil whose top-face centre is nearest to the point (m); ties as in
    :attr:`designkit.design.Design.design_coil`."""
    p = np.asarray(v.vector3("point_m", point_m, "m"), dtype=float)
    d = np.linalg.norm(np.asarray(design.array.top_centres_m(), dtype=float) - p, axis=1)
    return int(np.flatnonzero(d <= d.min() + TIE_M)[0])


def resolve_currents(design: "Design", currents: Sequence[float] | None = None) -> np.ndarray:
    """Per-coil currents, A, shape (ncoils,), in the layout's coil order.

    ``None`` gives the default: the coil nearest the design point (:func:`design_point_m`) at
    ``drive.max_current_a``, the others at 0 A.
    """
    n = design.n_coils
    if currents is None:
        out = np.zeros(n)
        out[nearest_coil(design, np.asarray(design.design_point_m))] = design.drive.max_current_a
        return out
    try:
        arr = np.asarray(currents, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise BadInputError("currents", f"{n} numbers in A (one per coil)", currents) from None
    if arr.size != n:
        raise BadInputError("currents", f"{n} numbers in A (one per coil, in the layout's "
                            "order)",
                            f"{arr.size} values")
    if not np.all(np.isfinite(arr)):
        raise BadInputError("currents", "finite numbers in A", arr.tolist())
    return arr


def magnet_moment(design: "Design", moment=None) -> np.ndarray:
    """The finger magnet's dipole moment, A m^2, shape (3,): the design's (MagnetSpec.direction)."""
    if moment is None:
        return np.array(design.magnet.moment_vector_a_m2)
    return np.asarray(v.vector3("moment", moment, "A m^2"), dtype=float)


def array_field(design: "Design", points, currents: Sequence[float] | None = None, *,
                gradient: bool = True, tolerance: float | None = None):
    """Flux density (and gradient) of the design's whole coil array at points.

    :class:`designkit.model.array.CoilArray` of the whole array (its cores solved together, so the
    unpowered coils' cores count too): the one place where the coils' fields are summed.

    Parameters
    ----------
    design : Design
    points : array-like, shape (n, 3), m
    currents : sequence of float, shape (ncoils,), A, or None (see :func:`resolve_currents`)
    gradient : bool
        Also return ``G[:, i, j] = dB_i/dx_j``.
    tolerance : float in [1e-9, 0.1], or None
        None: the coupled model to the field engine's 1e-10. A float (a picture's accuracy,
        e.g. :data:`PICTURE_TOLERANCE`): the windings through
        :class:`designkit.model.skipping.SkippingEvaluator` at that tolerance (relative to the
        largest |B| and |grad B| over the points; unpowered and negligible windings skipped),
        the coupled cores by their reference rules as with None (docs/coupling.md: why the
        cores have no cheaper rule at a picture's tolerance).

    Returns
    -------
    B : ndarray, shape (n, 3), T
    G : ndarray, shape (n, 3, 3), T/m (only when gradient=True)
    """
    p, _ = v.points(points)
    cur = resolve_currents(design, currents)
    if tolerance is not None:
        v.in_range("tolerance", tolerance, 1e-9, 0.1)
    if not np.any(cur):
        b, g = np.zeros((len(p), 3)), np.zeros((len(p), 3, 3))
    elif tolerance is None:
        # the whole array, unpowered coils included: their cores are magnetized by the others
        with warnings.catch_warnings():
            # A figure is not the place to repeat the linear-core saturation warning for every
            # grid; `designkit report` states it once in its summary.
            warnings.simplefilter("ignore")
            b, g = array_for_design(design).field(p, cur)
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            b, g = _skipping_field(array_for_design(design), p, cur, gradient, tolerance)
    return (b, g) if gradient else b


PICTURE_TOLERANCE = 1e-5
"""The windings' tolerance of the slices (relative to the largest value over a slice): 1 %
down to 1e-3 of the largest value, three decades of a logarithmic colour scale."""
FIELDLINE_TOLERANCE = 1e-3
"""The tolerance of the field lines' volume (relative to its largest |B|): a streamline's
step follows the direction of B, which an error of 1e-3 of the largest value turns by less
than a degree wherever |B| is above 6 % of it."""


def _skipping_field(array, p, cur, gradient, tolerance):
    """B (n, 3) T and G (n, 3, 3) T/m (zeros if not ``gradient``): the windings through the
    skipping evaluator at ``tolerance`` and the coupled cores by their reference rules."""
    system = array.coupled()
    coupled = set() if system is None else set(system.core_index)
    # the coupled cores are added below, all together: their windings alone here, and only the
    # powered ones
    on = np.flatnonzero(cur)
    wind = CoilArray(tuple(dataclasses.replace(array.coils[k], core=None) if k in coupled
                           else array.coils[k] for k in on))
    outs = ("B", "gradient") if gradient else ("B",)
    res = SkippingEvaluator(wind, p, outs, currents=tuple(cur[on]),
                            tolerance=tolerance).evaluate()
    b = res["B"]
    g = gradient_from_g5(res["gradient"]) if gradient else np.zeros((len(p), 3, 3))
    if system is not None:
        cb = system.core_field(p, system.coil_solution(), gradient=gradient, coil_columns=True)
        if gradient:
            b = b + cb[0] @ cur
            g = g + cb[1] @ cur
        else:
            b = b + cb @ cur
    return b, g


def force_from_gradient(gradient_t_per_m: np.ndarray, moment_a_m2: np.ndarray) -> np.ndarray:
    """Force on a point dipole in air, ``F = F(m) G5`` (:func:`designkit.model.array.force_matrix`),
    N, shape (n, 3), from the gradient (n, 3, 3), T/m."""
    return g5_from_gradient(np.asarray(gradient_t_per_m)) @ force_matrix(moment_a_m2).T


def add_field_arrays(mesh, b, g=None, moment=None):
    mesh.point_data[B_T] = b
    mesh.point_data[B_MT] = np.linalg.norm(b, axis=1) * 1e3
    if g is not None:
        f = force_from_gradient(g, moment)
        mesh.point_data[GRAD_T_M] = g.reshape(-1, 9)
        mesh.point_data[F_N] = f
        mesh.point_data[F_MN] = np.linalg.norm(f, axis=1) * 1e3
        mesh.point_data[FZ_MN] = f[:, 2] * 1e3
    return mesh


def footprint_half_m(design: "Design") -> float:
    """Half side of a square about the array's axis that covers the coil tops (each with its
    outer radius) and the workspace, m."""
    tops = design.array.top_centres_m()
    reach = max(float(np.abs(tops[k, :2]).max()) + design.coil_spec(k).outer_radius_m
                for k in range(len(tops)))
    return max(design.workspace_region().half_width_m(), reach)


def solid_distance_m(design: "Design", points) -> np.ndarray:
    """Signed distance, m, shape (n,), from points (n, 3) m to the nearest winding or core of
    the array, each in its pose: < 0 inside a solid, > 0 in air.

    A winding is the hollow cylinder ``inner_radius_m <= rho <= outer_radius_m``, ``|z| <=
    length_m / 2`` of its coil's frame, a core the cylinder ``rho <= radius_m``, ``|z - offset_m|
    <= length_m / 2``; both are solids of revolution, so the distance is that to a rectangle in
    the meridian half-plane (rho, z), exact.
    """
    p, _ = v.points(points)
    out = np.full(len(p), np.inf)
    for k, pose in enumerate(design.coil_poses()):
        local = pose.to_local(p)
        rho = np.hypot(local[:, 0], local[:, 1])
        c, core = design.coil_spec(k), design.core_spec(k)
        out = np.minimum(out, _box_distance(np.maximum(c.inner_radius_m - rho,
                                                       rho - c.outer_radius_m),
                                            np.abs(local[:, 2]) - c.length_m / 2))
        if core is not None:
            out = np.minimum(out, _box_distance(rho - core.radius_m,
                                                np.abs(local[:, 2] - core.offset_m)
                                                - core.length_m / 2))
    return out


def _box_distance(d_rho: np.ndarray, d_z: np.ndarray) -> np.ndarray:
    """Signed distance to a rectangle from the signed distances to its two slabs."""
    outside = np.hypot(np.maximum(d_rho, 0.0), np.maximum(d_z, 0.0))
    return np.where((d_rho > 0) | (d_z > 0), outside, np.maximum(d_rho, d_z))


def inside_solids(design: "Design", points) -> np.ndarray:
    """Boolean mask (n,): the points (m) inside or on a core or a winding of the array, each in
    its pose (:func:`solid_distance_m` <= 0)."""
    return solid_distance_m(design, points) <= 0.0
