"""Regenerate the transverse (m = 1) GetDP references of a core (tests/data/transverse_refs.*).

A horizontal point dipole m x_hat on a body's axis has the potential f_s(r, z) cos(theta): pure
azimuthal mode m = 1. The reduced potential f(r, z) cos(theta) of the magnetized body solves,
on the meridian half-plane (r, z), r >= 0, f = 0 on the axis,
  int mu (f_r g_r + f_z g_z + f g / r^2) r dr dz = -int_body (mu - mu0) (grad f_s . grad g
  + f_s g / r^2) r dr dz      for every g,
with the exterior dipole's condition df/dn = -2 f / R on the outer half-circle (radius R_OUT):
a 2-D GetDP problem (second-order nodes, ``VolAxi``). Induced field at theta = 0: B_x = -mu0
df/dr, B_z = -mu0 df/dz (T); on the axis B_x(z) and Fz = m dB_x/dz on the dipole (N).
'sphere' validates it: a sphere of mu_r 1000 beside the dipole against the Legendre series
(sphere response l (mu_r - 1) / (mu_r l + l + 1) per order l) and, in a uniform field, against
the dipole of moment 4 pi a^3 (mu_r - 1) / (mu_r + 2) H0 (A m^2). 'core': the thesis core
(linear mu_r, the model's) below the design's magnet turned horizontal at PULL_HEIGHTS_M, B at
points beside and above it and the force. 'stack': a second core STACK_GAP_M below it,
magnetized mostly through the m = 1 coupling. Frame of the stored points: the 1 x 1 array's
(winding top at z = 0).

Usage: ``PYTHONPATH=$PWD python tests/data/make_transverse_refs.py [--cases sphere,core,stack]
[--levels 0,1] [--domain-check]`` (needs GetDP and gmsh; minutes per level).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from designkit.model.array import CoilArray
from designkit.constants import MU0
from designkit.design import default_design
from designkit.fem.mesh import AIR, AXIS, CORE, OUTER, gmsh_model, mesh_to_file
from designkit.fem.runner import LineResult, find_getdp, run_getdp, work_folder
from make_axisym_refs import load_refs, size_fields  # tests/data, the script's own folder

R_OUT = 0.72
"""Radius of the truncated half-disc, m (exterior dipole condition on it)."""
PULL_HEIGHTS_M = (0.020, 0.030, 0.050)
"""Dipole above the winding's top face, m (as the axisymmetric pull reference)."""
AXIS_Z_M = (0.008, 0.012, 0.020, 0.030, 0.050, 0.080)
SIDE_R_M = 0.030
SIDE_Z_M = tuple(np.round(np.linspace(-0.12, 0.04, 9), 6))
STACK_GAP_M = 0.010
"""Gap between the two cores of the 'stack' case, m."""
STACK_SIDE_Z_M = tuple(np.round(np.linspace(-0.24, 0.04, 13), 6))
SPHERE = (0.02, 1000.0, 0.035)
"""Validation sphere: radius (m), mu_r, dipole distance from its centre (m)."""
STEP_M = 0.1e-3
"""Sampling step along the extraction lines, m."""
FIT_HALF_M = 1.5e-3
"""Half window of the local degree-4 fits of {d f} along the lines, m."""


