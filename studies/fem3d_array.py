"""3-D GetDP reference for the coupled array: how close is the 3-D FEM to known answers, and
what does it say about coupled cores and the magnet's pull on the iron?

Question: with the 3-D GetDP model of designkit.fem.fem3d (vector potential, Whitney +
second-order face functions, tree gauge, shell to infinity, symmetry where it exists), how
accurate are B and grad B (single coil with its core vs the axisymmetric model) and the magnet
force (vs the image method), at two mesh levels; and what are the reference values for (1) two
cores at the 50 mm pitch with one coil energized, (2) the 3x3 array with the centre (and,
unless quick, the corner) coil energized, (3) the magnet's pull on one core at 20, 30, 50 mm
(magnet centre above the winding top)? The uncoupled single-coil model is set beside (1) and
(2) to show the coupling effect, and designkit's coupled model (designkit.cores.coupled via
CoilArray) is checked against (1)-(3): per point |dB|/|B| and ||dG||_F/||G||_F over the
workspace points (12, 20, 30, 50, 80 mm, the rows above the default workspace's floor reported
separately) and the pull at each height. B and grad B come from the cores' FEM magnetization
plus the windings' exact field (``outputs='iron'``). Default level 0 for the reference cases,
one level coarser for the corner case (full model, no symmetry); the centre case is also solved
at the level below and its largest per-point change is reported (the FEM's own convergence).
Measured accuracy and convergence: docs/fem.md, docs/coupling.md.

Writes ``fem3d_array.npz`` (every case's points, B, G, forces) and ``fem3d_array.json``
(summary) under the output folder (default out/fem3d_array/); returns the summary dict.
Usage: ``PYTHONPATH=$PWD python studies/fem3d_array.py [out_dir] [--quick] [--level N]
[--cases two,centre,...] [--timeout S]``.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from designkit.support.atomic import write_json_atomic
from designkit.support.progress import tqdm
from designkit.model.array import CoilArray, gradient_from_g5
from designkit.model.coil import Coil
from designkit.cores.panel import Core
from designkit.design import default_design
from designkit.fem import fem3d
from designkit.field import winding_field


DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "fem3d_array"
"""Default output folder (git-ignored), whatever the working directory."""


def _rel(a, b, axis):
    return np.linalg.norm(a - b, axis=axis) / np.linalg.norm(b, axis=axis)


def _uncoupled(points, centre_xy=(0.0, 0.0)):
    """designkit's single-coil model (winding + its own core, mu_r 1000, 1 A) at array-frame
    points for a coil centred at ``centre_xy``: the uncoupled reference."""
    geo = fem3d.thesis_geometry()
    coil = Coil(geo["ri"], geo["ro"], geo["length"], geo["turns"],
                Core(geo["core_radius"], geo["core_length"], 1000.0))
    loc = points - np.array([centre_xy[0], centre_xy[1], -geo["length"] / 2])
    bw, gw = winding_field(loc, geo["ri"], geo["ro"], geo["length"], geo["turns"], 1.0,
                           gradient=True)
    bc, gc = coil.core.field_local(loc, coil, 1.0, gradient=True)
    return bw + bc, gw + gc


def _coupled(points, case):
    """designkit's coupled model (designkit.cores.coupled through CoilArray: every core of the case
    solved together, linear mu_r 1000, 1 A) at the case's points (its frame): B (n, 3) T,
    G (n, 3, 3) T/m. Cases: 'two' (fem3d puts coil 0 at the origin, the design's 1 x 2 array
    has it at x = -pitch / 2), 'centre', 'corner' (the 3 x 3 array, coil 4 resp. 0)."""
    d = default_design()
    if case == "two":
        arr = CoilArray.from_design(d.replace(**{"array.rows": 1, "array.columns": 2}))
        p, k = points - np.array([d.array.pitch_m / 2, 0.0, 0.0]), 0
    else:
        arr, p, k = CoilArray.from_design(d), points, 4 if case == "centre" else 0

    a = arr.actuation_matrix(p)
    return a[:, :3, k], gradient_from_g5(a[:, 3:, k])


def model_vs_fem(points, b, g, case) -> dict:
    """The coupled model against the FEM at the case's points: per point |dB| / |B| and
    ||dG||_F / ||G||_F (FEM as reference), max and median overall, max per height, and max
    over the points inside the default workspace (z >= its floor)."""
    bm, gm = _coupled(points, case)
    eb, eg = _rel(bm, b, 1), _rel(gm, g, (1, 2))
    z_min = default_design().workspace.z_min_m
    inside = points[:, 2] >= z_min - 1e-9
    heights = np.unique(np.round(points[:, 2], 6))
    return {"b_max": float(eb.max()), "b_median": float(np.median(eb)),
            "g_max": float(eg.max()), "g_median": float(np.median(eg)),
            "workspace_z_min_m": z_min,
            "b_max_in_workspace": float(eb[inside].max()) if inside.any() else None,
            "g_max_in_workspace": float(eg[inside].max()) if inside.any() else None,
            "by_height_mm": {f"{1e3 * h:g}": {
                "b_max": float(eb[np.isclose(points[:, 2], h)].max()),
                "g_max": float(eg[np.isclose(points[:, 2], h)].max())} for h in heights}}


def model_pull(heights) -> np.ndarray:
    """designkit's pull of one core on the exact 10 x 10 mm magnet (coupling solve, face
    charges; designkit.model.array.CoilArray.bias_force with ``magnet_size_m``) at the heights of
    the magnet's centre above the winding's top (m): Fz (k,) N."""
    d = default_design()
    a1 = CoilArray.from_design(d.replace(**{"array.rows": 1, "array.columns": 1}))
    m = np.asarray(d.magnet.moment_vector_a_m2, float)
    size = (d.magnet.radius_m, d.magnet.length_m)
    return np.array([a1.bias_force([0.0, 0.0, h], m, magnet_size_m=size)[2] for h in heights])


def run(out_dir=DEFAULT_OUT, quick: bool = False, level: int | None = None,
        cases: tuple[str, ...] | None = None, timeout_s: float = 1800.0) -> dict:
    """Run the cases (``cases``: a subset of two, centre, pull, single, block, corner; default
    all) and write the result files; returns the summary dict. ``timeout_s`` bounds each GetDP
    run of the 3 x 3 array cases (the full corner model at level 0 needs more than 1800 s on
    a loaded 2-core machine)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lv = (-2 if quick else 0) if level is None else level
    levels = (lv,) if quick else (lv - 1, lv)
    geo = fem3d.thesis_geometry()
    pitch = geo["pitch"]
    heights = (0.012, 0.020, 0.030, 0.050, 0.080)
    # odd counts put a point on the centre coil's axis (the design point at 30 mm)
    ws = fem3d.workspace_points(n_side=3 if quick else 5, heights=heights)
    rng = np.random.default_rng(11)
    check = np.column_stack([rng.uniform(-0.06, 0.06, 8), rng.uniform(-0.06, 0.06, 8),
                             rng.uniform(0.012, 0.08, 8)])
    pair = np.array([[x, y, z] for x in (0.0, 0.025, pitch) for y in (0.0, 0.02)
                     for z in (0.012, 0.03, 0.06)])
    arrays: dict = {}
    summary: dict = {"levels": list(levels), "seconds": {}}
    # the reference cases first, the accuracy checks and the coarser levels after: every step
    # rewrites the result files, so an interrupted run keeps what it finished
    steps = [("two", lv), ("centre", lv), ("pull", lv)] + [("single", l) for l in levels] + \
        [("block", l) for l in levels[:1]] + [("pull", l) for l in levels[:-1]] + \
        [("centre", l) for l in levels[:-1]] + ([] if quick else [("corner", lv - 1)])
    if cases is not None:
        steps = [st for st in steps if st[0] in cases]
    for name, l in tqdm(steps, desc="3-D GetDP cases", mininterval=2):
        t0 = time.perf_counter()
        if name == "single":
            b, g, res = fem3d.single_core_case(check, level=l)
            bm, gm = _uncoupled(check)
            summary[f"single_L{l}"] = {
                "b_err_max": float(_rel(b, bm, 1).max()),
                "g_err_max": float(_rel(g, gm, (1, 2)).max()),
                "dbz_err_max": float(np.max(np.abs(g[:, 2, 2] - gm[:, 2, 2])
                                            / np.linalg.norm(gm, axis=(1, 2)))),
                "tets": res.mesh_stats["tetrahedra"]}
            arrays[f"single_L{l}_points"], arrays[f"single_L{l}_b"] = check, b
            arrays[f"single_L{l}_g"] = g
        elif name == "block":
            r = fem3d.magnet_block_force(level=l)
            summary[f"block_L{l}"] = {"fem_fz_n": r["fem_fz_n"], "image_fz_n": r["image_fz_n"],
                                      "rel": r["fem_fz_n"] / r["image_fz_n"] - 1,
                                      "tets": r["mesh"]["tetrahedra"]}
        elif name == "pull":
            h, fz = fem3d.magnet_pull_case(level=l)
            fm = model_pull(h)
            summary[f"pull_L{l}"] = {"heights_m": h.tolist(), "fz_n": fz.tolist(),
                                     "model_fz_n": fm.tolist(),
                                     "model_vs_fem": (fm / fz - 1).tolist()}
            arrays[f"pull_L{l}_heights"], arrays[f"pull_L{l}_fz"] = h, fz
        elif name == "two":
            b, g, res = fem3d.two_cores_case(pair, level=l)
            bm, gm = _uncoupled(pair)
            summary["two_cores"] = {
                "coupling_b_max": float(_rel(b, bm, 1).max()),
                "coupling_dbz_at_design_point": float(g[1, 2, 2] / gm[1, 2, 2] - 1),
                "tets": res.mesh_stats["tetrahedra"], "level": l,
                "model_vs_fem": model_vs_fem(pair, b, g, "two")}
            arrays["two_points"], arrays["two_b"], arrays["two_g"] = pair, b, g
        elif name == "centre" and l != lv:  # the FEM's convergence: a coarser level
            b, g, res = fem3d.array_case(ws, energized=name, level=l)
            if "centre_b" in arrays:
                eb = _rel(b, arrays["centre_b"], 1)
                eg = _rel(g, arrays["centre_g"], (1, 2))
                summary["array_centre"][f"fem_change_from_L{l}"] = {
                    "b_max": float(eb.max()), "g_max": float(eg.max()),
                    "tets": res.mesh_stats["tetrahedra"]}
        elif name in ("centre", "corner"):
            b, g, res = fem3d.array_case(ws, energized=name, level=l, timeout_s=timeout_s)
            c = (0.0, 0.0) if name == "centre" else (-pitch, pitch)
            bm, gm = _uncoupled(ws, c)
            i0 = int(np.argmin(np.linalg.norm(ws - np.array([c[0], c[1], 0.03]), axis=1)))
            summary[f"array_{name}"] = {
                "coupling_b_max": float(_rel(b, bm, 1).max()),
                "coupling_b_median": float(np.median(_rel(b, bm, 1))),
                "dbz_vs_uncoupled_nearest_design_point":
                    float(g[i0, 2, 2] / gm[i0, 2, 2] - 1),
                "design_point_m": ws[i0].tolist(), "level": l,
                "tets": res.mesh_stats["tetrahedra"],
                "model_vs_fem": model_vs_fem(ws, b, g, name)}
            arrays[f"{name}_points"], arrays[f"{name}_b"], arrays[f"{name}_g"] = ws, b, g
        summary["seconds"][f"{name}_L{l}"] = time.perf_counter() - t0
        np.savez(out / "fem3d_array.npz", **arrays)
        write_json_atomic(out / "fem3d_array.json", summary)
    return summary


