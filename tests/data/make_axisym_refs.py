"""Regenerate the axisymmetric GetDP references of the coupled model (tests/data/axisym_refs.*).

Question 1 ('coaxial'): B (T) and dB/dz (T/m) around two thesis coils stacked on one axis (core
1 a gap ``--gap`` above core 0, 10 mm by default; mu_r 1000), 1 A in coil 0, coil 1 unpowered.
Core 1 is magnetized only through the core-to-core coupling: an independent check of
designkit.cores.coupled that a planar array would need a 3-D FEM for. Points (model frame:
coil 0's winding centre at 0, axis +z): the axis 12-80 mm above core 1, the line r = 30 mm.
Question 2 ('pull'): Fz (N) on the design's magnet (uniform M as an azimuthal current sheet
SHEET_M thick, moment kept) 20 / 30 / 50 mm above one unpowered thesis core (its centre above
the winding's top): -2 pi a J delta int Br_ind dz, Br_ind from a mu_r 1000 minus a mu_r 1 solve
on the same mesh (the source's discretization error cancels).
Mesh and problem: designkit.fem's (second-order a_phi, spherical-shell infinity); B and dB/dz
from local polynomial fits along densely sampled lines (designkit.fem.runner.LineResult).
Each case is solved at ``--levels`` (default 0,1) and stored with the largest change between
the two finest, the reference's own error estimate (axisym_refs.json).

Usage: ``PYTHONPATH=$PWD python tests/data/make_axisym_refs.py [--cases coaxial,pull]
[--levels 0,1] [--gap 0.01]`` (needs GetDP and gmsh; minutes per level).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from designkit.model.coil import Coil
from designkit.design import default_design
from designkit.fem.mesh import AIR, AXIS, CORE, OUTER, SHELL, WINDING, gmsh_model, size_near
from designkit.fem.mesh import mesh_to_file
from designkit.fem.problem import AxiProblem, problem_text
from designkit.fem.runner import find_getdp, read_line, run_getdp, work_folder

HERE = Path(__file__).resolve().parent
HEIGHTS_M = (0.012, 0.020, 0.030, 0.050, 0.080)
SIDE_R_M = 0.030
SHELL_M = (0.30, 0.36)
"""Inner and outer radius of the shell mapped to infinity, m."""
PULL_HEIGHTS_M = (0.020, 0.030, 0.050)
"""Magnet centre above the winding's top face, m (the 3-D FEM's and the README's heights)."""
SHEET_M = 0.2e-3
"""Thickness of the current sheet that stands for the magnet's surface current M, m."""


def geometry(gap_m: float) -> dict:
    """The stack in the model frame (coil 0's winding centre at 0): coil, centre distance."""
    coil = Coil.from_design(default_design(), (0.0, 0.0, 0.0))
    return {"coil": coil, "distance_m": coil.core.length + float(gap_m)}


def points(geo: dict) -> np.ndarray:
    """(n, 2) (r, z) m of the reference points in the model frame."""
    c, d = geo["coil"].core, geo["distance_m"]
    top1 = d + c.offset + c.length / 2
    axis = [(0.0, top1 + h) for h in HEIGHTS_M]
    zs = np.linspace(-0.10, d + 0.10, 12)
    return np.array(axis + [(SIDE_R_M, z) for z in zs])


def _core_rect(coil, zc: float) -> tuple:
    """(r0, z0, r1, z1) of the core of ``coil`` with its winding centre at z = zc, m."""
    c = coil.core
    return (0.0, zc + c.offset - c.length / 2, c.radius, zc + c.offset + c.length / 2)


