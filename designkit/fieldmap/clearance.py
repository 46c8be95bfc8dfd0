"""How far the map's box is from the coils' sources: the scale its harmonic cells grow with.

A polynomial's error in a cell falls like (cell size / distance to the nearest source)^degree
(docs/fieldmap.md), so a layer of cells is sized by the distance between its slab of the box
and the sources (windings' envelopes and cores, any pose): for upright coils under the box that
is the height above their tops; a tilted coil's rim that rises beside the box counts by its
true 3-D distance, not by its height. Lengths in m.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.array import CoilArray

SAMPLE_STEP_M = 1e-3
"""Spacing of the surface points of a tilted solid (the distance is their minimum less half
this step: a lower bound)."""


def solids(arr: CoilArray) -> list:
    """Every coil's source solids (winding envelope, core) as (centre (3,), unit axis (3,),
    radius, half length), m."""
    out = []
    for c in arr.coils:
        axis = c.pose.matrix[:, 2]
        pos = np.asarray(c.pose.position, float)
        out.append((pos, axis, c.outer_radius, c.length / 2))
        if c.core is not None:
            out.append((pos + c.core.offset * axis, axis, c.core.radius, c.core.length / 2))
    return out


def _gap(lo: float, hi: float, a: float, b: float) -> float:
    """Distance between the intervals [lo, hi] and [a, b]."""
    return max(0.0, lo - b, a - hi)


def _upright_distance(solid, lo, hi) -> float:
    """Exact distance between an upright cylinder and the box [lo, hi]: the product of a disc
    and an interval against the product of a rectangle and an interval."""
    centre, _, radius, half = solid
    dx = _gap(lo[0], hi[0], centre[0], centre[0])
    dy = _gap(lo[1], hi[1], centre[1], centre[1])
    horizontal = max(0.0, math.hypot(dx, dy) - radius)
    return math.hypot(horizontal, _gap(lo[2], hi[2], centre[2] - half, centre[2] + half))


def _surface(solid) -> np.ndarray:
    """Points (n, 3) m on a cylinder's surface, at most :data:`SAMPLE_STEP_M` apart."""
    centre, axis, radius, half = solid
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(helper, axis)
    u /= np.linalg.norm(u)
    w = np.cross(axis, u)
    n_phi = max(16, int(math.ceil(2 * math.pi * radius / SAMPLE_STEP_M)))
    phi = 2 * math.pi * np.arange(n_phi) / n_phi
    ring = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w  # (n_phi, 3)
    t = np.linspace(-half, half, max(2, int(math.ceil(2 * half / SAMPLE_STEP_M)) + 1))
    r = np.linspace(0.0, radius, max(2, int(math.ceil(radius / SAMPLE_STEP_M)) + 1))
    side = (t[:, None, None] * axis + radius * ring[None]).reshape(-1, 3)
    faces = [(s * half * axis + r[:, None, None] * ring[None]).reshape(-1, 3) for s in (-1, 1)]
    return centre + np.concatenate([side] + faces)


class Clearance:
    """Distance (m) between boxes and the nearest source solid of an array (0 when one reaches
    into the box): exact for upright coils, a lower bound within :data:`SAMPLE_STEP_M` for
    tilted ones (their surfaces sampled once). ``clearance(lo, hi)`` for the box [lo, hi]
    (3-vectors, m)."""

    def __init__(self, arr: CoilArray):
        self.upright, tilted = [], []
        for solid in solids(arr):
            (self.upright if abs(abs(solid[1][2]) - 1.0) < 1e-12 else tilted).append(solid)
        self.points = np.concatenate([_surface(s) for s in tilted]) if tilted else None

    def __call__(self, lo, hi) -> float:
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        best = min((_upright_distance(s, lo, hi) for s in self.upright), default=math.inf)
        if self.points is not None:
            d = np.maximum(np.maximum(lo - self.points, self.points - hi), 0.0)
            best = min(best, max(0.0, float(np.sqrt(np.einsum("ij,ij->i", d, d)).min())
                                 - 0.5 * SAMPLE_STEP_M))
        return best

    def slab(self, lower, upper):
        """The clearance of the box's horizontal slabs: (z_lo, z_hi) -> m, for
        :func:`designkit.fieldmap.plan.cell_layers` (the sampled points' horizontal distances
        from the box computed once)."""
        lo, hi = np.asarray(lower, float), np.asarray(upper, float)
        if self.points is None:
            return lambda z0, z1: self(np.r_[lo[:2], z0], np.r_[hi[:2], z1])
        d = np.maximum(np.maximum(lo[:2] - self.points[:, :2], self.points[:, :2] - hi[:2]), 0)
        flat2, z = np.einsum("ij,ij->i", d, d), self.points[:, 2]

        def clearance(z0, z1):
            best = min((_upright_distance(s, np.r_[lo[:2], z0], np.r_[hi[:2], z1])
                        for s in self.upright), default=math.inf)
            dz = np.maximum(np.maximum(z0 - z, z - z1), 0.0)
            return min(best, max(0.0, float(np.sqrt((flat2 + dz * dz).min()))
                                 - 0.5 * SAMPLE_STEP_M))

        return clearance
