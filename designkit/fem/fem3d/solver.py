"""Solve one 3-D model with GetDP and return B and grad B at points (and the magnet's force).

mesh (:mod:`.mesh`) -> .pro (:mod:`.problem`) -> getdp -> outputs: the iron's magnetization
(:mod:`.iron`, windings-only models) or line fits (:mod:`.lines`, models with a magnet);
with ``magnet_force`` a second run with the cores as air gives the force (:mod:`.force`).
Points in m, B in T, G in T/m (G[i, j] = dB_i/dx_j); the formulation is in docs/fem.md.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from ...errors import BadInputError
from ..runner import find_getdp, run_getdp, work_folder
from .bodies import MIRROR_AXES, mirror
from .force import face_rule, force_on_magnet, read_faces
from .iron import iron_field
from .lines import fit_lines, line_specs
from .mesh import MeshSettings, build_mesh
from .problem import problem_text


@dataclass
class Fem3DResult:
    """B (n, 3) T and G (n, 3, 3) T/m (G[i, j] = dB_i/dx_j) at the requested points."""

    points: np.ndarray
    b: np.ndarray
    g: np.ndarray
    mesh_stats: dict
    solve_seconds: float
    mesh_seconds: float
    extra: dict = field(default_factory=dict)


def _checked(bodies, points, symmetry, outputs):
    """Validate; return (points (n, 3), the outputs mode)."""
    if symmetry not in ("none", "half", "quarter"):
        raise BadInputError("symmetry", "'none', 'half' or 'quarter'", symmetry)
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
        raise BadInputError("points", "finite array of shape (n, 3), m", pts.shape)
    has_magnet = any(b.kind == "magnet" for b in bodies)
    if any(b.kind == "magnet" and not b.vertical for b in bodies):
        raise BadInputError("bodies", "a magnet with a vertical axis (the face rule of the "
                            "force integral)", [b.axis for b in bodies if b.kind == "magnet"])
    outputs = ("lines" if has_magnet else "iron") if outputs is None else outputs
    if outputs not in ("iron", "lines") or (outputs == "iron" and has_magnet):
        raise BadInputError("outputs", "'lines', or 'iron' when no body is a magnet", outputs)
    return pts, outputs


@dataclass(frozen=True)
class Fem3DSettings:
    """How :func:`solve` models, meshes and samples a 3-D model (SI).

    symmetry : {'none', 'half', 'quarter'}
        Model only y >= 0 ('half') or x, y >= 0 ('quarter'); the bodies must be symmetric.
    level : int
        Mesh refinement level; sizes shrink by sqrt(2) per level.
    refine : list of (xmin, xmax, ymin, ymax, zmin, zmax, size) boxes, m
    out_dir : path or None
        Where GetDP's files stay; None: a temporary folder.
    magnet_force : bool
        Also solve with the cores replaced by air on the same mesh and return
        ``extra['force_n']`` (3,) N: the force of the magnetized iron on the magnet
        (``face_nodes`` Gauss nodes on its end faces).
    timeout_s : float
        GetDP's wall-clock limit per run, s.
    body_size, point_size : float, m
        Element sizes at the bodies and around the fitting lines (level 0).
    outputs : {'iron', 'lines'} or None
        How B and grad B at the points are obtained (docs/fem.md): 'iron' (exact windings
        + the cores' magnetization; only without a magnet) or 'lines' (fits of the FEM's B);
        None: 'iron' when there is no magnet.
    """

    symmetry: str = "none"
    level: int = 0
    refine: tuple = ()
    out_dir: object = None
    magnet_force: bool = False
    face_nodes: int = 4
    timeout_s: float = 1800.0
    body_size: float = 3.0e-3
    point_size: float = 2.0e-3
    outputs: str | None = None


def solve(bodies, points, settings: Fem3DSettings | None = None, **changes) -> Fem3DResult:
    """Solve one 3-D model and return B, grad B at ``points`` (n, 3) m (outside the bodies,
    >= FIT_HALF_WINDOW from any body surface) and the force on the magnet; ``bodies``: list
    of :class:`Cyl`; ``settings`` (:class:`Fem3DSettings`; None: its defaults), ``changes``:
    fields of it to replace (``solve(bodies, pts, symmetry='half')``)."""
    names = {f.name for f in dataclasses.fields(Fem3DSettings)}
    for key in changes:
        if key not in names:
            raise BadInputError("3-D FEM setting", f"one of {sorted(names)}", key)
    st = dataclasses.replace(settings or Fem3DSettings(), **changes)
    symmetry, level, refine, out_dir = st.symmetry, st.level, st.refine, st.out_dir
    magnet_force, face_nodes, timeout_s, outputs = (st.magnet_force, st.face_nodes,
                                                    st.timeout_s, st.outputs)
    exe = find_getdp()
    pts, outputs = _checked(bodies, points, symmetry, outputs)
    folded_all, signs = mirror(pts, symmetry)
    # points that fold onto the same modelled point are solved for once
    folded, inverse = np.unique(np.round(folded_all, 12), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    with work_folder(out_dir, "designkit_fem3d_") as work:
        t0 = time.perf_counter()
        msh = work / "model.msh"
        stats = build_mesh(bodies, msh, MeshSettings(
            symmetry=symmetry, level=level, refine=tuple(refine), body_size=st.body_size,
            balls=folded if outputs == "lines" else (), point_size=st.point_size))
        t_mesh = time.perf_counter() - t0
        mirror_axes = MIRROR_AXES[symmetry]
        lines, names = line_specs(folded if outputs == "lines" else (), mirror_axes)
        plane = []
        mag = [b for b in bodies if b.kind == "magnet"]
        if magnet_force:
            if len(mag) != 1:
                raise BadInputError("bodies", "exactly one magnet for magnet_force", len(mag))
            fq = face_rule(mag[0], face_nodes, symmetry)
            plane = [(fq[0], "face_top.txt"), (fq[1], "face_bot.txt")]
        t_solve = run_getdp(exe, work, problem_text(bodies, stats, lines=lines,
                                                    plane_points=plane,
                                                    core_table=outputs == "iron"),
                            msh, timeout_s)[1]
        if outputs == "iron":  # the whole iron (mirror images included) at the points
            b, g = iron_field(work, stats, bodies, pts, symmetry)
        else:
            b, g = fit_lines(work, names, folded, mirror_axes)
            b = b[inverse] * signs
            g = g[inverse] * signs[:, :, None] * signs[:, None, :]
        extra = {}
        if magnet_force:
            with_iron = read_faces(work)
            t_solve += run_getdp(exe, work, problem_text(bodies, stats, mu_scale=0.0, lines=[],
                                                         plane_points=plane), msh, timeout_s)[1]
            extra["force_n"] = force_on_magnet(mag[0].magnetization, fq[2], with_iron,
                                               read_faces(work), symmetry)
        return Fem3DResult(pts, b, g, stats, t_solve, t_mesh, extra)