def size_fields(gmsh, s: float, boxes, h_box: float, bodies, axis) -> list:
    """gmsh size fields: ``h_box`` (m) in the boxes (r1, z0, z1), 1 mm on the outlines of the
    surfaces ``bodies`` (but the axis curves ``axis``), 0.15 mm at their corners, 12 mm far;
    each size times ``s``. Returns the field tags."""
    f = gmsh.model.mesh.field
    h_far = 12e-3 * s
    fields = []
    for r1, z0, z1 in boxes:
        box = f.add("Box")
        for k, val in (("VIn", h_box * s), ("VOut", h_far), ("XMin", 0.0), ("XMax", r1),
                       ("YMin", z0), ("YMax", z1), ("Thickness", 0.02)):
            f.setNumber(box, k, val)
        fields.append(box)
    curves, corners = set(), set()
    for tag in bodies:
        curves |= {abs(e[1]) for e in gmsh.model.getBoundary([(2, tag)], oriented=False)}
        corners |= {p for dd, p in gmsh.model.getBoundary([(2, tag)], recursive=True) if dd == 0}
    fields.append(size_near(f, "CurvesList", sorted(curves - set(axis)), 1.0e-3 * s, h_far,
                             2e-3, 0.08, sampling=200))
    fields.append(size_near(f, "PointsList", sorted(corners), 0.15e-3 * s, h_far, 0.3e-3,
                             0.01))
    return fields


def _mesh(boxes: dict, level: int, lines_box, msh: Path, h_fine=None) -> dict:
    """gmsh model of the rectangles ``boxes`` {WINDING: [...], CORE: [...]} ((r0, z0, r1, z1)
    m, FEM frame), refined in the boxes ``lines_box`` (r1, z0, z1) to 0.6 mm (or ``h_fine``)
    times 2^(-level/2). Writes ``msh``; returns the mesh size."""
    s = 2.0 ** (-level / 2.0)
    rint, rext = SHELL_M
    with gmsh_model("designkit_axisym_refs") as gmsh:
        occ = gmsh.model.occ
        half_ext, tools = (occ.intersect([(2, occ.addDisk(0, 0, 0, r, r))],
                                         [(2, occ.addRectangle(0, -r, 0, r, 2 * r))])[0]
                           for r in (rext, rint))
        tools = list(tools)
        for tag, bb in boxes.items():
            for x0, y0, x1, y1 in bb:
                tools.append((2, occ.addRectangle(x0, y0, 0, x1 - x0, y1 - y0)))
        occ.fragment(half_ext, tools)
        occ.synchronize()

        def inside(tag, b):
            x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(2, tag)
            e = 1e-6
            return x0 >= b[0] - e and y0 >= b[1] - e and x1 <= b[2] + e and y1 <= b[3] + e

        groups = {CORE: [], WINDING: [], AIR: [], SHELL: []}
        for _, tag in gmsh.model.getEntities(2):
            kind = next((k for k, bb in boxes.items() if any(inside(tag, b) for b in bb)), None)
            if kind is None:
                kind = AIR if inside(tag, (0.0, -rint, rint, rint)) else SHELL
            groups[kind].append(tag)
        for tag, ents in groups.items():
            gmsh.model.addPhysicalGroup(2, ents, tag)
        boxes1 = {cv: gmsh.model.getBoundingBox(1, cv) for _, cv in gmsh.model.getEntities(1)}
        axis = [cv for cv, b in boxes1.items() if b[3] < 1e-6]
        outer = [cv for cv, b in boxes1.items() if b[3] > rint
                 and abs(math.hypot(b[3], max(abs(b[1]), abs(b[4]))) - rext) < 1e-6 * rext]
        gmsh.model.addPhysicalGroup(1, axis, AXIS)
        gmsh.model.addPhysicalGroup(1, outer, OUTER)
        fields = size_fields(gmsh, s, lines_box, h_fine or 0.6e-3, groups[CORE] + groups[WINDING],
                             axis)
        mesh_to_file(gmsh, fields, 2, msh)
        _, etags, _ = gmsh.model.mesh.getElements(2)
        return {"triangles": int(sum(len(t) for t in etags))}


