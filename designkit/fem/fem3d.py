"""3-D GetDP reference for coupled cores: several iron cores, one energized winding, a magnet.

The independent check of the coupled-array model (issue 12): what the axisymmetric model
(:mod:`designkit.fem.runner`) cannot do -- cores side by side, the 3x3 array with one coil
energized, the finger magnet magnetizing a core -- solved by a 3-D finite-element model.

Formulation (GetDP, magnetostatics in the magnetic vector potential ``a``, Whitney edge
elements, 3-D): find a with n x a = 0 on the boundary such that

    (nu curl a, curl a')  -  (js, a')_winding  -  (nu br, curl a')_magnet  =  0,

* ``js`` the energized winding's uniform azimuthal current density (turns I / section area)
  imposed analytically about the winding's axis; unenergized windings are air (mu0) and are not
  meshed;
* the magnet is a rigid uniformly magnetized cylinder, br = mu0 M (mu_r = 1);
* linear cores, nu = 1 / (mu0 mu_r);
* a spanning-tree gauge (GetDP ``EdgesOfTreeIn``, grown from the constrained boundary) makes
  the system non-singular (the analytic js is divergence-free, so the source is compatible);
* the exterior: a spherical shell R_int..R_ext mapped to infinity by GetDP's ``VolSphShell``
  Jacobian (n x a = 0 at its outer surface is the condition at infinity);
* symmetry: ``'quarter'`` (x >= 0, y >= 0) or ``'half'`` (y >= 0) when every body is symmetric
  under those mirrors; on the cut planes B . n = 0 (n x a = 0), the right condition for
  axial coils and magnets whose axes lie in the planes. Results at points outside the
  modelled part are obtained by the mirror symmetry (B_x odd in x, B_y odd in y).

Outputs at points (``outputs='iron'``, the default when the sources are windings only): the
windings' field exactly (:func:`designkit.field.winding_field`) plus the field of the iron's
magnetization M = (1 - 1/mu_r) b / mu0, integrated over every core tetrahedron (b is linear in
each: the second-order face functions) with a conical product rule (:func:`iron_field`: point
dipoles, exact derivatives for grad B, the mirror images of the symmetric models added). The
output points need no mesh of their own and the FEM's element-wise noise in the air does not
reach B or grad B: only the iron's solution does. ``outputs='lines'`` (magnet cases): least-
squares cubic fits along three short lines (x, y, z) through each point
(:data:`FIT_HALF_WINDOW`), which average the element-wise jumps of the piecewise-linear B.

Accuracy (single thesis coil with its mu_r 1000 core, quarter model, against the axisymmetric
surface-current model, which agrees with the axisymmetric GetDP to < 0.5 % in B and dBz/dz;
20 points 12-80 mm above, beside and between; relative to |B| and ||grad B||_F at each point):
iron outputs, level -2 (~6k tetrahedra, ~1 s) B 0.67 %, grad B 0.78 %; level -1 (~15k) 0.30 /
0.39 %. Line fits: level -2 B 0.9 %, grad B 30 %; level 0 (~42k) 0.28 / 1.0 %. The 3 x 3 array
(centre coil, quarter model) changes by at most 0.6 % in B and 1.3 % in grad B from level 0
(~55k) to 1 (~147k) over a 5 x 5 x 5 grid 12-80 mm high (studies/fem3d_array.py).

Force on the magnet from the iron: F = integral over the magnet of (M . grad) B_ind dV with
B_ind = B(with cores) - B(cores replaced by air), both on the same mesh (so the magnet's own
discretized field cancels); for an axial, uniform M this is
F = M [ integral of B_ind over the top face - over the bottom face ] (exact), evaluated with
a Gauss rule on the two end faces. Checked against the image method (magnet above a large
high-mu_r block) in the tests.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..constants import MU0
from ..errors import BadInputError
from .mesh import gmsh_model, mesh_to_file
from .runner import find_getdp, run_getdp, work_folder

AIR, SHELL, MAGNET, BOUNDARY = 1, 2, 3, 4
CORE0, WIND0 = 100, 200
FIT_HALF_WINDOW = 5e-3
"""Half-length of the three fitting lines through every output point, m."""
FIT_SAMPLES = 33
FIT_DEGREE = 3
"""Degree of the least-squares polynomials along the fitting lines: a quadratic's slope carries
a cubic-term error ~ (window / field scale)^2, ~8 % at 15 mm above a core; quartic: < 0.5 %."""


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


def _mirror(points, symmetry):
    """Points folded into the modelled part and the sign matrices S (B -> S B, G -> S G S)."""
    p = np.array(points, dtype=float)
    s = np.ones((len(p), 3))
    if symmetry in ("quarter", "half"):
        s[:, 1] = np.where(p[:, 1] < 0, -1.0, 1.0)
        p[:, 1] = np.abs(p[:, 1])
    if symmetry == "quarter":
        s[:, 0] = np.where(p[:, 0] < 0, -1.0, 1.0)
        p[:, 0] = np.abs(p[:, 0])
    return p, s


def build_mesh(bodies, msh_path, *, symmetry="none", level=0, refine=(), r_int=0.25,
               r_ext=0.32, body_size=3.0e-3, far_size=25e-3, balls=(),
               point_size=2.0e-3) -> dict:
    """gmsh 3-D mesh of the bodies in a sphere + shell, cut to the symmetry part.

    ``refine``: list of (xmin, xmax, ymin, ymax, zmin, zmax, size) boxes (m); ``balls``:
    points (m) meshed at ``point_size`` within FIT_HALF_WINDOW + 2 mm (the fitting lines).
    Sizes shrink by sqrt(2) per ``level``. Returns mesh statistics."""
    s = 2.0 ** (-level / 2.0)
    with gmsh_model("designkit_fem3d") as gmsh:
        occ = gmsh.model.occ
        outer = occ.addSphere(0, 0, 0, r_ext)
        inner = occ.addSphere(0, 0, 0, r_int)
        vols = []
        for b in bodies:
            c = occ.addCylinder(b.x, b.y, b.z0, 0, 0, b.z1 - b.z0, b.radius)
            if b.inner_radius > 0:
                h = occ.addCylinder(b.x, b.y, b.z0, 0, 0, b.z1 - b.z0, b.inner_radius)
                c = occ.cut([(3, c)], [(3, h)])[0][0][1]
            vols.append(c)
        objs = [(3, outer), (3, inner)] + [(3, v) for v in vols]
        if symmetry != "none":
            x0 = 0.0 if symmetry == "quarter" else -r_ext * 1.1
            box = occ.addBox(x0, 0.0, -r_ext * 1.1, r_ext * 1.1 - x0, r_ext * 1.1,
                             2.2 * r_ext)
            cut = []
            for o in objs:
                res = occ.intersect([o], [(3, box)], removeObject=True, removeTool=False)[0]
                cut.append(res)
            occ.remove([(3, box)], recursive=True)
            objs = [c[0] if c else None for c in cut]
        out, out_map = occ.fragment([objs[0]], [o for o in objs[1:] if o is not None])
        occ.synchronize()
        # map: input index -> output volumes; later inputs own the overlaps (bodies inside)
        present = [o for o in objs if o is not None]
        owner = {}
        for idx, ents in enumerate(out_map):
            for d, t in ents:
                if d == 3:
                    owner[t] = idx  # the innermost (last) input wins
        groups = {AIR: [], SHELL: [], MAGNET: []}
        body_groups = {}
        for t, idx in owner.items():
            src = present[idx]
            k = objs.index(src)
            if k == 0:
                groups[SHELL].append(t)
            elif k == 1:
                groups[AIR].append(t)
            else:
                bi = k - 2
                b = bodies[bi]
                if b.kind == "magnet":
                    groups[MAGNET].append(t)
                else:
                    tag = (CORE0 if b.kind == "core" else WIND0) + bi
                    body_groups.setdefault(tag, []).append(t)
        for tag, ents in groups.items():
            if ents:
                gmsh.model.addPhysicalGroup(3, ents, tag)
        for tag, ents in body_groups.items():
            gmsh.model.addPhysicalGroup(3, ents, tag)
        bnd = []
        for _, t in gmsh.model.getEntities(2):
            x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, t)
            on_plane = (symmetry != "none" and abs(y0) < 1e-6 and abs(y1) < 1e-6) or \
                (symmetry == "quarter" and abs(x0) < 1e-6 and abs(x1) < 1e-6)
            far = max(abs(x0), abs(x1), abs(y0), abs(y1), abs(z0), abs(z1)) > 0.5 * (r_int
                                                                                    + r_ext)
            if on_plane or (far and _on_sphere(gmsh, t, r_ext)):
                bnd.append(t)
        gmsh.model.addPhysicalGroup(2, bnd, BOUNDARY)

        f = gmsh.model.mesh.field
        body_surfs = set()
        for ents in list(body_groups.values()) + [groups[MAGNET]]:
            for t in ents:
                for d, st in gmsh.model.getBoundary([(3, t)], oriented=False):
                    body_surfs.add(abs(st))
        surf = sorted(body_surfs)
        fields = []
        dist = f.add("Distance")
        f.setNumbers(dist, "SurfacesList", surf)
        f.setNumber(dist, "Sampling", 40)
        thr = f.add("Threshold")
        f.setNumber(thr, "InField", dist)
        f.setNumber(thr, "SizeMin", body_size * s)
        f.setNumber(thr, "SizeMax", far_size * s)
        f.setNumber(thr, "DistMin", 2e-3)
        f.setNumber(thr, "DistMax", 0.1)
        fields.append(thr)
        for (xa, xb, ya, yb, za, zb, h) in refine:
            bx = f.add("Box")
            f.setNumber(bx, "VIn", h * s)
            f.setNumber(bx, "VOut", far_size * s)
            for k, v in zip(("XMin", "XMax", "YMin", "YMax", "ZMin", "ZMax"),
                            (xa, xb, ya, yb, za, zb)):
                f.setNumber(bx, k, v)
            f.setNumber(bx, "Thickness", 0.03)
            fields.append(bx)
        for c in balls:
            bl = f.add("Ball")
            f.setNumber(bl, "Radius", FIT_HALF_WINDOW + 2e-3)
            f.setNumber(bl, "Thickness", 4e-3)
            f.setNumber(bl, "VIn", point_size * s)
            f.setNumber(bl, "VOut", far_size * s)
            for k, v in zip(("XCenter", "YCenter", "ZCenter"), c):
                f.setNumber(bl, k, float(v))
            fields.append(bl)
        mesh_to_file(gmsh, fields, 3, msh_path)
        nodes = len(gmsh.model.mesh.getNodes()[0])
        _, et, _ = gmsh.model.mesh.getElements(3)
        ntet = int(sum(len(t) for t in et))
        return {"nodes": nodes, "tetrahedra": ntet, "cores": sorted(body_groups),
                "magnet": bool(groups[MAGNET])}


def _on_sphere(gmsh, tag, r):
    x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, tag)
    return max(abs(x0), abs(x1), abs(y0), abs(y1), abs(z0), abs(z1)) > 0.9 * r


def problem_text(bodies, stats, *, mu_scale=1.0, r_int=0.25, r_ext=0.32,
                 lines=(), plane_points=(), core_table=False) -> str:
    """The .pro file. ``mu_scale`` 0 replaces every core by air (for B_ind = B - B_alone)."""
    cores = [t for t in stats["cores"] if t < WIND0]
    winds = [t for t in stats["cores"] if t >= WIND0]
    has_mag = stats["magnet"]
    L = []
    L.append("Group {")
    L.append(f"  Air = Region[{{{AIR}}}]; Shell = Region[{{{SHELL}}}];")
    L.append(f"  Bnd = Region[{{{BOUNDARY}}}];")
    for t in cores + winds:
        L.append(f"  B{t} = Region[{{{t}}}];")
    L.append(f"  Cores = Region[{{{', '.join(str(t) for t in cores)}}}];")
    L.append(f"  Winds = Region[{{{', '.join(str(t) for t in winds)}}}];")
    L.append(f"  Mag = Region[{{{MAGNET if has_mag else ''}}}];")
    L.append("  Domain = Region[{Air, Shell, Cores, Winds, Mag}];")
    L.append("}")
    L.append("Function {")
    L.append("  mu0 = 4.e-7 * Pi;")
    L.append("  nu[Region[{Air, Shell, Winds, Mag}]] = 1. / mu0;")
    for t in cores:
        b = bodies[t - CORE0]
        mu = 1.0 + (b.mu_r - 1.0) * mu_scale
        L.append(f"  nu[B{t}] = 1. / (mu0 * {mu!r});")
    for t in winds:
        b = bodies[t - WIND0]
        L.append(f"  js[B{t}] = {b.current_density!r} * Vector[-(Y[] - {b.y!r}), X[] - {b.x!r}, 0]"
                 f" / Sqrt[(X[] - {b.x!r})^2 + (Y[] - {b.y!r})^2];")
    if has_mag:
        mb = [b for b in bodies if b.kind == "magnet"][0]
        L.append(f"  br[Mag] = Vector[0, 0, mu0 * {mb.magnetization!r}];")
    L.append("}")
    L.append("Constraint {")
    L.append("  { Name a_bc; Case { { Region Bnd; Value 0.; } } }")
    L.append("  { Name Gauge; Type Assign; Case { { Region Domain; SubRegion Bnd; Value 0.; } } }")
    L.append("}")
    L.append("Jacobian { { Name Vol; Case {")
    L.append(f"  {{ Region Shell; Jacobian VolSphShell{{{r_int!r}, {r_ext!r}}}; }}")
    L.append("  { Region All; Jacobian Vol; } } } }")
    L.append("Integration { { Name I1; Case { { Type Gauss; Case {")
    L.append("  { GeoElement Tetrahedron; NumberOfPoints 4; }")
    L.append("  { GeoElement Triangle; NumberOfPoints 3; } } } } } }")
    L.append("FunctionSpace { { Name Hcurl_a; Type Form1;")
    L.append("  BasisFunction { { Name se; NameOfCoef ae; Function BF_Edge; Support Domain;"
             " Entity EdgesOf[All]; }")
    # second-order rotational (face) functions: curl a, so B, linear in each tetrahedron;
    # the gradient-type second-order functions (BF_Edge_2E) are left out, so the tree gauge
    # on the Whitney functions is the whole gauge
    L.append("    { Name s3a; NameOfCoef a3a; Function BF_Edge_3F_a; Support Domain;"
             " Entity FacetsOf[All]; }")
    L.append("    { Name s3b; NameOfCoef a3b; Function BF_Edge_3F_b; Support Domain;"
             " Entity FacetsOf[All]; } }")
    L.append("  Constraint { { NameOfCoef ae; EntityType EdgesOf; NameOfConstraint a_bc; }")
    L.append("    { NameOfCoef a3a; EntityType FacetsOf; NameOfConstraint a_bc; }")
    L.append("    { NameOfCoef a3b; EntityType FacetsOf; NameOfConstraint a_bc; }")
    L.append("    { NameOfCoef ae; EntityType EdgesOfTreeIn; EntitySubType StartingOn;"
             " NameOfConstraint Gauge; } } } }")
    L.append("Formulation { { Name MagSta; Type FemEquation;")
    L.append("  Quantity { { Name a; Type Local; NameOfSpace Hcurl_a; } }")
    L.append("  Equation {")
    L.append("    Galerkin { [ nu[] * Dof{d a}, {d a} ]; In Domain; Jacobian Vol;"
             " Integration I1; }")
    if winds:
        L.append("    Galerkin { [ -js[], {a} ]; In Winds; Jacobian Vol; Integration I1; }")
    if has_mag:
        L.append("    Galerkin { [ -nu[] * br[], {d a} ]; In Mag; Jacobian Vol; Integration I1; }")
    L.append("  } } }")
    L.append("Resolution { { Name MagSta; System { { Name A; NameOfFormulation MagSta; } }")
    L.append("  Operation { Generate[A]; Solve[A]; SaveSolution[A]; } } }")
    L.append("PostProcessing { { Name MagSta; NameOfFormulation MagSta; Quantity {")
    L.append("  { Name b; Value { Local { [ {d a} ]; In Domain; Jacobian Vol; } } } } } }")
    L.append("PostOperation { { Name Post; NameOfPostProcessing MagSta; Operation {")
    for (p0, p1, n, name) in lines:
        p0, p1 = [float(v) for v in p0], [float(v) for v in p1]
        L.append(f"  Print[ b, OnLine {{{{{p0[0]!r}, {p0[1]!r}, {p0[2]!r}}}"
                 f"{{{p1[0]!r}, {p1[1]!r}, {p1[2]!r}}}}} {{{n}}}, Format SimpleTable,"
                 f" File \"{name}\" ];")
    if core_table:
        for t in cores:
            L.append(f'  Print[ b, OnElementsOf B{t}, Format SimpleTable, File "bcore_{t}.txt" ];')
    for (pts, name) in plane_points:
        for k, q in enumerate(pts):
            q = [float(v) for v in q]
            L.append(f"  Print[ b, OnPoint {{{q[0]!r}, {q[1]!r}, {q[2]!r}}}, Format SimpleTable,"
                     f" File {'>' if k else ''} \"{name}\" ];")
    L.append("} } }")
    return "\n".join(L) + "\n"


def _fit_lines(work, names, centres, mirror_axes=()):
    """B (n,3) and G (n,3,3) from least-squares polynomials along the x, y, z lines.

    A line along a mirror axis (x = 0 or y = 0 plane of the symmetric model) that would cross
    the plane is sampled on the modelled side only and completed by the mirror image
    (B_j odd, the other components even in x_j), so the window stays centred."""
    n = len(centres)
    b = np.zeros((n, 3))
    g = np.zeros((n, 3, 3))
    for i in range(n):
        for j in range(3):
            d = np.loadtxt(work / names[i][j], ndmin=2)
            u, vals = d[:, j], d[:, 3:6]
            if j in mirror_axes and centres[i, j] - FIT_HALF_WINDOW < 0:
                pos = u > 1e-12
                mv = vals[pos].copy()
                mv[:, j] *= -1.0
                u = np.concatenate([u, -u[pos]])
                vals = np.vstack([vals, mv])
            sel = np.abs(u - centres[i, j]) <= FIT_HALF_WINDOW * (1 + 1e-9)
            t = (u[sel] - centres[i, j]) / FIT_HALF_WINDOW
            for c in range(3):
                coef = np.polynomial.polynomial.polyfit(t, vals[sel, c], FIT_DEGREE)
                b[i, c] += coef[0] / 3.0
                g[i, c, j] = coef[1] / FIT_HALF_WINDOW
    return b, g


def solve(bodies, points, *, symmetry="none", level=0, refine=(), out_dir=None,
          magnet_force=False, face_nodes=4, timeout_s=1800.0, body_size=3.0e-3,
          point_size=2.0e-3, outputs=None) -> Fem3DResult:
    """Solve one 3-D model and return B, grad B at ``points`` (and the force on the magnet).

    Parameters
    ----------
    bodies : list of :class:`Cyl`
    points : ndarray (n, 3), m
        Output points (outside the bodies, >= FIT_HALF_WINDOW from any body surface).
    symmetry : {'none', 'half', 'quarter'}
        Model only y >= 0 ('half') or x, y >= 0 ('quarter'); the bodies must be symmetric.
    level : int
        Mesh refinement level; sizes shrink by sqrt(2) per level.
    refine : list of (xmin, xmax, ymin, ymax, zmin, zmax, size) boxes, m
    magnet_force : bool
        Also solve with the cores replaced by air on the same mesh and return
        ``extra['force_n']`` (3,) N: the force of the magnetized iron on the magnet.
    outputs : {'iron', 'lines'} or None
        How B and grad B at the points are obtained (module docstring): 'iron' (exact windings
        + the cores' magnetization; only without a magnet) or 'lines' (fits of the FEM's B);
        None: 'iron' when there is no magnet.

    Returns
    -------
    Fem3DResult
    """
    exe = find_getdp()
    if symmetry not in ("none", "half", "quarter"):
        raise BadInputError("symmetry", "'none', 'half' or 'quarter'", symmetry)
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    if pts.ndim != 2 or pts.shape[1] != 3 or not np.all(np.isfinite(pts)):
        raise BadInputError("points", "finite array of shape (n, 3), m", pts.shape)
    has_magnet = any(b.kind == "magnet" for b in bodies)
    outputs = ("lines" if has_magnet else "iron") if outputs is None else outputs
    if outputs not in ("iron", "lines") or (outputs == "iron" and has_magnet):
        raise BadInputError("outputs", "'lines', or 'iron' when no body is a magnet", outputs)
    folded_all, signs = _mirror(pts, symmetry)
    # points that fold onto the same modelled point are solved for once
    folded, inverse = np.unique(np.round(folded_all, 12), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    with work_folder(out_dir, "designkit_fem3d_") as work:
        t0 = time.perf_counter()
        msh = work / "model.msh"
        stats = build_mesh(bodies, msh, symmetry=symmetry, level=level, refine=refine,
                           body_size=body_size, balls=folded if outputs == "lines" else (),
                           point_size=point_size)
        t_mesh = time.perf_counter() - t0
        mirror_axes = {"none": (), "half": (1,), "quarter": (0, 1)}[symmetry]
        lines, names = [], []
        for i, c in enumerate(folded if outputs == "lines" else ()):
            row = []
            for j in range(3):
                e = np.zeros(3)
                e[j] = FIT_HALF_WINDOW
                p0, p1 = c - e, c + e
                if j in mirror_axes:
                    p0[j] = max(p0[j], 0.0)  # the rest comes from the mirror image
                name = f"l{i}_{j}.txt"
                lines.append((p0, p1, FIT_SAMPLES - 1, name))
                row.append(name)
            names.append(row)
        plane = []
        mag = [b for b in bodies if b.kind == "magnet"]
        if magnet_force:
            if len(mag) != 1:
                raise BadInputError("bodies", "exactly one magnet for magnet_force", len(mag))
            fq = _face_rule(mag[0], face_nodes, symmetry)
            plane = [(fq[0], "face_top.txt"), (fq[1], "face_bot.txt")]
        t_solve = run_getdp(exe, work, problem_text(bodies, stats, lines=lines,
                                                    plane_points=plane,
                                                    core_table=outputs == "iron"),
                            msh, timeout_s)[1]
        if outputs == "iron":  # the whole iron (mirror images included) at the points
            b, g = iron_field(work, stats, bodies, pts, symmetry)
        else:
            b, g = _fit_lines(work, names, folded, mirror_axes)
            b = b[inverse] * signs
            g = g[inverse] * signs[:, :, None] * signs[:, None, :]
        extra = {}
        if magnet_force:
            top = np.loadtxt(work / "face_top.txt", ndmin=2)[:, -3:]
            bot = np.loadtxt(work / "face_bot.txt", ndmin=2)[:, -3:]
            t_solve += run_getdp(exe, work, problem_text(bodies, stats, mu_scale=0.0, lines=[],
                                                         plane_points=plane), msh, timeout_s)[1]
            top0 = np.loadtxt(work / "face_top.txt", ndmin=2)[:, -3:]
            bot0 = np.loadtxt(work / "face_bot.txt", ndmin=2)[:, -3:]
            w = fq[2]
            fz = mag[0].magnetization * (np.sum(w * (top[:, 2] - top0[:, 2]))
                                         - np.sum(w * (bot[:, 2] - bot0[:, 2])))
            fx = mag[0].magnetization * (np.sum(w * (top[:, 0] - top0[:, 0]))
                                         - np.sum(w * (bot[:, 0] - bot0[:, 0])))
            fy = mag[0].magnetization * (np.sum(w * (top[:, 1] - top0[:, 1]))
                                         - np.sum(w * (bot[:, 1] - bot0[:, 1])))
            if symmetry == "quarter":
                fx = fy = 0.0  # on the symmetry axis by construction
            elif symmetry == "half":
                fy = 0.0
            extra["force_n"] = np.array([fx, fy, fz])
        return Fem3DResult(pts, b, g, stats, t_solve, t_mesh, extra)


def conical_rule(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Stroud's conical product rule on a tetrahedron: barycentric coordinates (n^3, 4) and
    weights (n^3,) summing to 1 (fractions of the volume); exact for polynomials of degree
    2 n - 1 (Gauss-Jacobi nodes in the collapsed coordinates)."""
    from scipy.special import roots_jacobi

    u, wu = roots_jacobi(n, 2, 0)  # weight (1 - u)^2 of the collapsed coordinate
    v, wv = roots_jacobi(n, 1, 0)
    w, ww = roots_jacobi(n, 0, 0)
    u, v, w = (u + 1) / 2, (v + 1) / 2, (w + 1) / 2
    U, V, W = np.meshgrid(u, v, w, indexing="ij")
    x, y, z = U.ravel(), ((1 - U) * V).ravel(), ((1 - U) * (1 - V) * W).ravel()
    wt = (wu[:, None, None] / 8 * wv[None, :, None] / 4 * ww[None, None, :] / 2).ravel() * 6.0
    return np.column_stack([1 - x - y - z, x, y, z]), wt