def _pro(mu_r: float, source: tuple, lines: list, r_out: float = R_OUT) -> str:
    """GetDP text: ``source`` ("dipole", m, z_m) or ("uniform", H0); ``lines`` (r0, z0, r1,
    z1, n, file) print {d f}."""
    if source[0] == "dipole":
        m, zm = float(source[1]), float(source[2])
        d3 = f"((X[]^2 + (Y[] - {zm!r})^2)^1.5)"
        d5 = f"((X[]^2 + (Y[] - {zm!r})^2)^2.5)"
        k = f"{m / (4 * math.pi)!r}"
        fs = f"{k} * X[] / {d3}"
        dfs = (f"Vector[ {k} * (1. / {d3} - 3. * X[]^2 / {d5}),"
               f" -3. * {k} * X[] * (Y[] - {zm!r}) / {d5}, 0. ]")
    else:
        fs, dfs = f"{-source[1]!r} * X[]", f"Vector[ {-source[1]!r}, 0., 0. ]"
    t = [f"Group {{ Body = Region[{{{CORE}}}]; Air = Region[{{{AIR}}}];",
         f"  Axis = Region[{{{AXIS}}}]; Outer = Region[{{{OUTER}}}];",
         "  Domain = Region[{Body, Air}]; All_ = Region[{Body, Air, Outer}]; }",
         "Function { mu0 = 4.e-7 * Pi; mu[Air] = mu0; mu[Outer] = mu0;",
         f"  mu[Body] = mu0 * {mu_r!r}; fs[] = {fs}; dfs[] = {dfs}; ir2[] = 1. / X[]^2; }}",
         "Constraint { { Name f_fixed; Case { { Region Axis; Value 0.; } } } }",
         "Jacobian { { Name Vol; Case { { Region All; Jacobian VolAxi; } } }",
         "  { Name Sur; Case { { Region All; Jacobian SurAxi; } } } }",
         "Integration { { Name I1; Case { { Type Gauss; Case {",
         "  { GeoElement Triangle; NumberOfPoints 12; }",
         "  { GeoElement Line; NumberOfPoints 4; } } } } } }",
         "FunctionSpace { { Name H1_f; Type Form0; BasisFunction {",
         "  { Name sn; NameOfCoef fn; Function BF_Node; Support All_; Entity NodesOf[All]; }",
         "  { Name se; NameOfCoef fe; Function BF_Node_2E; Support All_; Entity EdgesOf[All]; } }",
         "  Constraint { { NameOfCoef fn; EntityType NodesOf; NameOfConstraint f_fixed; }",
         "    { NameOfCoef fe; EntityType EdgesOf; NameOfConstraint f_fixed; } } } }",
         "Formulation { { Name MagSta; Type FemEquation;",
         "  Quantity { { Name f; Type Local; NameOfSpace H1_f; } }",
         "  Equation {",
         "    Galerkin { [ mu[] * Dof{d f}, {d f} ]; In Domain; Jacobian Vol; Integration I1; }",
         "    Galerkin { [ mu[] * ir2[] * Dof{f}, {f} ]; In Domain; Jacobian Vol;"
         " Integration I1; }",
         "    Galerkin { [ (mu[] - mu0) * dfs[], {d f} ]; In Body; Jacobian Vol;"
         " Integration I1; }",
         "    Galerkin { [ (mu[] - mu0) * ir2[] * fs[], {f} ]; In Body; Jacobian Vol;"
         " Integration I1; }",
         f"    Galerkin {{ [ {2.0 / r_out!r} * mu0 * Dof{{f}}, {{f}} ]; In Outer; Jacobian Sur;"
         " Integration I1; }",
         "  } } }",
         "Resolution { { Name MagSta; System { { Name A; NameOfFormulation MagSta; } }",
         "  Operation { Generate[A]; Solve[A]; SaveSolution[A]; } } }",
         "PostProcessing { { Name MagSta; NameOfFormulation MagSta; Quantity {",
         "  { Name df; Value { Local { [ {d f} ]; In Domain; Jacobian Vol; } } }",
         "} } }",
         "PostOperation { { Name Post; NameOfPostProcessing MagSta; Operation {"]
    for r0, z0, r1, z1, n, name in lines:
        t.append(f"  Print[ df, OnLine {{{{{r0!r}, {z0!r}, 0}}{{{r1!r}, {z1!r}, 0}}}} {{{n}}},"
                 f" Format SimpleTable, File \"{name}\" ];")
    t += ["} } }"]
    return "\n".join(t) + "\n"