def solve(geo: dict, level: int, timeout_s: float = 1800.0) -> tuple[dict, dict]:
    """B, dB/dz at :func:`points` (model frame) from one GetDP solve: (arrays, mesh stats)."""
    coil, d = geo["coil"], geo["distance_m"]
    shift = -d / 2  # the stack centred in the FEM's air disc
    pts = points(geo)
    axis_z = pts[pts[:, 0] == 0.0, 1]
    side_z = pts[pts[:, 0] > 0.0, 1]
    step, margin = 0.25e-3, 6e-3
    spans = [(1e-7, float(axis_z.min()) - margin, float(axis_z.max()) + margin, "axis.txt"),
             (SIDE_R_M, float(side_z.min()) - margin, float(side_z.max()) + margin, "side.txt")]
    lines = [(r, float(z0 + shift), r, float(z1 + shift), int(round((z1 - z0) / step)), name)
             for r, z0, z1, name in spans]
    box = [(r + 4e-3, float(z0 + shift), float(z1 + shift)) for r, z0, z1, _ in spans]
    area = (coil.outer_radius - coil.inner_radius) * coil.length
    pro = problem_text(AxiProblem(
        current_density=coil.turns / area, mu_r=float(coil.core.relative_permeability), bh=None,
        has_core=True, shell_inner=SHELL_M[0], shell_outer=SHELL_M[1], lines=lines,
        winding_area=area, turns=coil.turns))
    hl = coil.length / 2
    boxes = {WINDING: [(coil.inner_radius, shift - hl, coil.outer_radius, shift + hl)],
             CORE: [_core_rect(coil, zc) for zc in (shift, shift + d)]}
    with work_folder(None, "designkit_coaxial_") as work:
        stats = _mesh(boxes, level, box, work / "model.msh")
        run_getdp(find_getdp(), work, pro, work / "model.msh", timeout_s, expect="side.txt")
        out = {k: [] for k in ("br", "bz", "dbr_dz", "dbz_dz")}
        for (r, _, _, name), zz in zip(spans, (axis_z, side_z)):
            fit = read_line(work / name, r).fit(zz + shift)
            for k in out:
                out[k].append(fit[k])
    return {k: np.concatenate(v) for k, v in out.items()}, stats


def pull(level: int, timeout_s: float = 1800.0) -> tuple[np.ndarray, dict]:
    """Fz (N) on the design's magnet (its uniform M as an azimuthal current sheet on its side,
    axis vertical) at each of PULL_HEIGHTS_M above one unpowered thesis core: -2 pi a J delta
    int Br_ind(a, z) dz, Br_ind the difference of a mu_r 1000 and a mu_r 1 solve on one mesh."""
    design = default_design()
    coil = Coil.from_design(design, (0.0, 0.0, 0.0))
    a, length = design.magnet.radius_m, design.magnet.length_m
    mag = design.magnet.magnetization_a_per_m
    d = SHEET_M
    jd = mag / d * a * a / (a * a + d * d / 12)  # the sheet's moment = the magnet's
    fz, stats = [], {}
    for h in PULL_HEIGHTS_M:
        zc = coil.length / 2 + h
        z0, z1 = zc - length / 2, zc + length / 2
        boxes = {WINDING: [(a - d / 2, z0, a + d / 2, z1)], CORE: [_core_rect(coil, 0.0)]}
        n = int(round(length / 0.05e-3))
        lines = [(a, z0, a, z1, n, "sheet.txt")]
        br = {}
        with work_folder(None, "designkit_pull_") as work:
            stats = _mesh(boxes, level, [(a + 3e-3, z0 - 3e-3, z1 + 3e-3)], work / "model.msh",
                          h_fine=0.1e-3)
            for mu in (1000.0, 1.0):
                pro = problem_text(AxiProblem(
                    current_density=jd, mu_r=mu, bh=None, has_core=True,
                    shell_inner=SHELL_M[0], shell_outer=SHELL_M[1], lines=lines,
                    winding_area=d * length, turns=1))
                run_getdp(find_getdp(), work, pro, work / "model.msh", timeout_s,
                          expect="sheet.txt")
                br[mu] = read_line(work / "sheet.txt", a)
        ind = br[1000.0].br - br[1.0].br
        fz.append(-2 * math.pi * a * jd * d * np.trapezoid(ind, br[1000.0].z))
    return np.array(fz), stats


