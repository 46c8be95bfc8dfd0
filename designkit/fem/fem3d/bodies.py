"""The bodies of a 3-D model, their gmsh region tags, and the mirror symmetry of the models.

A model is a list of :class:`Cyl` (cores, the energized winding, a magnet), all with vertical
axes, in SI units (m, A/m^2, A/m). The symmetric models keep only y >= 0 (``'half'``) or
x, y >= 0 (``'quarter'``); :func:`mirror` folds output points into that part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

AIR, SHELL, MAGNET, BOUNDARY = 1, 2, 3, 4
CORE0, WIND0 = 100, 200
"""Region tags: body k is region CORE0 + k (a core) or WIND0 + k (the energized winding)."""


@dataclass(frozen=True)
class Cyl:
    """A coaxial cylinder body with a vertical axis through (x, y), spanning z0..z1 (m)."""

    kind: str  # 'core', 'winding' (energized), 'magnet'
    x: float
    y: float
    z0: float
    z1: float
    radius: float
    inner_radius: float = 0.0
    mu_r: float = 1.0
    current_density: float = 0.0
    """Winding: azimuthal current density J, A/m^2 (+: field along +z)."""
    magnetization: float = 0.0
    """Magnet: axial magnetization M, A/m."""


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