def _mesh(body: tuple, level: int, boxes: list, msh: Path, r_out: float = R_OUT) -> dict:
    """Half-disc of radius ``r_out`` with the body ("rects", r1, ((z0, z1), ...)) or ("sphere", a), sizes
    1 mm on its outline, 0.15 mm at its corners, 0.5 mm in ``boxes`` (r1, z0, z1), 12 mm far,
    each times 2^(-level/2). Writes ``msh``; returns the number of triangles."""
    s = 2.0 ** (-level / 2.0)
    with gmsh_model("designkit_transverse_refs") as gmsh:
        occ = gmsh.model.occ

        def half_disc(r):
            return occ.intersect([(2, occ.addDisk(0, 0, 0, r, r))],
                                 [(2, occ.addRectangle(0, -r, 0, r, 2 * r))])[0]

        if body[0] == "rects":
            tool = [(2, occ.addRectangle(0, z0, 0, body[1], z1 - z0)) for z0, z1 in body[2]]
            bbs = [(0.0, z0, body[1], z1) for z0, z1 in body[2]]
        else:
            tool = half_disc(body[1])
            bbs = [(0.0, -body[1], body[1], body[1])]
        occ.fragment(half_disc(r_out), tool)
        occ.synchronize()
        groups = {CORE: [], AIR: []}
        for _, tag in gmsh.model.getEntities(2):
            x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(2, tag)
            e = 1e-6
            inside = any(x0 >= bb[0] - e and y0 >= bb[1] - e and x1 <= bb[2] + e
                         and y1 <= bb[3] + e for bb in bbs)
            groups[CORE if inside else AIR].append(tag)
        for tag, ents in groups.items():
            gmsh.model.addPhysicalGroup(2, ents, tag)
        curves = {cv: gmsh.model.getBoundingBox(1, cv) for _, cv in gmsh.model.getEntities(1)}
        axis = [cv for cv, b in curves.items() if b[3] < 1e-6]
        outer = [cv for cv, b in curves.items() if b[3] > 0.5 * r_out]
        gmsh.model.addPhysicalGroup(1, axis, AXIS)
        gmsh.model.addPhysicalGroup(1, outer, OUTER)
        fields = size_fields(gmsh, s, boxes, 0.5e-3, groups[CORE], axis)
        mesh_to_file(gmsh, fields, 2, msh)
        _, etags, _ = gmsh.model.mesh.getElements(2)
        return {"triangles": int(sum(len(t) for t in etags))}


def _line(path: Path, r: float) -> LineResult:
    """{d f} printed along a line: (df/dr, df/dz) as LineResult's (br, bz)."""
    data = np.loadtxt(path, ndmin=2)
    order = np.argsort(data[:, 1])
    return LineResult(r, data[order, 1], data[order, 3], data[order, 4])


def _solve(body, mu_r, sources, axis_z, side, level, r_out=R_OUT, timeout_s=1800.0):
    """One mesh, one GetDP run per source. ``axis_z`` (FEM z on the axis), ``side`` (r, z
    array). Returns per source dict: bx_axis, dbx_dz_axis, bx_side, bz_side (T, T/m)."""
    m = 3e-3
    spans = [(1e-7, float(min(axis_z)) - m, float(max(axis_z)) + m, "axis.txt", axis_z)]
    if len(side):
        spans.append((float(side[0, 0]), float(side[:, 1].min()) - m, float(side[:, 1].max()) + m,
                      "side.txt", side[:, 1]))
    lines = [(r, z0, r, z1, int(round((z1 - z0) / STEP_M)), name) for r, z0, z1, name, _ in spans]
    boxes = [(r + 4e-3, z0, z1) for r, z0, z1, _, _ in spans]
    out = []
    with work_folder(None, "designkit_transverse_") as work:
        stats = _mesh(body, level, boxes, work / "model.msh", r_out)
        for src in sources:
            run_getdp(find_getdp(), work, _pro(mu_r, src, lines, r_out), work / "model.msh",
                      timeout_s, expect=spans[-1][3])
            res = {}
            fa = _line(work / "axis.txt", 1e-7).fit(np.asarray(axis_z), half_window=FIT_HALF_M)
            res["bx_axis"], res["dbx_dz_axis"] = -MU0 * fa["br"], -MU0 * fa["dbr_dz"]
            if len(side):
                fs = _line(work / "side.txt", side[0, 0]).fit(side[:, 1], half_window=FIT_HALF_M)
                res["bx_side"], res["bz_side"] = -MU0 * fs["br"], -MU0 * fs["bz"]
            out.append(res)
    return out, stats


