"""The bodies of a 3-D model, their gmsh region tags, and the mirror symmetry of the models.

A model is a list of :class:`Cyl` (cores, the energized winding, a magnet), each a coaxial
cylinder about its own axis (any direction; the magnet's vertical), in SI units (m, A/m^2,
A/m). The symmetric models keep only y >= 0 (``'half'``) or x, y >= 0 (``'quarter'``);
:func:`mirror` folds output points into that part and :func:`model_symmetry` finds the
largest of them the bodies allow.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

AIR, SHELL, MAGNET, BOUNDARY = 1, 2, 3, 4
CORE0, WIND0 = 100, 200
"""Region tags: body k is region CORE0 + k (a core) or WIND0 + k (the energized winding)."""


@dataclass(frozen=True)
class Cyl:
    """A coaxial cylinder body about the line through (x, y, ``origin_z``) along the unit
    ``axis``, spanning z0..z1 (m) along it (a vertical body: from (x, y, z0) to (x, y, z1))."""

    kind: str  # 'core', 'winding' (energized), 'magnet'
    x: float
    y: float
    z0: float
    z1: float
    radius: float
    inner_radius: float = 0.0
    mu_r: float = 1.0
    current_density: float = 0.0
    """Winding: azimuthal current density J, A/m^2 (+: field along +axis)."""
    magnetization: float = 0.0
    """Magnet: axial magnetization M, A/m."""
    axis: tuple = (0.0, 0.0, 1.0)
    """Unit vector of the body's axis (global frame)."""
    origin_z: float = 0.0
    """z of the axis line's reference point (x, y, origin_z), m."""

    @classmethod
    def on_axis(cls, kind: str, centre, axis, half_length: float, radius: float,
                **values) -> "Cyl":
        """The body centred at ``centre`` (3,) m along the unit ``axis`` (3,), its length
        2 ``half_length`` (m); ``values``: the other fields (inner_radius, mu_r, ...)."""
        c = [float(q) for q in centre]
        a = np.asarray(axis, float)
        return cls(kind, c[0], c[1], -half_length, half_length, radius,
                   axis=tuple(float(q) for q in a / np.linalg.norm(a)), origin_z=c[2],
                   **values)

    @property
    def vertical(self) -> bool:
        return self.axis == (0.0, 0.0, 1.0)

    @property
    def origin(self) -> np.ndarray:
        """The axis line's reference point (3,) m (z0, z1 count from it)."""
        return np.array([self.x, self.y, self.origin_z])

    def end_points(self) -> tuple[np.ndarray, np.ndarray]:
        """The centres of the two end faces (3,) m, at z0 and z1 along the axis."""
        a = np.asarray(self.axis)
        return self.origin + self.z0 * a, self.origin + self.z1 * a

    def centre(self) -> np.ndarray:
        """The body's centre (3,) m."""
        lo, hi = self.end_points()
        return 0.5 * (lo + hi)

    def mirrored(self, axis_index: int) -> "Cyl":
        """The body's mirror image in the plane x_axis_index = 0."""
        flip = np.ones(3)
        flip[axis_index] = -1.0
        o, a = self.origin * flip, np.asarray(self.axis) * flip
        return dataclasses.replace(self, x=float(o[0]), y=float(o[1]), origin_z=float(o[2]),
                                   axis=tuple(float(q) + 0.0 for q in a))

    def same_body(self, other: "Cyl", tol: float = 1e-9) -> bool:
        """Whether ``other`` occupies the same solid with the same material and sources (a
        winding's current and a magnet's magnetization follow the axis: reversed, they are
        another body; a core's axis may point either way)."""
        if (self.kind, self.mu_r, self.current_density, self.magnetization) != (
                other.kind, other.mu_r, other.current_density, other.magnetization):
            return False
        close = np.allclose
        return bool(close([self.radius, self.inner_radius, self.z1 - self.z0],
                          [other.radius, other.inner_radius, other.z1 - other.z0], atol=tol)
                    and (close(self.axis, other.axis, atol=tol) or (
                        self.kind == "core" and close(self.axis, -np.asarray(other.axis),
                                                      atol=tol)))
                    and close(self.centre(), other.centre(), atol=tol))


MIRROR_AXES = {"none": (), "half": (1,), "quarter": (0, 1)}
"""Coordinate axes whose sign the symmetric model folds away (y for 'half', x and y for
'quarter')."""


def mirror(points, symmetry):
    """Points folded into the modelled part and the sign matrices S (B -> S B, G -> S G S).

    Parameters
    ----------
    points : array (n, 3), m
    symmetry : {'none', 'half', 'quarter'}

    Returns
    -------
    folded : ndarray (n, 3), m
    signs : ndarray (n, 3) of +-1
    """
    p = np.array(points, dtype=float)
    s = np.ones((len(p), 3))
    if symmetry in ("quarter", "half"):
        s[:, 1] = np.where(p[:, 1] < 0, -1.0, 1.0)
        p[:, 1] = np.abs(p[:, 1])
    if symmetry == "quarter":
        s[:, 0] = np.where(p[:, 0] < 0, -1.0, 1.0)
        p[:, 0] = np.abs(p[:, 0])
    return p, s


def model_symmetry(bodies) -> str:
    """The largest symmetric model the bodies allow: 'quarter' when the set of bodies is its
    own image under x -> -x and under y -> -y, 'half' under y -> -y alone, else 'none'.

    The cut planes carry B . n = 0, which holds when the sources are their own mirror images
    as polar currents: a winding or magnet on a plane must have its axis in it (its image is
    then itself), a body off the plane must have an image body."""
    def closed(axis_index):
        for b in bodies:
            img = b.mirrored(axis_index)
            if not any(img.same_body(o) for o in bodies):
                return False
        return True

    if not closed(1):
        return "none"
    return "quarter" if closed(0) else "half"
