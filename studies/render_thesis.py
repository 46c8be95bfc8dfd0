"""Question: what force constant lambda (thesis eq. 4.3) can the default device render on the
thesis' four objects and a mesh, and where is the force met?

For the flat surface (100 mm square at 50 mm), hemisphere (100 mm), half-cylinder and wedge
(100 mm footprint, 50 mm top: assumed, the thesis gives no sizes) and a closed mesh (a bumpy
80 mm blob, STL in mm, through MeshSurface's signed-distance grid):

* lambda, unipolar (the thesis' drive) and bipolar, for the 3-D required force lambda h n
  (and for the plane also the thesis' literal Fz-only form), per-coil limit 6 A, budget 54 A;
* the effect of the total-current bound on lambda (plane; budgets 54 .. 6 A);
* at the thesis' lambda = 6 N/m and at 3x it: the renderable region (surface points whose
  required force is met within 5 %), the force error over the surface and the currents;
* one Fig. 4.5/4.6-like figure per object: surface + required forces, error map, currents and
  forces along a line across the object.

Source of A(p) and of the bias force F0(p) (the magnet's pull on the cores with every coil off,
which the allocator subtracts: lambda h n - F0 is what the coils must render): designkit's
coupled CoilArray directly, through ArrayActuation (the map v2 carries the same within 1e-3).

    python studies/render_thesis.py [OUT_DIR] [--n-side N] [--quick]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit import default_design
from designkit.support.atomic import atomic_path, write_json_atomic, write_text_atomic
from designkit.render import (ArrayActuation, HalfCylinder, Hemisphere, MeshSurface, Plane,
                              Wedge, force_constant)
from designkit.render.constant import force_matrices
from firmware_io.allocation import allocate

U_A, T_A = 6.0, 54.0


DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "render_thesis"
"""Default output folder (git-ignored), whatever the working directory."""


def blob_stl(path: Path, radius_mm: float = 40.0, res: int = 48) -> Path:
    """A closed bumpy blob (a stand-in for the thesis' heart scan), STL in millimetres."""
    import pyvista as pv

    s = pv.Sphere(radius=radius_mm, theta_resolution=res, phi_resolution=res)
    p = np.asarray(s.points)
    r = np.linalg.norm(p, axis=1)
    th = np.arccos(np.clip(p[:, 2] / r, -1, 1))
    ph = np.arctan2(p[:, 1], p[:, 0])
    scale = 1 + 0.18 * np.sin(2 * ph) * np.sin(th) ** 2 + 0.12 * np.cos(3 * th)
    s.points = p * scale[:, None] * np.array([1.0, 0.8, 0.7])
    path.parent.mkdir(parents=True, exist_ok=True)
    s.save(str(path))
    return path


def render_stats(obj, source, lam, unipolar, pts, nrm, fms):
    """Allocate lambda h n at every surface point: relative error, currents, met within 5 %."""
    h = obj.height(pts)
    want = lam * h[:, None] * nrm
    cur = np.empty((len(pts), fms.shape[2]))
    err = np.empty(len(pts))
    for j in range(len(pts)):
        cur[j], res = allocate(fms[j], want[j], U_A, T_A, unipolar=unipolar)
        err[j] = np.sqrt(res) / max(np.linalg.norm(want[j]), 1e-300)
    return {"want_n": want, "currents_a": cur, "rel_error": err, "met": err <= 0.05}


def figure(name, obj, pts, nrm, stats_u, stats_b, lam, out_png, source):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(13, 9.5))
    ax = fig.add_subplot(2, 2, 1, projection="3d")
    h = obj.height(pts)
    step = max(1, len(pts) // 250)
    ax.scatter(pts[:, 0] * 1e3, pts[:, 1] * 1e3, pts[:, 2] * 1e3, c=h * 1e3, s=4,
               cmap="viridis")
    f = stats_u["want_n"][::step]
    q = pts[::step] * 1e3
    fmax = max(float(np.linalg.norm(stats_u["want_n"], axis=1).max()), 1e-9)
    mm_per_n = 25.0 / fmax
    ax.quiver(q[:, 0], q[:, 1], q[:, 2], f[:, 0], f[:, 1], f[:, 2], length=mm_per_n,
              color="k", linewidth=0.5, normalize=False)
    ax.set_zlim(0, float(pts[:, 2].max()) * 1e3 + 30)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_zlabel("z (mm)")
    ax.set_title(f"(a) {name}: surface points, required force lambda h n\n"
                 f"lambda = {lam:g} N/m (arrows: {mm_per_n:.3g} mm per N)", fontsize=10)
    ax = fig.add_subplot(2, 2, 2)
    sc = ax.scatter(pts[:, 0] * 1e3, pts[:, 1] * 1e3,
                    c=np.clip(stats_u["rel_error"] * 100, 0, 20), s=max(6, 4000 // len(pts)),
                    cmap="RdYlGn_r", vmin=0, vmax=20)
    ax.tricontour(pts[:, 0] * 1e3, pts[:, 1] * 1e3, stats_u["rel_error"] * 100, levels=[5],
                  colors="tab:blue") if len(pts) > 8 else None
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"(b) force error, unipolar, lambda = {lam:g} N/m\n"
                 f"blue: 5 % (met inside: {stats_u['met'].mean() * 100:.0f} % unipolar, "
                 f"{stats_b['met'].mean() * 100:.0f} % bipolar)", fontsize=10)
    cb = fig.colorbar(sc, ax=ax, shrink=0.85)
    cb.set_label("|F - F_req| / |F_req| (%), clipped at 20")
    # the line y = 0 across the object
    x0, x1, _, _ = obj.footprint_m()
    xs = np.linspace(x0, x1, 61)
    line = np.c_[xs, np.zeros_like(xs), np.zeros_like(xs)]
    hl = obj.height(line)
    keep = (hl > source.bounds[0][2])
    line = np.c_[xs[keep], np.zeros(keep.sum()), hl[keep]]
    ax = fig.add_subplot(2, 2, 3)
    ax4 = fig.add_subplot(2, 2, 4)
    if len(line):
        ln = obj._obj().top_normal(line)
        fm = force_matrices(source, line, "force")
        want = lam * line[:, 2:3] * ln
        for uni, style in ((True, "-"), (False, "--")):
            cur = np.array([allocate(fm[j], want[j], U_A, T_A, unipolar=uni)[0]
                            for j in range(len(line))])
            got = np.einsum("nkc,nc->nk", fm, cur)
            if uni:
                for c in range(cur.shape[1]):
                    ax.plot(line[:, 0] * 1e3, cur[:, c], style, lw=1.2, label=f"coil {c + 1}")
            else:
                ax.plot(line[:, 0] * 1e3, np.abs(cur).sum(axis=1), "k--", lw=1.5,
                        label="sum |I|, bipolar")
            ax4.plot(line[:, 0] * 1e3, got[:, 2] * 1e3, style, color="tab:red",
                     label=f"rendered Fz, {'unipolar' if uni else 'bipolar'}")
            ax4.plot(line[:, 0] * 1e3, got[:, 0] * 1e3, style, color="tab:green",
                     label=f"rendered Fx, {'unipolar' if uni else 'bipolar'}")
        ax4.plot(line[:, 0] * 1e3, want[:, 2] * 1e3, ":", color="k", lw=2, label="required Fz")
        ax4.plot(line[:, 0] * 1e3, want[:, 0] * 1e3, ":", color="gray", lw=2,
                 label="required Fx")
    ax.set_xlabel("x on the line y = 0 (mm)")
    ax.set_ylabel("current (A)")
    ax.set_title("(c) coil currents along y = 0 (unipolar; dashed: bipolar sum |I|)",
                 fontsize=10)
    ax.legend(fontsize=7, ncol=2, loc="center left", bbox_to_anchor=(1.0, 0.5))
    ax.grid(alpha=0.3)
    ax4.set_xlabel("x on the line y = 0 (mm)")
    ax4.set_ylabel("force (mN)")
    ax4.set_title("(d) required and rendered force along y = 0", fontsize=10)
    ax4.legend(fontsize=7, loc="best")
    ax4.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(out_png, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=80)
    plt.close(fig)


def figures_only(out_dir=DEFAULT_OUT, *, n_side: int = 31) -> None:
    """Redraw the per-object figures (no lambda searches)."""
    out_dir = Path(out_dir)
    source = ArrayActuation.from_design(default_design())
    mesh = MeshSurface.from_file(blob_stl(out_dir / "blob.stl"), spacing_m=0.002)
    lo, hi = source.bounds
    for name, obj in {"flat surface": Plane(), "hemisphere": Hemisphere(),
                      "half-cylinder": HalfCylinder(), "wedge": Wedge(),
                      "mesh (blob)": mesh}.items():
        pts, nrm = obj.surface_points(n_side)
        keep = np.all((pts >= lo) & (pts <= hi), axis=1)
        pts, nrm = pts[keep], nrm[keep]
        fms = force_matrices(source, pts, "force")
        su = render_stats(obj, source, 18.0, True, pts, nrm, fms)
        sb = render_stats(obj, source, 18.0, False, pts, nrm, fms)
        slug = name.split()[0].replace("-", "_")
        figure(name, obj, pts, nrm, su, sb, 18.0, out_dir / f"render_{slug}.png", source)


def run(out_dir=DEFAULT_OUT, *, n_side: int = 31, quick: bool = False,
        progress: bool = True) -> dict:
    out_dir = Path(out_dir)
    t0 = time.perf_counter()
    design = default_design()
    source = ArrayActuation.from_design(design)
    if quick:
        n_side = 5
    stl = blob_stl(out_dir / "blob.stl", res=24 if quick else 48)
    mesh = MeshSurface.from_file(stl, spacing_m=0.004 if quick else 0.002)
    mesh_err = mesh.grid_error(n_samples=500 if quick else 4000)
    objects = {"flat surface": Plane(), "hemisphere": Hemisphere(),
               "half-cylinder": HalfCylinder(), "wedge": Wedge(), "mesh (blob)": mesh}
    if quick:  # the smoke test: same code paths, two objects
        objects = {k: objects[k] for k in ("flat surface", "mesh (blob)")}
    rows, lam_thesis = [], 6.0
    kw = dict(current_limit_a=U_A, n_side=n_side, progress=progress)
    for name, obj in objects.items():
        r = {"object": name}
        for uni in (True, False):
            fc = force_constant(obj, source, total_current_a=T_A, unipolar=uni, **kw)
            key = "unipolar" if uni else "bipolar"
            r[f"lambda_{key}_n_per_m"] = fc.lam_n_per_m
            r[f"limiting_point_{key}_mm"] = (fc.limiting_point_m * 1e3).round(1).tolist()
        r["n_points"] = int(len(fc.points_m))
        r["excluded_below_workspace"] = fc.excluded
        pts, nrm = fc.points_m, fc.normals
        fms = force_matrices(source, pts, "force")
        for lam, tag in ((lam_thesis, "6"), (3 * lam_thesis, "18")):
            su = render_stats(obj, source, lam, True, pts, nrm, fms)
            sb = render_stats(obj, source, lam, False, pts, nrm, fms)
            r[f"met5_unipolar_at_{tag}"] = float(su["met"].mean())
            r[f"met5_bipolar_at_{tag}"] = float(sb["met"].mean())
            r[f"median_err_unipolar_at_{tag}"] = float(np.median(su["rel_error"]))
            r[f"max_err_unipolar_at_{tag}"] = float(su["rel_error"].max())
            r[f"max_sum_current_unipolar_at_{tag}_a"] = float(
                np.abs(su["currents_a"]).sum(axis=1).max())
            if tag == "18":
                slug = name.split()[0].replace("-", "_")
                figure(name, obj, pts, nrm, su, sb, lam, out_dir / f"render_{slug}.png", source)
        rows.append(r)
    # the plane: thesis formulation (Fz only, eq. 4.2), thesis discretization, budgets
    plane = objects["flat surface"]
    ns_thesis = 5 if quick else 61
    thesis = {}
    for uni in ((True,) if quick else (True, False)):
        for rw in ("fz", "force"):
            fc = force_constant(plane, source, total_current_a=T_A, unipolar=uni, rows=rw,
                                current_limit_a=U_A, n_side=ns_thesis, progress=progress)
            thesis[f"{rw}_{'unipolar' if uni else 'bipolar'}"] = {
                "lambda_n_per_m": fc.lam_n_per_m,
                "limiting_point_mm": (fc.limiting_point_m * 1e3).round(1).tolist(),
                "force_at_lambda_n": fc.lam_n_per_m * 0.05, "n_points": len(fc.points_m)}
    budgets = (54.0, 6.0) if quick else (54.0, 36.0, 24.0, 18.0, 12.0, 6.0)
    budget_rows = []
    for tl in budgets:
        b = {"total_current_a": tl}
        for uni in (True, False):
            fc = force_constant(plane, source, total_current_a=tl, unipolar=uni, **kw)
            b["unipolar" if uni else "bipolar"] = fc.lam_n_per_m
        budget_rows.append(b)
    res = {"objects": rows, "plane_thesis_form": thesis, "plane_budgets": budget_rows,
           "mesh_grid_error_m": mesh_err, "n_side": n_side, "current_limit_a": U_A,
           "total_current_a": T_A, "seconds": time.perf_counter() - t0,
           "moment_a_m2": list(design.magnet.moment_vector_a_m2)}
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out_dir / "render_thesis.json", res)
    write_text_atomic(out_dir / "render_thesis.md", table(res))
    _lambda_figure(res, out_dir / "render_lambda.png")
    print(table(res))
    return res


