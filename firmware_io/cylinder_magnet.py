"""A finger magnet where it is: a uniformly magnetized cylinder in a pose, and the refusal of
magnets that overlap.

:class:`CylinderMagnet` (centre, moment along its axis, radius, length) is what the pair force
(:mod:`firmware_io.magnet_pair`), the map's several-magnet lookups (:mod:`firmware_io.mapfile`)
and designkit's coupled model check positions with; :func:`check_apart` refuses overlapping
magnets in one line naming both and their positions. Positions m, moments A m^2; numpy only.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import BadInputError


class CylinderMagnet:
    """A finger magnet where it is: centre ``position_m`` (3,) m, moment ``moment_a_m2`` (3,)
    A m^2 along its axis, ``radius_m`` and ``length_m`` m."""

    __slots__ = ("position_m", "moment_a_m2", "radius_m", "length_m")

    def __init__(self, position_m, moment_a_m2, radius_m: float, length_m: float):
        self.position_m = np.asarray(position_m, dtype=float)
        self.moment_a_m2 = np.asarray(moment_a_m2, dtype=float)
        self.radius_m = float(radius_m)
        self.length_m = float(length_m)

    def axis(self) -> np.ndarray:
        """The unit axis (3,) along the moment (+z for a zero moment)."""
        n = float(np.linalg.norm(self.moment_a_m2))
        return self.moment_a_m2 / n if n > 0 else np.array([0.0, 0.0, 1.0])

    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The unit axis u (along the moment) and two unit vectors e1, e2 across it."""
        u = self.axis()
        e1 = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        return u, e1, np.cross(u, e1)

    @property
    def bounding_radius_m(self) -> float:
        """Radius of the sphere about the centre that holds the cylinder, m."""
        return math.hypot(self.radius_m, 0.5 * self.length_m)

    def overlaps(self, other: "CylinderMagnet") -> bool:
        """Do the two cylinders share a point? (exact for parallel axes, conservative
        otherwise: their bounding capsules)."""
        d = other.position_m - self.position_m
        u, v = self.axis(), other.axis()
        if abs(abs(float(u @ v)) - 1.0) < 1e-12:
            axial = abs(float(d @ u))
            radial = float(np.linalg.norm(d - (d @ u) * u))
            return (axial < 0.5 * (self.length_m + other.length_m)
                    and radial < self.radius_m + other.radius_m)
        return float(np.linalg.norm(d)) < self.bounding_radius_m + other.bounding_radius_m


def check_apart(magnets, names=None, error: type = BadInputError) -> None:
    """Refuse magnets that overlap (:meth:`CylinderMagnet.overlaps`), or two at one point:
    ``error`` (an InputRangeError class, e.g. designkit's BadInputError) naming the two
    magnets (``names``, default their indices) and their positions, one line."""
    mags = list(magnets)
    label = [str(k) for k in range(len(mags))] if names is None else [str(n) for n in names]
    for j, b in enumerate(mags):
        for i in range(j):
            a = mags[i]
            if a.overlaps(b) or not np.any(a.position_m != b.position_m):
                raise error("magnet positions", "apart: no two magnets overlapping (centres "
                            "farther apart than their radii and lengths allow)",
                            f"magnets {label[i]} at {np.round(a.position_m, 6).tolist()} m and "
                            f"{label[j]} at {np.round(b.position_m, 6).tolist()} m overlap")
