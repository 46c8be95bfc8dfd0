"""GetDP problem text of a 3-D model: magnetostatics in the vector potential a (docs/fem.md).

Whitney edge functions plus the second-order rotational face functions (B linear in each
tetrahedron), a spanning-tree gauge, GetDP's ``VolSphShell`` Jacobian on the shell, linear
cores (nu = 1 / (mu0 mu_r)), the analytic azimuthal current density of the energized winding
and the rigid magnetization of the magnet (br = mu0 M). Region tags from :mod:`.bodies`.
"""

from __future__ import annotations

from .bodies import AIR, BOUNDARY, CORE0, MAGNET, SHELL, WIND0

# second-order rotational (face) functions: curl a, so B, linear in each tetrahedron;
# the gradient-type second-order functions (BF_Edge_2E) are left out, so the tree gauge
# on the Whitney functions is the whole gauge
_INTEGRATION_AND_SPACE = [
    "Integration { { Name I1; Case { { Type Gauss; Case {",
    "  { GeoElement Tetrahedron; NumberOfPoints 4; }",
    "  { GeoElement Triangle; NumberOfPoints 3; } } } } } }",
    "FunctionSpace { { Name Hcurl_a; Type Form1;",
    "  BasisFunction { { Name se; NameOfCoef ae; Function BF_Edge; Support Domain;"
    " Entity EdgesOf[All]; }",
    "    { Name s3a; NameOfCoef a3a; Function BF_Edge_3F_a; Support Domain;"
    " Entity FacetsOf[All]; }",
    "    { Name s3b; NameOfCoef a3b; Function BF_Edge_3F_b; Support Domain;"
    " Entity FacetsOf[All]; } }",
    "  Constraint { { NameOfCoef ae; EntityType EdgesOf; NameOfConstraint a_bc; }",
    "    { NameOfCoef a3a; EntityType FacetsOf; NameOfConstraint a_bc; }",
    "    { NameOfCoef a3b; EntityType FacetsOf; NameOfConstraint a_bc; }",
    "    { NameOfCoef ae; EntityType EdgesOfTreeIn; EntitySubType StartingOn;"
    " NameOfConstraint Gauge; } } } }",
]

_RESOLUTION_AND_POST = [
    "Resolution { { Name MagSta; System { { Name A; NameOfFormulation MagSta; } }",
    "  Operation { Generate[A]; Solve[A]; SaveSolution[A]; } } }",
    "PostProcessing { { Name MagSta; NameOfFormulation MagSta; Quantity {",
    "  { Name b; Value { Local { [ {d a} ]; In Domain; Jacobian Vol; } } } } } }",
]


def _groups(cores, winds, has_mag):
    L = ["Group {",
         f"  Air = Region[{{{AIR}}}]; Shell = Region[{{{SHELL}}}];",
         f"  Bnd = Region[{{{BOUNDARY}}}];"]
    for t in cores + winds:
        L.append(f"  B{t} = Region[{{{t}}}];")
    L.append(f"  Cores = Region[{{{', '.join(str(t) for t in cores)}}}];")
    L.append(f"  Winds = Region[{{{', '.join(str(t) for t in winds)}}}];")
    L.append(f"  Mag = Region[{{{MAGNET if has_mag else ''}}}];")
    L.append("  Domain = Region[{Air, Shell, Cores, Winds, Mag}];")
    L.append("}")
    return L


def _functions(bodies, cores, winds, has_mag, mu_scale):
    """nu per region (cores scaled by ``mu_scale``), js of the windings, br of the magnet."""
    L = ["Function {", "  mu0 = 4.e-7 * Pi;", "  nu[Region[{Air, Shell, Winds, Mag}]] = 1. / mu0;"]
    for t in cores:
        b = bodies[t - CORE0]
        mu = 1.0 + (b.mu_r - 1.0) * mu_scale
        L.append(f"  nu[B{t}] = 1. / (mu0 * {mu!r});")
    for t in winds:
        b = bodies[t - WIND0]
        L.append(f"  js[B{t}] = {b.current_density!r} * {_azimuthal(b)};")
    if has_mag:
        mb = [b for b in bodies if b.kind == "magnet"][0]
        ax, ay, az = (f"mu0 * {mb.magnetization * q!r}" for q in mb.axis)
        L.append(f"  br[Mag] = Vector[{ax}, {ay}, {az}];")
    L.append("}")
    return L


