"""The 3-D model of any device: every core of a :class:`~designkit.model.array.CoilArray` (any
pose, any core per coil) and the winding of one energized coil.

The reference for the coupled model of arrays of any layout (grid, hex, ring, tilted, free):
:func:`device_bodies` turns the array's coils into :class:`.bodies.Cyl` bodies (each core
along its coil's axis, shifted by its offset; the energized winding's uniform azimuthal current
density, ``turns * current / ((Ro - Ri) L)``), :func:`device_case` picks the largest mirror
model the bodies allow (:func:`.bodies.model_symmetry`), refines the mesh over the output
points and solves (outputs 'iron': the windings' exact field plus the iron's FEM
magnetization). Lengths in m, B in T, grad B in T/m (G[i, j] = dB_i/dx_j). Accuracy and
mesh levels: docs/fem.md.
"""

from __future__ import annotations

import numpy as np

from ...errors import BadInputError
from .bodies import Cyl, model_symmetry
from .solver import solve

REFINE_SIZE_M = 8e-3
"""Element size (level 0) in the box around the output points, m (as the 3 x 3 array case)."""
BODY_SIZE_M = 4e-3
"""Element size (level 0) at the bodies' surfaces, m (as the 3 x 3 array case)."""


def device_bodies(array, energized: int, current_a: float = 1.0) -> list:
    """The bodies of ``array`` (a CoilArray) with coil ``energized`` carrying ``current_a`` A:
    one 'core' per coil with a core (its linear ``relative_permeability``), then the energized
    winding (the other windings carry no current: air)."""
    if not 0 <= int(energized) < array.n_coils:
        raise BadInputError("energized", f"a coil index in [0, {array.n_coils - 1}]", energized)
    bodies = []
    for c in array.coils:
        if c.core is None:
            continue
        axis = c.pose.matrix[:, 2]
        centre = np.asarray(c.pose.position) + c.core.offset * axis
        bodies.append(Cyl.on_axis("core", centre, axis, c.core.length / 2, c.core.radius,
                                  mu_r=float(c.core.relative_permeability)))
    c = array.coils[int(energized)]
    j = c.turns * float(current_a) / ((c.outer_radius - c.inner_radius) * c.length)
    bodies.append(Cyl.on_axis("winding", c.pose.position, c.pose.matrix[:, 2], c.length / 2,
                              c.outer_radius, inner_radius=c.inner_radius, current_density=j))
    return bodies


def device_case(array, points, *, energized: int = 0, level: int = 0, out_dir=None,
                timeout_s: float = 3600.0):
    """B (n, 3) T and G (n, 3, 3) T/m at ``points`` (n, 3) m of ``array`` with coil
    ``energized`` at 1 A (:func:`device_bodies`), from the 3-D FEM at mesh ``level``; the
    model is cut to the largest mirror symmetry the bodies allow. Returns (B, G,
    :class:`.solver.Fem3DResult`; its ``extra['symmetry']`` names the model)."""
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    bodies = device_bodies(array, energized)
    sym = model_symmetry(bodies)
    lo, hi = pts.min(axis=0) - 0.01, pts.max(axis=0) + 0.01
    if sym in ("half", "quarter"):
        lo[1] = max(lo[1], 0.0)
    if sym == "quarter":
        lo[0] = max(lo[0], 0.0)
    refine = [(lo[0], hi[0], lo[1], hi[1], lo[2], hi[2], REFINE_SIZE_M)]
    res = solve(bodies, pts, symmetry=sym, level=level, out_dir=out_dir, refine=refine,
                body_size=BODY_SIZE_M, timeout_s=timeout_s)
    res.extra["symmetry"] = sym
    return res.b, res.g, res
