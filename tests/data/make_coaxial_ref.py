"""Regenerate the axisymmetric GetDP reference of two coaxial cores (tests/data/coaxial_refs.*).

Question: what B (T) and dB/dz (T/m) does GetDP give around two thesis coils stacked on one axis
(core 1 a gap ``--gap`` above core 0, 10 mm by default; mu_r 1000), with 1 A in coil 0 and coil 1
unpowered? Core 1 is magnetized only through the core-to-core coupling, so the field above and
beside it is the independent check of designkit's coupled array (designkit.cores.coupled) that a
planar array would need a 3-D FEM for.

Frame of the stored points: coil 0's winding centre at the origin, the common axis +z (coil 1's
winding centre at z = core length + gap). Points: the axis above core 1 (12, 20, 30, 50, 80 mm
above its top) and the line r = 30 mm from 100 mm below coil 0's centre to 100 mm above coil 1's.
The mesh is that of designkit.fem (second-order a_phi, spherical-shell infinity) with both cores
in the core region; B and dB/dz come from local polynomial fits along densely sampled lines
(designkit.fem.runner.LineResult). Levels ``--levels`` (default 1,2,3) are solved and stored with
the largest per-point change between the two finest, the reference's own error estimate.

Usage: ``PYTHONPATH=$PWD python tests/data/make_coaxial_ref.py [--levels 1,2,3] [--gap 0.01]``
(needs GetDP and gmsh; about a minute per level).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from designkit.coil import Coil
from designkit.design import default_design
from designkit.fem.mesh import AIR, AXIS, CORE, OUTER, SHELL, WINDING, _size_near, gmsh_model
from designkit.fem.mesh import mesh_to_file
from designkit.fem.problem import problem_text
from designkit.fem.runner import _read_line, find_getdp, run_getdp, work_folder

HERE = Path(__file__).resolve().parent
HEIGHTS_M = (0.012, 0.020, 0.030, 0.050, 0.080)
SIDE_R_M = 0.030
SIDE_Z_M = tuple(np.round(np.linspace(-0.10, 0.10, 11), 6))
"""Side points: z relative to the mid-point of the two winding centres (extended below)."""
SHELL_M = (0.30, 0.36)


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


def _mesh(geo: dict, shift: float, level: int, lines_box, msh: Path) -> dict:
    """gmsh model of winding 0 and both cores, FEM frame = model frame + ``shift`` in z."""
    coil, d = geo["coil"], geo["distance_m"]
    c = coil.core
    s = 2.0 ** (-level / 2.0)
    rint, rext = SHELL_M
    with gmsh_model("designkit_coaxial") as gmsh:
        occ = gmsh.model.occ
        half_ext = occ.intersect([(2, occ.addDisk(0, 0, 0, rext, rext))],
                                 [(2, occ.addRectangle(0, -rext, 0, rext, 2 * rext))])[0]
        half_int = occ.intersect([(2, occ.addDisk(0, 0, 0, rint, rint))],
                                 [(2, occ.addRectangle(0, -rint, 0, rint, 2 * rint))])[0]
        hl = coil.length / 2
        boxes = {WINDING: [(coil.inner_radius, shift - hl, coil.outer_radius, shift + hl)],
                 CORE: [(0.0, zc + c.offset - c.length / 2, c.radius, zc + c.offset + c.length / 2)
                        for zc in (shift, shift + d)]}
        tools = list(half_int)
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
        axis, outer = [], []
        for _, cv in gmsh.model.getEntities(1):
            x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(1, cv)
            if x1 < 1e-6:
                axis.append(cv)
            elif abs(math.hypot(x1, max(abs(y0), abs(y1))) - rext) < 1e-6 * rext and x1 > rint:
                outer.append(cv)
        gmsh.model.addPhysicalGroup(1, axis, AXIS)
        gmsh.model.addPhysicalGroup(1, outer, OUTER)
        f = gmsh.model.mesh.field
        h_far = 12e-3 * s
        fields = []
        for r1, z0, z1 in lines_box:
            box = f.add("Box")
            for k, val in (("VIn", 0.6e-3 * s), ("VOut", h_far), ("XMin", 0.0), ("XMax", r1),
                           ("YMin", z0), ("YMax", z1), ("Thickness", 0.02)):
                f.setNumber(box, k, val)
            fields.append(box)
        curves, corners = set(), set()
        for tag in groups[CORE] + groups[WINDING]:
            curves |= {abs(e[1]) for e in gmsh.model.getBoundary([(2, tag)], oriented=False)}
            corners |= {p for dd, p in gmsh.model.getBoundary([(2, tag)], recursive=True)
                        if dd == 0}
        fields.append(_size_near(f, "CurvesList", sorted(curves - set(axis)), 1.0e-3 * s, h_far,
                                 2e-3, 0.08, sampling=200))
        fields.append(_size_near(f, "PointsList", sorted(corners), 0.15e-3 * s, h_far, 0.3e-3,
                                 0.01))
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
    pro = problem_text(current_density=coil.turns / area, mu_r=float(coil.core.relative_permeability),
                       bh=None, has_core=True, shell_inner=SHELL_M[0], shell_outer=SHELL_M[1],
                       lines=lines, winding_area=area, turns=coil.turns)
    with work_folder(None, "designkit_coaxial_") as work:
        stats = _mesh(geo, shift, level, box, work / "model.msh")
        run_getdp(find_getdp(), work, pro, work / "model.msh", timeout_s, expect="side.txt")
        out = {k: [] for k in ("br", "bz", "dbr_dz", "dbz_dz")}
        for (r, _, _, name), zz in zip(spans, (axis_z, side_z)):
            fit = _read_line(work / name, r).fit(zz + shift)
            for k in out:
                out[k].append(fit[k])
    return {k: np.concatenate(v) for k, v in out.items()}, stats


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="1,2,3", help="mesh levels, comma-separated")
    ap.add_argument("--gap", type=float, default=0.010, help="core-to-core gap, m")
    a = ap.parse_args(argv)
    geo = geometry(a.gap)
    levels = [int(v) for v in a.levels.split(",")]
    res, meta = {}, {"gap_m": a.gap, "distance_m": geo["distance_m"], "levels": {}}
    for lv in levels:
        t0 = time.perf_counter()
        res[lv], stats = solve(geo, lv)
        meta["levels"][str(lv)] = {**stats, "seconds": round(time.perf_counter() - t0, 1)}
        print(f"level {lv}: {stats['triangles']} triangles, "
              f"{meta['levels'][str(lv)]['seconds']:.0f} s", flush=True)
    best = res[levels[-1]]
    arrays = {"points_rz_m": points(geo), "level": np.array(levels[-1])}
    for k, v in best.items():
        arrays[k] = v
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
        print(f"change between the two finest levels: B {db.max():.2e}, dB/dz {dg.max():.2e}")
    np.savez_compressed(HERE / "coaxial_refs.npz", **arrays)
    (HERE / "coaxial_refs.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