def _coaxial_case(levels, gap) -> tuple[dict, dict]:
    geo = geometry(gap)
    res, meta = {}, {"gap_m": gap, "distance_m": geo["distance_m"], "levels": {}}
    for lv in levels:
        t0 = time.perf_counter()
        res[lv], stats = solve(geo, lv)
        meta["levels"][str(lv)] = {**stats, "seconds": round(time.perf_counter() - t0, 1)}
        print(f"coaxial level {lv}: {stats['triangles']} triangles, "
              f"{meta['levels'][str(lv)]['seconds']:.0f} s", flush=True)
    best = res[levels[-1]]
    arrays = {"points_rz_m": points(geo), "level": np.array(levels[-1]), **best}
    for lv in levels:
        for k, v in res[lv].items():
            arrays[f"level{lv}_{k}"] = v
    if len(levels) > 1:
        prev = res[levels[-2]]
        bn = np.hypot(best["br"], best["bz"])
        gn = np.hypot(best["dbr_dz"], best["dbz_dz"])
        db = np.hypot(best["br"] - prev["br"], best["bz"] - prev["bz"]) / bn
        dg = np.hypot(best["dbr_dz"] - prev["dbr_dz"], best["dbz_dz"] - prev["dbz_dz"]) / gn
        meta["change_last_level"] = {"b_max": float(db.max()), "dbdz_max": float(dg.max())}
    return arrays, meta


def _pull_case(levels) -> tuple[dict, dict]:
    arrays = {"pull_heights_m": np.array(PULL_HEIGHTS_M), "pull_level": np.array(levels[-1])}
    meta = {"sheet_m": SHEET_M, "levels": {}}
    res = {}
    for lv in levels:
        t0 = time.perf_counter()
        res[lv], stats = pull(lv)
        arrays[f"pull_level{lv}_fz_n"] = res[lv]
        meta["levels"][str(lv)] = {**stats, "seconds": round(time.perf_counter() - t0, 1)}
        print(f"pull level {lv}: Fz {res[lv]} N, {meta['levels'][str(lv)]['seconds']:.0f} s",
              flush=True)
    arrays["pull_fz_n"] = res[levels[-1]]
    if len(levels) > 1:
        meta["change_last_level"] = float(np.max(np.abs(res[levels[-1]] / res[levels[-2]] - 1)))
    return arrays, meta


def load_refs(stem: str) -> tuple:
    """Paths of tests/data/``stem``.npz and .json and their contents (empty when absent): the
    cases not regenerated are kept."""
    npz, js = HERE / f"{stem}.npz", HERE / f"{stem}.json"
    arrays = dict(np.load(npz)) if npz.exists() else {}
    meta = json.loads(js.read_text()) if js.exists() else {}
    return npz, js, arrays, meta


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="0,1", help="mesh levels, comma-separated")
    ap.add_argument("--gap", type=float, default=0.010, help="core-to-core gap, m")
    ap.add_argument("--cases", default="coaxial,pull", help="coaxial and/or pull")
    a = ap.parse_args(argv)
    levels = [int(v) for v in a.levels.split(",")]
    npz, js, arrays, meta = load_refs("axisym_refs")
    for case in a.cases.split(","):
        if case == "coaxial":
            arr, meta["coaxial"] = _coaxial_case(levels, a.gap)
            arrays.update({f"coaxial_{k}": v for k, v in arr.items()})
        else:
            arr, meta["pull"] = _pull_case(levels)
            arrays.update(arr)
        print(f"{case}: change between the two finest levels {meta[case].get('change_last_level')}")
        np.savez_compressed(npz, **arrays)
        js.write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