def sphere_series(r, z, a, mu_r, d, m, l_max=60):
    """Reduced potential f (A) of a sphere (radius a, centre 0) beside the dipole m x_hat at
    (0, d), at exterior (r, z), theta = 0: sum_l C_l P_l'(cos t) sin t / R^(l+1)."""
    big_r = np.hypot(r, z)
    c, s = z / big_r, r / big_r
    f = np.zeros_like(big_r)
    for ll in range(1, l_max + 1):
        dp = np.polynomial.legendre.Legendre.basis(ll).deriv()(c)
        cl = -(m / (4 * math.pi)) / d ** (ll + 2) * a ** (2 * ll + 1) * ll * (mu_r - 1) \
            / (mu_r * ll + ll + 1)
        f += cl * dp * s / big_r ** (ll + 1)
    return f


def _b_of(f, r, z, h=1e-6):
    """B_x, B_z, dB_x/dz (T, T/m) at theta = 0 of the reduced potential f(r, z) (A) by
    central differences."""
    def grad(rr, zz):
        return (f(rr + h, zz) - f(rr - h, zz)) / (2 * h), (f(rr, zz + h) - f(rr, zz - h)) / (2 * h)
    fr, fz = grad(r, z)
    dfr_dz = (grad(r, z + 1e-5)[0] - grad(r, z - 1e-5)[0]) / 2e-5
    return -MU0 * fr, -MU0 * fz, -MU0 * dfr_dz


def _sphere_case(levels) -> dict:
    a, mu_r, d = SPHERE
    axis_z = np.array([a + 4e-3, a + 8e-3, d, d + 0.01, d + 0.03])
    side = np.c_[np.full(5, 0.03), np.linspace(-0.03, 0.03, 5)]
    meta = {"radius_m": a, "mu_r": mu_r, "dipole_z_m": d, "levels": {}}
    for lv in levels:
        t0 = time.perf_counter()
        (dip, uni), stats = _solve(("sphere", a), mu_r, [("dipole", 1.0, d), ("uniform", 1.0)],
                                   axis_z, side, lv)
        k = int(np.argmin(abs(axis_z - d)))
        # uniform H0 = 1 A/m: the induced field is the dipole p x_hat of the closed form
        p = 4 * math.pi * a ** 3 * (mu_r - 1) / (mu_r + 2)
        errs = []
        for res, fn in ((dip, lambda r, z: sphere_series(r, z, a, mu_r, d, 1.0)),
                        (uni, lambda r, z: p * r / (4 * math.pi * np.hypot(r, z) ** 3))):
            bx_a, _, g_a = _b_of(fn, 1e-7, axis_z)
            bx_s, bz_s, _ = _b_of(fn, side[:, 0], side[:, 1])
            ref_b = np.hypot(np.r_[bx_a, bx_s], np.r_[0 * bx_a, bz_s])
            errs.append(np.hypot(np.r_[res["bx_axis"] - bx_a, res["bx_side"] - bx_s],
                                 np.r_[0 * bx_a, res["bz_side"] - bz_s]) / ref_b)
            errs.append(res["dbx_dz_axis"][k] / g_a[k] - 1)
        meta["levels"][str(lv)] = {
            **stats, "seconds": round(time.perf_counter() - t0, 1),
            "dipole_b_rel_err_max": float(errs[0].max()), "dipole_fz_rel_err": float(errs[1]),
            "uniform_b_rel_err_max": float(errs[2].max())}
        print(f"sphere level {lv}: {meta['levels'][str(lv)]}", flush=True)
    return meta


