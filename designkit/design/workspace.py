"""The workspace: the region the finger magnet moves in, a convex prism in the array frame.

Its outline in x, y is a convex polygon (m, counter-clockwise): by default the layout's own
footprint (:mod:`.layouts`), or a box or a disc the design names; in z it spans
``[z_min_m, z_max_m]`` above the coil tops. The map covers its bounding box; figures,
trajectories, plans and objectives sample the prism itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DISC_SIDES = 48
"""Sides of the polygon a disc workspace is drawn and tested as (its area within 0.3 %)."""


@dataclass(frozen=True)
class Workspace:
    """A convex prism: ``outline_m`` (k, 2) m, counter-clockwise, and ``z_min_m`` < ``z_max_m``.
    """

    outline_m: tuple[tuple[float, float], ...]
    z_min_m: float
    z_max_m: float

    @classmethod
    def from_polygon(cls, outline_m, z_min_m: float, z_max_m: float) -> "Workspace":
        return cls(tuple((float(x), float(y)) for x, y in np.asarray(outline_m, dtype=float)),
                   float(z_min_m), float(z_max_m))

    @classmethod
    def box(cls, half_width_m: float, z_min_m: float, z_max_m: float) -> "Workspace":
        h = float(half_width_m)
        return cls.from_polygon([(-h, -h), (h, -h), (h, h), (-h, h)], z_min_m, z_max_m)

    @classmethod
    def disc(cls, radius_m: float, z_min_m: float, z_max_m: float) -> "Workspace":
        # circumscribed polygon: it contains the disc
        a = 2 * math.pi * np.arange(DISC_SIDES) / DISC_SIDES
        r = float(radius_m) / math.cos(math.pi / DISC_SIDES)
        return cls.from_polygon(np.c_[r * np.cos(a), r * np.sin(a)], z_min_m, z_max_m)

    @property
    def outline(self) -> np.ndarray:
        """(k, 2) m."""
        return np.array(self.outline_m)

    def bounds_m(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounding box: lower and upper corners, (3,) m each."""
        o = self.outline
        return (np.r_[o.min(axis=0), self.z_min_m], np.r_[o.max(axis=0), self.z_max_m])

    def half_width_m(self) -> float:
        """Largest |x| or |y| of the outline, m: the half side of the square about the
        array's axis that holds the workspace."""
        return float(np.abs(self.outline).max())

    def contains(self, points_m, tol_m: float = 1e-9) -> np.ndarray:
        """Which points (n, 3) m lie in the prism (within ``tol_m``): (n,) bool."""
        p = np.atleast_2d(np.asarray(points_m, dtype=float))
        inside = (p[:, 2] >= self.z_min_m - tol_m) & (p[:, 2] <= self.z_max_m + tol_m)
        return inside & self.contains_xy(p[:, :2], tol_m)

    def contains_xy(self, points_xy_m, tol_m: float = 1e-9) -> np.ndarray:
        """Which points (n, 2) m lie inside the outline (within ``tol_m``): (n,) bool."""
        q = np.atleast_2d(np.asarray(points_xy_m, dtype=float))
        o = self.outline
        e = np.roll(o, -1, axis=0) - o
        # left of every counter-clockwise edge, by the signed distance
        cross = (e[None, :, 0] * (q[:, None, 1] - o[None, :, 1])
                 - e[None, :, 1] * (q[:, None, 0] - o[None, :, 0]))
        return np.all(cross / np.linalg.norm(e, axis=1)[None, :] >= -tol_m, axis=1)

    def grid_xy(self, spacing_m: float) -> np.ndarray:
        """Points (n, 2) m of a square grid of ``spacing_m`` over the bounding box that lie in
        the outline, symmetric about the box's centre."""
        lo, hi = self.bounds_m()
        axes = []
        for k in range(2):
            n = int(math.floor((hi[k] - lo[k]) / spacing_m + 1e-9))
            c = 0.5 * (lo[k] + hi[k])
            axes.append(c + (np.arange(n + 1) - n / 2) * spacing_m)
        xx, yy = np.meshgrid(axes[0], axes[1], indexing="xy")
        q = np.c_[xx.ravel(), yy.ravel()]
        return q[self.contains_xy(q)]