def table(res) -> str:
    lines = ["| object | points | lambda unipolar (N/m) | lambda bipolar (N/m) | bipolar/uni | "
             "met 5 % at 6 N/m uni/bi | met 5 % at 18 N/m uni/bi | median err at 18 uni |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in res["objects"]:
        lu, lb = r["lambda_unipolar_n_per_m"], r["lambda_bipolar_n_per_m"]
        lines.append(f"| {r['object']} | {r['n_points']} | {lu:.3g} | {lb:.3g} | "
                     f"{(f'{lb / lu:.2f}' if lu > 0 else 'inf')} | "
                     f"{r['met5_unipolar_at_6'] * 100:.0f} % / "
                     f"{r['met5_bipolar_at_6'] * 100:.0f} % | "
                     f"{r['met5_unipolar_at_18'] * 100:.0f} % / "
                     f"{r['met5_bipolar_at_18'] * 100:.0f} % | "
                     f"{r['median_err_unipolar_at_18'] * 100:.1f} % |")
    lines += ["", "Flat surface at 50 mm, thesis discretization (thesis: lambda = 6 N/m, 0.3 N):",
              "", "| required force | drive | lambda (N/m) | force at 50 mm (N) | limiting point "
              "(mm) |", "| --- | --- | --- | --- | --- |"]
    for k, t in res["plane_thesis_form"].items():
        rw, dr = k.split("_")
        lines.append(f"| {'Fz only (eq. 4.2)' if rw == 'fz' else '3-D lambda h n'} | {dr} | "
                     f"{t['lambda_n_per_m']:.3g} | {t['force_at_lambda_n']:.3g} | "
                     f"{t['limiting_point_mm']} |")
    lines += ["", "Flat surface, total-current bound (per coil 6 A):", "",
              "| I_t (A) | lambda unipolar | lambda bipolar |", "| --- | --- | --- |"]
    for b in res["plane_budgets"]:
        lines.append(f"| {b['total_current_a']:g} | {b['unipolar']:.3g} | {b['bipolar']:.3g} |")
    e = res["mesh_grid_error_m"]
    lines += ["", f"Mesh SDF grid ({e['spacing_m'] * 1e3:g} mm) vs exact point-to-mesh distance: "
              f"max {e['max_m'] * 1e6:.0f} um, RMS {e['rms_m'] * 1e6:.0f} um; within 5 mm of the "
              f"surface max {e['near_max_m'] * 1e6:.0f} um, RMS {e['near_rms_m'] * 1e6:.0f} um."]
    return "\n".join(lines) + "\n"


def _lambda_figure(res, out_png):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.5))
    names = [r["object"] for r in res["objects"]]
    x = np.arange(len(names))
    a.bar(x - 0.2, [r["lambda_unipolar_n_per_m"] for r in res["objects"]], 0.4,
          label="unipolar (thesis drive)")
    a.bar(x + 0.2, [r["lambda_bipolar_n_per_m"] for r in res["objects"]], 0.4, label="bipolar")
    a.axhline(6.0, color="k", ls=":", label="thesis: 6 N/m")
    a.set_xticks(x, names, fontsize=9)
    a.set_ylabel("force constant lambda (N/m)")
    a.set_title("lambda (eq. 4.3, 3-D force, 6 A per coil, 54 A total)", fontsize=10)
    a.legend(fontsize=8, loc="lower center", framealpha=0.9)
    a.grid(alpha=0.3, axis="y")
    t = [r["total_current_a"] for r in res["plane_budgets"]]
    b.plot(t, [r["unipolar"] for r in res["plane_budgets"]], "o-", label="unipolar")
    b.plot(t, [r["bipolar"] for r in res["plane_budgets"]], "s-", label="bipolar")
    b.set_xlabel("total-current bound I_t (A)")
    b.set_ylabel("lambda (N/m)")
    b.set_title("flat surface at 50 mm: lambda vs the total-current bound", fontsize=10)
    b.grid(alpha=0.3)
    b.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(out_png, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=80)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out_dir", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--n-side", type=int, default=31)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--figures-only", action="store_true", help="redraw the object figures")
    ap.add_argument("--from-json", action="store_true",
                    help="rewrite the table and the lambda figure from render_thesis.json")
    a = ap.parse_args(argv)
    if a.from_json:
        res = json.loads((Path(a.out_dir) / "render_thesis.json").read_text())
        write_text_atomic(Path(a.out_dir) / "render_thesis.md", table(res))
        _lambda_figure(res, Path(a.out_dir) / "render_lambda.png")
        print(table(res))
    elif a.figures_only:
        figures_only(a.out_dir, n_side=a.n_side)
    else:
        run(a.out_dir, n_side=a.n_side, quick=a.quick)


if __name__ == "__main__":
    main()