def _core_case(levels, domain_check=False, stack=False) -> tuple[dict, dict]:
    """The thesis core ('core') or two stacked on one axis, STACK_GAP_M apart, the second
    below the first ('stack'): B at the points, Fz on the dipole, per height and level."""
    design = default_design()
    one = CoilArray.from_design(design.replace(**{"array.rows": 1, "array.columns": 1}))
    coil = one.coils[0]
    c = coil.core
    centres = float(coil.pose.position[2]) + c.offset - np.arange(1 + stack) * (c.length
                                                                              + STACK_GAP_M)
    zc = float(centres.mean())  # FEM origin, array frame
    m = float(np.linalg.norm(design.magnet.moment_vector_a_m2))
    axis_z = np.r_[AXIS_Z_M, PULL_HEIGHTS_M]
    side_z = STACK_SIDE_Z_M if stack else SIDE_Z_M
    side = np.c_[np.full(len(side_z), SIDE_R_M), side_z]
    body = ("rects", c.radius, tuple((q - zc - c.length / 2, q - zc + c.length / 2)
                                     for q in centres))
    sources = [("dipole", m, h - zc) for h in PULL_HEIGHTS_M]
    arrays = {"heights_m": np.array(PULL_HEIGHTS_M), "moment_a_m2": np.array([m, 0.0, 0.0]),
              "points_m": np.r_[np.c_[np.zeros(len(AXIS_Z_M)), np.zeros(len(AXIS_Z_M)),
                                      AXIS_Z_M],
                                np.c_[side[:, 0], np.zeros(len(side)), side[:, 1]]]}
    meta = {"mu_r": float(c.relative_permeability), "r_out_m": R_OUT, "levels": {},
            "core_centres_m": centres.tolist()}
    res = {}
    for lv in levels:
        t0 = time.perf_counter()
        out, stats = _solve(body, float(c.relative_permeability), sources, axis_z - zc,
                            side - np.array([0.0, zc]), lv)
        na = len(AXIS_Z_M)
        b = np.array([np.c_[np.r_[o["bx_axis"][:na], o["bx_side"]], np.zeros(na + len(side)),
                            np.r_[np.zeros(na), o["bz_side"]]] for o in out])
        fz = np.array([m * o["dbx_dz_axis"][na + i] for i, o in enumerate(out)])
        res[lv] = (b, fz)
        arrays[f"level{lv}_b_t"], arrays[f"level{lv}_fz_n"] = b, fz
        meta["levels"][str(lv)] = {**stats, "seconds": round(time.perf_counter() - t0, 1)}
        print(f"{'stack' if stack else 'core'} level {lv}: Fz {fz} N, {meta['levels'][str(lv)]}", flush=True)
    if domain_check:  # the outer radius doubled at the finest level
        out, _ = _solve(body, float(c.relative_permeability), sources, axis_z - zc,
                        side - np.array([0.0, zc]), levels[-1], 2 * R_OUT)
        fz2 = np.array([m * o["dbx_dz_axis"][len(AXIS_Z_M) + i] for i, o in enumerate(out)])
        meta["domain_check"] = {"level": levels[-1], "r_out_m": 2 * R_OUT,
                                "fz_change_max": float(np.max(np.abs(fz2 / res[levels[-1]][1] - 1)))}
        print(f"core, outer radius doubled: {meta['domain_check']}", flush=True)
    arrays["b_t"], arrays["fz_n"] = res[levels[-1]]
    arrays["level"] = np.array(levels[-1])
    if len(levels) > 1:
        (b1, f1), (b0, f0) = res[levels[-1]], res[levels[-2]]
        meta["change_last_level"] = {
            "b_max": float(np.max(np.linalg.norm(b1 - b0, axis=-1) / np.linalg.norm(b1, axis=-1))),
            "fz_max": float(np.max(np.abs(f1 / f0 - 1)))}
    return arrays, meta


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="0,1", help="mesh levels, comma-separated")
    ap.add_argument("--cases", default="sphere,core,stack", help="sphere, core and/or stack")
    ap.add_argument("--domain-check", action="store_true",
                    help="also solve the core with the outer radius doubled (finest level)")
    a = ap.parse_args(argv)
    levels = [int(v) for v in a.levels.split(",")]
    npz, js, arrays, meta = load_refs("transverse_refs")
    for case in a.cases.split(","):
        if case == "sphere":
            meta["sphere"] = _sphere_case(levels)
        else:
            arr, meta[case] = _core_case(levels, a.domain_check and case == "core",
                                         case == "stack")
            arrays.update({(f"{case}_{k}" if case == "stack" else k): v for k, v in arr.items()})
            np.savez_compressed(npz, **arrays)
        js.write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