def _azimuthal(b) -> str:
    """GetDP expression of the unit azimuthal direction about body ``b``'s axis, a x (r - o) /
    |a x (r - o)| (o a point of the axis; counter-clockwise seen from the tip of a)."""
    if b.vertical:
        return (f"Vector[-(Y[] - {b.y!r}), X[] - {b.x!r}, 0]"
                f" / Sqrt[(X[] - {b.x!r})^2 + (Y[] - {b.y!r})^2]")
    (ax, ay, az), (ox, oy, oz) = (float(q) for q in b.axis), (float(q) for q in b.origin)
    dx, dy, dz = f"(X[] - {ox!r})", f"(Y[] - {oy!r})", f"(Z[] - {oz!r})"
    cx = f"({ay!r} * {dz} - {az!r} * {dy})"
    cy = f"({az!r} * {dx} - {ax!r} * {dz})"
    cz = f"({ax!r} * {dy} - {ay!r} * {dx})"
    return f"Vector[{cx}, {cy}, {cz}] / Sqrt[{cx}^2 + {cy}^2 + {cz}^2]"


def _constraints_and_jacobian(r_int, r_ext):
    return ["Constraint {",
            "  { Name a_bc; Case { { Region Bnd; Value 0.; } } }",
            "  { Name Gauge; Type Assign; Case { { Region Domain; SubRegion Bnd; Value 0.; } } }",
            "}",
            "Jacobian { { Name Vol; Case {",
            f"  {{ Region Shell; Jacobian VolSphShell{{{r_int!r}, {r_ext!r}}}; }}",
            "  { Region All; Jacobian Vol; } } } }"]


def _formulation(winds, has_mag):
    L = ["Formulation { { Name MagSta; Type FemEquation;",
         "  Quantity { { Name a; Type Local; NameOfSpace Hcurl_a; } }",
         "  Equation {",
         "    Galerkin { [ nu[] * Dof{d a}, {d a} ]; In Domain; Jacobian Vol;"
         " Integration I1; }"]
    if winds:
        L.append("    Galerkin { [ -js[], {a} ]; In Winds; Jacobian Vol; Integration I1; }")
    if has_mag:
        L.append("    Galerkin { [ -nu[] * br[], {d a} ]; In Mag; Jacobian Vol; Integration I1; }")
    L.append("  } } }")
    return L


def _post_operation(lines, plane_points, core_table, cores):
    """Prints of b: along ``lines``, on every core element (``core_table``), at points."""
    L = ["PostOperation { { Name Post; NameOfPostProcessing MagSta; Operation {"]
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
    return L


def problem_text(bodies, stats, *, mu_scale=1.0, r_int=0.25, r_ext=0.32,
                 lines=(), plane_points=(), core_table=False) -> str:
    """The .pro file. ``mu_scale`` 0 replaces every core by air (for B_ind = B - B_alone).

    ``stats`` is :func:`build_mesh`'s (its region tags); ``lines``: (p0, p1, n, file) segments
    (m) printed at n + 1 points; ``plane_points``: (points (k, 3) m, file) printed point by
    point; ``core_table``: b at the vertices of every core element (``bcore_<tag>.txt``)."""
    cores = [t for t in stats["cores"] if t < WIND0]
    winds = [t for t in stats["cores"] if t >= WIND0]
    has_mag = stats["magnet"]
    L = (_groups(cores, winds, has_mag)
         + _functions(bodies, cores, winds, has_mag, mu_scale)
         + _constraints_and_jacobian(r_int, r_ext)
         + _INTEGRATION_AND_SPACE
         + _formulation(winds, has_mag)
         + _RESOLUTION_AND_POST
         + _post_operation(lines, plane_points, core_table, cores))
    return "\n".join(L) + "\n"
