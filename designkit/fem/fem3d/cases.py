"""The thesis cases of the 3-D reference: one coil, two cores, the 3x3 array, the magnet's pull.

Geometry from the default design (:func:`thesis_geometry`, SI), array frame (coil top faces at
z = 0). Each case builds its :class:`.bodies.Cyl` list, picks the symmetry and refinement and
calls :func:`.solver.solve`; :func:`image_force_z` is the FEM-independent reference for the
magnet above a block (the image method). Accuracy of each case: docs/fem.md.
"""

from __future__ import annotations

import math

import numpy as np

from ...design import default_design
from ...errors import BadInputError
from ...field import magnetized_cylinder_field
from .bodies import Cyl
from .solver import solve


def thesis_geometry():
    """(ri, ro, length, turns, core_radius, core_length, pitch, magnet) of the default design,
    SI; the winding's top face at z = 0 (array frame), cores centred on their windings."""
    d = default_design()
    c = d.coil
    core = d.core
    return dict(ri=c.inner_radius_m, ro=c.outer_radius_m, length=c.length_m, turns=c.turns,
                core_radius=core.radius_m, core_length=core.length_m,
                core_offset=core.offset_m, pitch=d.array.pitch_m,
                magnet_radius=d.magnet.radius_m, magnet_length=d.magnet.length_m,
                magnetization=d.magnet.magnetization_a_per_m)


def _core_body(geo, x, y, mu_r):
    zc = -geo["length"] / 2 + geo["core_offset"]
    return Cyl("core", x, y, zc - geo["core_length"] / 2, zc + geo["core_length"] / 2,
               geo["core_radius"], mu_r=mu_r)


def _winding_body(geo, x, y, current):
    j = geo["turns"] * current / ((geo["ro"] - geo["ri"]) * geo["length"])
    return Cyl("winding", x, y, -geo["length"], 0.0, geo["ro"], inner_radius=geo["ri"],
               current_density=j)


def workspace_points(n_side=4, heights=(0.010, 0.030, 0.050, 0.080), half_width=0.075):
    """A grid over the workspace (array frame): x, y in [-half_width, half_width] (n_side per
    axis), z at ``heights`` above the coils' top faces; (n, 3) m."""
    xs = np.linspace(-half_width, half_width, n_side)
    X, Y, Z = np.meshgrid(xs, xs, np.asarray(heights), indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])


def image_force_z(magnet_radius, magnet_length, magnetization, gap, mu_r, n=24):
    """Axial force on a magnet (axis vertical, M axial) whose bottom face is ``gap`` (m) above
    a linear half-space of ``mu_r`` (surface z = 0), N: the image method.

    The image is the mirrored magnet with magnetization k M, k = (mu_r - 1)/(mu_r + 1) (same
    direction: attraction); F = M [int_top B_img,z dA - int_bottom B_img,z dA] with the exact
    field of a magnetized cylinder (designkit.field.magnetized_cylinder_field). Independent of
    the FEM; the reference for :func:`magnet_block_force`."""
    k = (mu_r - 1.0) / (mu_r + 1.0)
    zc = gap + magnet_length / 2
    x, w = np.polynomial.legendre.leggauss(n)
    r = magnet_radius * 0.5 * (x + 1.0)
    wr = magnet_radius * 0.5 * w * 2 * math.pi * r
    out = 0.0
    for zf, sgn in ((zc + magnet_length / 2, 1.0), (zc - magnet_length / 2, -1.0)):
        p = np.column_stack([r, np.zeros(n), np.full(n, zf + zc)])  # relative to the image
        bz = magnetized_cylinder_field(p, magnet_radius, magnet_length, k * magnetization)[:, 2]
        out += sgn * float(np.sum(wr * bz))
    return magnetization * out


def magnet_block_force(gap=0.010, mu_r=1000.0, *, level=0, block_radius=0.10,
                       block_thickness=0.05, out_dir=None) -> dict:
    """FEM force of a large linear block (top face z = 0) on the thesis magnet whose bottom
    face is ``gap`` above it (quarter model); with the image-method reference. Returns
    {'fem_fz_n', 'image_fz_n', 'seconds', 'mesh'}."""
    geo = thesis_geometry()
    a, L, m = geo["magnet_radius"], geo["magnet_length"], geo["magnetization"]
    bodies = [Cyl("core", 0.0, 0.0, -block_thickness, 0.0, block_radius, mu_r=mu_r),
              Cyl("magnet", 0.0, 0.0, gap, gap + L, a, magnetization=m)]
    res = solve(bodies, np.array([[0.0, 0.0, gap + L + 0.01]]), symmetry="quarter",
                level=level, magnet_force=True, out_dir=out_dir,
                refine=[(0, 2 * a, 0, 2 * a, 0, gap + L + 0.005, 1.5e-3)])
    return {"fem_fz_n": float(res.extra["force_n"][2]),
            "image_fz_n": image_force_z(a, L, m, gap, mu_r),
            "seconds": res.solve_seconds + res.mesh_seconds, "mesh": res.mesh_stats}


