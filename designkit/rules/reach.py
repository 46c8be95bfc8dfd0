"""How low the finger magnet can go: the highest printed part or sensor board under it (SI, m).

The magnet (radius R_m, length L_m, axis vertical) at a point p covers the disc of R_m about p
in x, y. Over a region of such points (the workspace's outline, or the design point alone) the
lowest reachable magnet centre is the highest point of every obstacle inside the region grown
by R_m, plus L_m / 2. Obstacles on the upper side: the upper frame plate, the sensor boards
and their holders (the mount plate's top is the boards' top; a cap is a cylinder on the coil
axis). Each highest point is a linear program: a box, a plate (prism) or a cap (its
circumscribed 24-gon, conservative by under 1 % of its radius) intersected with the grown
region (mitred, so it contains the rounded one: conservative).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.optimize import linprog

from ..design import Design, pose_on_axis
from ..design.layouts import grown_hull
from .geometry import assembly, board_top_m
from .convex import Box, Cylinder, Prism

CAP_SIDES = 24
"""Sides of the polygon a cylindrical obstacle is circumscribed by."""


def _halfplanes(outline: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A (k, 2), b (k,) with A xy <= b inside a counter-clockwise convex polygon."""
    e = np.roll(outline, -1, axis=0) - outline
    n = np.c_[e[:, 1], -e[:, 0]]
    return n, np.einsum("ij,ij->i", n, outline)


def _local_bounds(solid) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(origin (3,), rotation (3, 3), A_local, b_local): the solid as {origin + R u:
    A_local u <= b_local}."""
    if isinstance(solid, Box):
        e = np.asarray(solid.half_extents_m)
        a = np.vstack([np.eye(3), -np.eye(3)])
        return np.asarray(solid.centre), np.asarray(solid.rotation), a, np.r_[e, e]
    if isinstance(solid, Cylinder):
        r = pose_on_axis((0.0, 0.0, 0.0), solid.axis).matrix
        ang = 2 * math.pi * np.arange(CAP_SIDES) / CAP_SIDES
        sides = np.c_[np.cos(ang), np.sin(ang), np.zeros(CAP_SIDES)]
        a = np.vstack([sides, [[0, 0, 1.0], [0, 0, -1.0]]])
        b = np.r_[np.full(CAP_SIDES, solid.radius_m), solid.half_length_m, solid.half_length_m]
        return np.asarray(solid.centre), r, a, b
    if isinstance(solid, Prism):
        n, b = _halfplanes(np.asarray(solid.outline_m))
        a = np.vstack([np.c_[n, np.zeros(len(n))], [[0, 0, 1.0], [0, 0, -1.0]]])
        return np.zeros(3), np.eye(3), a, np.r_[b, solid.z1_m, -solid.z0_m]
    raise TypeError(type(solid).__name__)


def highest_point_m(solid, region_xy: np.ndarray) -> float | None:
    """Highest z of ``solid`` over the convex region ``region_xy`` (k, 2) m, or None when none
    of it lies over the region."""
    origin, rot, a_loc, b_loc = _local_bounds(solid)
    n, b = _halfplanes(np.asarray(region_xy, dtype=float))
    # p = origin + R u: region rows n . p_xy <= b  ->  (n R_xy) u <= b - n . origin_xy
    a_reg = n @ rot[:2, :]
    b_reg = b - n @ origin[:2]
    res = linprog(-rot[2, :], A_ub=np.vstack([a_loc, a_reg]), b_ub=np.r_[b_loc, b_reg],
                  bounds=[(None, None)] * 3, method="highs")
    if res.status != 0:
        return None
    return float(origin[2] - res.fun)


def upper_obstacles(design: Design) -> list:
    """The solids above the coil tops the magnet must stay clear of (module docstring)."""
    asm = assembly(design)
    c = design.cad
    out: list = [Prism(asm.upper.outline_m, asm.upper.z0_m, asm.upper.z1_m)]
    pos, rot = design.sensor_poses()
    n_up = design.n_coils if design.sensors.layout != "free" else len(pos)
    half = (c.board_width_m / 2, c.board_width_m / 2, c.board_thickness_m / 2)
    for k in range(n_up):
        out.append(Box(tuple(pos[k]), tuple(map(tuple, rot[k])), half))
    if asm.sensor_holder == "mount":
        top = board_top_m(design) + max(s.centre_m[2] for s in asm.upper.seats)
        out.append(Prism(asm.upper.outline_m, top - c.board_thickness_m - c.mount_floor_m, top))
    elif asm.sensor_holder == "caps":
        for s in asm.upper.seats:
            t = asm.type_of_coil(s.coil)
            base, top = t.reach_upper_m[0], board_top_m(design)
            a = np.asarray(s.axis)
            centre = np.asarray(s.centre_m) + a * 0.5 * (base + top)
            out.append(Cylinder(tuple(centre), s.axis, 0.5 * (top - base),
                                t.bore_radius_m - c.press_fit_clearance_m))
    return out


def _floor(design: Design, region_xy: np.ndarray) -> float:
    """Lowest magnet centre over ``region_xy``: obstacles' highest point + L_m / 2, m."""
    grown = grown_hull(region_xy, design.magnet.radius_m)
    up = np.array([[0.0, 0.0, 1.0]])
    obstacles = upper_obstacles(design)
    tops = sorted(((float(o.support_value(up)[0]), k) for k, o in enumerate(obstacles)),
                  reverse=True)
    best = -np.inf
    for top, k in tops:  # the highest first: one not above the best so far cannot raise it
        if top <= best:
            break
        h = highest_point_m(obstacles[k], grown)
        if h is not None:
            best = max(best, h)
    return (best if np.isfinite(best) else 0.0) + design.magnet.length_m / 2


@functools.lru_cache(maxsize=64)
def reachable_height_m(design: Design) -> float:
    """Lowest magnet-centre height anywhere over the workspace outline, m (the upright array:
    board top + magnet half length)."""
    return _floor(design, design.workspace_region().outline)


@functools.lru_cache(maxsize=64)
def design_point_floor_m(design: Design) -> float:
    """Lowest magnet-centre height at the design point's x, y, m."""
    x, y, _ = design.design_point_m
    return _floor(design, np.array([[x, y]]))