def core_dipoles(xyz: np.ndarray, b: np.ndarray, mu_r: float, symmetry: str = "none",
                 n: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Point dipoles equivalent to a linear core's FEM solution.

    xyz (e, 4, 3) m: the tetrahedra's vertices; b (e, 4, 3) T: the FEM's b at them (linear in
    each tetrahedron); M = (1 - 1/mu_r) b / mu0. Returns positions (k, 3) m and moments (k, 3)
    A m^2 (the :func:`conical_rule` nodes, weights times volume), with the mirror images of
    the symmetric models (``'half'``: y -> -y, ``'quarter'``: also x -> -x; the mirrored
    moment's component along the mirror axis flips, as B's does)."""
    bary, wt = conical_rule(n)
    e1, e2, e3 = (xyz[:, k] - xyz[:, 0] for k in (1, 2, 3))
    vol = np.abs(np.einsum("ei,ei->e", np.cross(e1, e2), e3)) / 6.0
    m_vert = b * ((1.0 - 1.0 / mu_r) / MU0)
    pos = np.einsum("qk,ekj->eqj", bary, xyz).reshape(-1, 3)
    mom = (np.einsum("qk,ekj->eqj", bary, m_vert)
           * (vol[:, None] * wt[None, :])[:, :, None]).reshape(-1, 3)
    for ax in {"none": (), "half": (1,), "quarter": (1, 0)}[symmetry]:
        flip = np.ones(3)
        flip[ax] = -1.0
        pos = np.vstack([pos, pos * flip])
        mom = np.vstack([mom, mom * flip])
    return pos, mom


def dipoles_field(points: np.ndarray, pos: np.ndarray, mom: np.ndarray,
                  chunk: int = 65536) -> tuple[np.ndarray, np.ndarray]:
    """B (n, 3) T and G (n, 3, 3) T/m (G[i, j] = dB_i/dx_j) of point dipoles ``mom`` (k, 3)
    A m^2 at ``pos`` (k, 3) m, at points (n, 3) m away from them."""
    c = MU0 / (4.0 * math.pi)
    b = np.zeros((len(points), 3))
    g = np.zeros((len(points), 3, 3))
    for i, p in enumerate(points):
        for a in range(0, len(pos), chunk):
            r = p - pos[a:a + chunk]
            m = mom[a:a + chunk]
            r2 = np.einsum("ij,ij->i", r, r)
            ir3 = r2 ** -1.5
            ir5 = ir3 / r2
            mr = np.einsum("ij,ij->i", m, r)
            b[i] += c * (3.0 * (mr * ir5) @ r - ir3 @ m)
            rm = (r * ir5[:, None]).T @ m  # sum r_i m_j / r^5
            g[i] += c * (3.0 * (rm + rm.T + np.eye(3) * np.sum(mr * ir5))
                         - 15.0 * (r * (mr * ir5 / r2)[:, None]).T @ r)
    return b, g


def iron_field(work, stats, bodies, points, symmetry):
    """B (n, 3) T, G (n, 3, 3) T/m at points: the windings' exact field plus the cores' (from
    the ``bcore_<tag>.txt`` tables :func:`problem_text` prints with ``core_table``)."""
    from ..field import winding_field

    b = np.zeros((len(points), 3))
    g = np.zeros((len(points), 3, 3))
    for t in stats["cores"]:
        body = bodies[t - (WIND0 if t >= WIND0 else CORE0)]
        if t >= WIND0:
            loc = points - np.array([body.x, body.y, 0.5 * (body.z0 + body.z1)])
            length = body.z1 - body.z0
            amp_turns = body.current_density * (body.radius - body.inner_radius) * length
            bw, gw = winding_field(loc, body.inner_radius, body.radius, length, 1.0,
                                   amp_turns, gradient=True)
            b += bw
            g += gw
        else:
            d = np.loadtxt(work / f"bcore_{t}.txt", ndmin=2)
            pos, mom = core_dipoles(d[:, :12].reshape(-1, 4, 3), d[:, 12:24].reshape(-1, 4, 3),
                                    body.mu_r, symmetry)
            bc, gc = dipoles_field(points, pos, mom)
            b += bc
            g += gc
    return b, g


def _face_rule(mag, n, symmetry):
    """Gauss points (just inside) on the magnet's top and bottom faces and area weights.

    With symmetry the points cover the modelled part and the weights the whole face (the
    integrand's mirror images carry the same z component)."""
    xr, wr = np.polynomial.legendre.leggauss(n)
    r = mag.radius * np.sqrt(0.5 * (xr + 1.0))  # area coordinate
    wr = 0.5 * wr * math.pi * mag.radius ** 2
    nphi = 2 * n
    if symmetry == "quarter":
        phi = (np.arange(nphi) + 0.5) * (0.5 * math.pi) / nphi
    elif symmetry == "half":
        phi = (np.arange(nphi) + 0.5) * math.pi / nphi
    else:
        phi = (np.arange(nphi) + 0.5) * 2 * math.pi / nphi
    R, P = np.meshgrid(r, phi, indexing="ij")
    W = np.repeat(wr[:, None], nphi, axis=1) / nphi
    eps = 1e-4 * (mag.z1 - mag.z0)
    x = mag.x + (R * np.cos(P)).ravel()
    y = mag.y + (R * np.sin(P)).ravel()
    top = np.column_stack([x, y, np.full(x.size, mag.z1 - eps)])
    bot = np.column_stack([x, y, np.full(x.size, mag.z0 + eps)])
    return top, bot, W.ravel()


# ====================================================================== cases
def thesis_geometry():
    """(ri, ro, length, turns, core_radius, core_length, pitch, magnet) of the default design,
    SI; the winding's top face at z = 0 (array frame), cores centred on their windings."""
    from ..design import default_design

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
    from ..field import magnetized_cylinder_field

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
    from ..design import default_design

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
