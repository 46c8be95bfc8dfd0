"""Question: how much time do scenes save by computing only what is asked, skipping coils that
cannot matter and sharing one (rho, z) table per coil type -- and what error does that cost?

For the default array (thesis device, with its core) on the default workspace grid (the
workspace box at 5 mm spacing), three output sets are evaluated in one run:

* full A (B and the 5 gradient rows, per ampere and coil),
* force only (3 components per ampere and coil on the thesis magnet, m = 0.909 A m^2 along z),
* Fz only (needs only dBz/dz),

each five ways: direct (Coil.field, no skipping), skipping only, tables only (always),
tables + skipping, and 'auto' (tables only where they pay, plus skipping).
The reference is CoilArray.actuation_matrix (direct, rtol 1e-10), from which force and Fz
follow by F(m) (thesis eq. 2.5). Errors are the largest |error| per output row divided by that
row's largest |value| over the grid. Speed-ups are against the direct evaluation of the same
output set and against the reference full A, measured in this process.

``--map``: the scene map instead -- the full map against the scene map of the thesis hemisphere
(build time wall and CPU, file size, A, bias-force and sensor-field errors in the scene's region,
the same-process 2000 x 2000 matmul): :func:`studies.bench_map.scene_vs_full`.

    python studies/bench_scene.py [OUT_DIR] [--map [N_POINTS]]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit import default_design
from designkit.support.atomic import write_json_atomic
from designkit.model.array import CoilArray, force_matrix
from designkit.model.skipping import SkippingEvaluator as Scene
from studies.bench_map import report_scene, scene_vs_full  # noqa: E402

VARIANTS = {"direct": ("never", "never"), "skip": ("never", "bound"),
            "tables": ("always", "never"), "tables+skip": ("always", "bound"),
            "auto": ("auto", "bound")}
SETS = {"full A": ("B", "gradient"), "force": ("force",), "Fz": ("fz",)}


def workspace_grid(design, spacing):
    ws = design.workspace
    xs = np.arange(-ws.half_width_m, ws.half_width_m + 1e-12, spacing)
    zs = np.arange(ws.z_min_m, ws.z_max_m + 1e-12, spacing)
    X, Y, Z = np.meshgrid(xs, xs, zs, indexing="ij")
    return np.c_[X.ravel(), Y.ravel(), Z.ravel()]


def _rel_err(got, ref):
    axes = tuple(k for k in range(ref.ndim) if k != 1) if ref.ndim == 3 else None
    err = np.abs(got - ref).max(axis=axes)
    scale = np.abs(ref).max(axis=axes)
    return float(np.max(err / scale))


def run(out_dir, quick: bool = False, tolerances=(1e-3, 1e-4), spacing: float = 0.005) -> dict:
    out_dir = Path(out_dir)
    design = default_design()
    if quick:  # air coils and a coarse grid: seconds, same code paths
        design = design.replace(core=None)
        spacing = 0.02
    arr = CoilArray.from_design(design)
    pts = workspace_grid(design, spacing)
    m = design.magnet.moment_vector_a_m2
    t0 = time.perf_counter()
    a_ref = arr.actuation_matrix(pts)
    t_ref = time.perf_counter() - t0
    f_ref = np.einsum("rk,nkc->nrc", force_matrix(m), a_ref[:, 3:])
    refs = {"full A": a_ref, "force": f_ref, "Fz": f_ref[:, 2]}
    rows = []
    cases = [(tol, s, o, v, t, k) for tol in tolerances for s, o in SETS.items()
             for v, (t, k) in VARIANTS.items()]
    t_direct = 1.0
    for tolerance, set_name, outs, var, tables, skip in cases:  # 'direct' comes first per set
        sc = Scene(arr, pts, outs, moment=m, tolerance=tolerance, tables=tables, skip=skip)
        t0 = time.perf_counter()
        res = sc.evaluate()
        dt = time.perf_counter() - t0
        got = res.actuation() if set_name == "full A" else res[outs[0]]
        if var == "direct":
            t_direct = dt
        rows.append({"tolerance": tolerance, "outputs": set_name, "variant": var,
                     "time_s": dt,
                     "speedup_vs_direct_same_outputs": t_direct / dt,
                     "speedup_vs_reference_full_A": t_ref / dt,
                     "max_rel_error": _rel_err(got, refs[set_name]),
                     "skipped_fraction": res.stats["skipped"] / res.stats["pairs"],
                     "table_nodes": res.stats["table_nodes"]})
    out = {"n_points": len(pts), "n_coils": arr.n_coils, "spacing_m": spacing,
           "tolerances": list(tolerances), "core": design.core is not None,
           "reference_full_A_time_s": t_ref, "rows": rows}
    write_json_atomic(out_dir / "bench_scene.json", out)
    return out


def _print(res):
    print(f"{res['n_points']} points x {res['n_coils']} coils, spacing "
          f"{res['spacing_m'] * 1e3:g} mm, core={res['core']}; "
          f"reference full A (CoilArray.actuation_matrix): {res['reference_full_A_time_s']:.2f} s")
    print(f"{'tol':6} {'outputs':8} {'variant':12} {'time s':>8} {'x direct':>9} {'x ref A':>8} "
          f"{'max rel err':>12} {'skipped':>8} {'nodes':>7}")
    for r in res["rows"]:
        print(f"{r['tolerance']:6.0e} {r['outputs']:8} {r['variant']:12} {r['time_s']:8.3f} "
              f"{r['speedup_vs_direct_same_outputs']:9.1f} {r['speedup_vs_reference_full_A']:8.1f} "
              f"{r['max_rel_error']:12.2e} {r['skipped_fraction']:8.1%} {r['table_nodes']:7d}")


if __name__ == "__main__":
    from studies._common import study_parser

    ap = study_parser(__doc__, Path(__file__).resolve().parents[1] / "out" / "bench_scene",
                      quick="air coils and a coarse grid (a smoke test)")
    ap.add_argument("n", nargs="?", type=int, default=2000,
                    help="with --map: points of the error comparison (default 2000)")
    ap.add_argument("--map", action="store_true",
                    help="the scene map against the full map (time, size, error, the floor)")
    a = ap.parse_args()
    if a.map:
        report_scene(scene_vs_full(a.out, a.n))
    else:
        _print(run(a.out, quick=a.quick))
    print(f"written to {a.out}")