WORKSPACE_BOX = (0.075, 0.005, 0.085)
"""Half-width in x and y, z_lo, z_hi of the refined workspace region (array frame), m."""


def _refine_workspace(symmetry, size):
    hw, z0, z1 = WORKSPACE_BOX
    x0 = 0.0 if symmetry == "quarter" else -hw
    y0 = 0.0 if symmetry in ("quarter", "half") else -hw
    return [(x0, hw, y0, hw, z0, z1, size)]


def single_core_case(points, *, mu_r=1000.0, current=1.0, level=0, out_dir=None):
    """One thesis coil (top face z = 0, axis through the origin) with its core, energized at
    ``current`` A; quarter model. Returns (B (n, 3) T, G (n, 3, 3) T/m, Fem3DResult).
    The 3-D counterpart of the axisymmetric model: its check."""
    geo = thesis_geometry()
    bodies = [_core_body(geo, 0.0, 0.0, mu_r), _winding_body(geo, 0.0, 0.0, current)]
    res = solve(bodies, points, symmetry="quarter", level=level, out_dir=out_dir,
                refine=_refine_workspace("quarter", 6e-3))
    return res.b, res.g, res


def two_cores_case(points, *, mu_r=1000.0, current=1.0, level=0, out_dir=None):
    """Two thesis coils with cores side by side at the design pitch: coil 0 at the origin
    energized at ``current`` A, coil 1 at (pitch, 0) unpowered (its winding is air, its core
    iron); half model (y >= 0). Returns (B (n, 3) T, G (n, 3, 3) T/m, Fem3DResult)."""
    geo = thesis_geometry()
    p = geo["pitch"]
    bodies = [_core_body(geo, 0.0, 0.0, mu_r), _core_body(geo, p, 0.0, mu_r),
              _winding_body(geo, 0.0, 0.0, current)]
    hw, z0, z1 = WORKSPACE_BOX
    res = solve(bodies, points, symmetry="half", level=level, out_dir=out_dir,
                refine=[(-0.04, p + 0.04, 0.0, 0.04, z0, z1, 6e-3)])
    return res.b, res.g, res


def array_case(points, *, energized="centre", mu_r=1000.0, current=1.0, level=0,
               out_dir=None, timeout_s=1800.0):
    """The default 3x3 array (``Design.coil_centres_m()``; every core iron, only one winding
    carrying ``current`` A): ``energized`` 'centre' (coil 4; quarter model) or 'corner'
    (coil 0; full model); ``timeout_s`` (s) bounds GetDP's run. Returns (B (n, 3) T,
    G (n, 3, 3) T/m, Fem3DResult), array frame (coil top faces in z = 0)."""
    if energized not in ("centre", "corner"):
        raise BadInputError("energized", "'centre' or 'corner'", energized)
    geo = thesis_geometry()
    centres = np.asarray(default_design().coil_centres_m(), dtype=float)
    k = 4 if energized == "centre" else 0
    bodies = [_core_body(geo, float(c[0]), float(c[1]), mu_r) for c in centres]
    bodies.append(_winding_body(geo, float(centres[k][0]), float(centres[k][1]), current))
    sym = "quarter" if energized == "centre" else "none"
    res = solve(bodies, points, symmetry=sym, level=level, out_dir=out_dir,
                refine=_refine_workspace(sym, 8e-3), body_size=4e-3, timeout_s=timeout_s)
    return res.b, res.g, res


def magnet_pull_case(heights=(0.020, 0.030, 0.050), *, mu_r=1000.0, level=0):
    """The magnet's pull on one thesis core (no current; the winding is air): the thesis
    magnet (axis vertical, M along +z) on the coil's axis with its CENTRE at each height (m)
    above the winding's top face; quarter model. Returns (heights (k,), Fz (k,) N) -- the
    force on the magnet (negative: pulled down)."""
    geo = thesis_geometry()
    a, L, m = geo["magnet_radius"], geo["magnet_length"], geo["magnetization"]
    out = []
    for h in heights:
        bodies = [_core_body(geo, 0.0, 0.0, mu_r),
                  Cyl("magnet", 0.0, 0.0, h - L / 2, h + L / 2, a, magnetization=m)]
        res = solve(bodies, np.array([[0.0, 0.0, h + L / 2 + 0.006]]), symmetry="quarter",
                    level=level, magnet_force=True,
                    refine=[(0, 2 * a, 0, 2 * a, 0.0, h + L / 2 + 0.005, 2e-3)])
        out.append(float(res.extra["force_n"][2]))
    return np.asarray(heights, dtype=float), np.array(out)