def print_table(s: dict) -> None:
    print("== 3-D GetDP reference (machine shared: times are wall-clock under load)")
    for key in sorted(k for k in s if k.startswith("single_")):
        e = s[key]
        print(f"   single coil+core vs axisymmetric model, {key[7:]} ({e['tets']} tets):"
              f" max |dB|/|B| {100 * e['b_err_max']:.2f} %, max |dG|/|G| "
              f"{100 * e['g_err_max']:.1f} %, max |d dBz/dz|/|G| {100 * e['dbz_err_max']:.1f} %")
    for key in sorted(k for k in s if k.startswith("block_")):
        e = s[key]
        print(f"   magnet 10 mm above a mu_r 1000 block, {key[6:]}: FEM"
              f" {1e3 * e['fem_fz_n']:.1f} mN"
              f" vs image {1e3 * e['image_fz_n']:.1f} mN ({100 * e['rel']:+.2f} %)")
    for key in sorted(k for k in s if k.startswith("pull_")):
        e = s[key]
        cells = ", ".join(f"{1e3 * h:.0f} mm: {1e3 * f:.1f} mN" for h, f in
                          zip(e["heights_m"], e["fz_n"]))
        print(f"   magnet pull on one core (no current), {key[5:]}: {cells}")
        if "model_fz_n" in e:
            cells = ", ".join(f"{1e3 * f:.1f} mN ({100 * r:+.1f} %)" for f, r in
                              zip(e["model_fz_n"], e["model_vs_fem"]))
            print(f"      designkit (coupling solve, exact cylinder): {cells}")
    if "two_cores" in s:
        e = s["two_cores"]
        print(f"   two cores, coil 0 at 1 A: |B| differs from the uncoupled model by up to"
              f" {100 * e['coupling_b_max']:.1f} %; dBz/dz 30 mm above coil 0"
              f" {100 * e['coupling_dbz_at_design_point']:+.1f} %")
    for name in ("centre", "corner"):
        if f"array_{name}" in s:
            e = s[f"array_{name}"]
            print(f"   3x3 array, {name} coil at 1 A (L{e['level']}, {e['tets']} tets): |B| vs"
                  f" uncoupled up to {100 * e['coupling_b_max']:.1f} % (median"
                  f" {100 * e['coupling_b_median']:.1f} %); dBz/dz at {e['design_point_m']}"
                  f" {100 * e['dbz_vs_uncoupled_nearest_design_point']:+.1f} %")
    print("   coupled model vs FEM, per point |dB|/|B| and ||dG||_F/||G||_F (FEM reference):")
    for key, label in (("two_cores", "two cores"), ("array_centre", "3x3, centre coil"),
                       ("array_corner", "3x3, corner coil")):
        e = s.get(key, {}).get("model_vs_fem")
        if e is None:
            continue
        heights = "; ".join(f"{h} mm: {100 * v['b_max']:.2f} / {100 * v['g_max']:.2f} %"
                            for h, v in e["by_height_mm"].items())
        ws = ("" if e["b_max_in_workspace"] is None else
              f"; in the workspace (z >= {1e3 * e['workspace_z_min_m']:g} mm) max"
              f" {100 * e['b_max_in_workspace']:.2f} / {100 * e['g_max_in_workspace']:.2f} %")
        print(f"      {label} (L{s[key]['level']}): B max {100 * e['b_max']:.2f} % (median"
              f" {100 * e['b_median']:.2f} %), G max {100 * e['g_max']:.2f} % (median"
              f" {100 * e['g_median']:.2f} %){ws}")
        print(f"         max by height B / G: {heights}")
        for k, v in s[key].items():
            if k.startswith("fem_change_from_"):
                print(f"         FEM convergence: {k[16:]} ({v['tets']} tets) -> L"
                      f"{s[key]['level']}: max per-point change B {100 * v['b_max']:.2f} %,"
                      f" G {100 * v['g_max']:.2f} %")
    print("   seconds: " + ", ".join(f"{k} {v:.0f}" for k, v in s["seconds"].items()))


if __name__ == "__main__":  # pragma: no cover
    import argparse

    ap = argparse.ArgumentParser()
    ap.add_argument("out_dir", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--level", type=int, default=None)
    ap.add_argument("--timeout", type=float, default=1800.0,
                    help="seconds allowed per GetDP run of the 3x3 array cases")
    ap.add_argument("--cases", default=None,
                    help="comma-separated subset of two,centre,pull,single,block,corner")
    a = ap.parse_args()
    print_table(run(a.out_dir, quick=a.quick, level=a.level,
                    cases=None if a.cases is None else tuple(a.cases.split(",")),
                    timeout_s=a.timeout))
