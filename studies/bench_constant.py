"""Question: what does the force constant (thesis eq. 4.3) cost per surface point, from the
reachable set's faces (the default) against the secant search on the allocator (the
reference), and do they agree?

Source: a map file of the default design (``--map``, or one built into OUT_DIR). Objects: the
thesis plane (61 x 61 = 3721 points) and the hemisphere (31 x 31 grid), unipolar and bipolar,
per-coil limit 6 A and budgets 54 A (the design's: never binding) and 20 A (binding).

* whole ``force_constant`` call, default path: median of 3, ms per evaluated point;
* the per-point lambda alone on the same precomputed force matrices: faces (median of 3) and
  secant (once, on every ``--ref-stride``-th point), ms per point and their ratio; the largest
  relative difference of the two on those points (the secant stops within 1e-6 below);
* the time of a 2000 x 2000 float64 matmul in the same process, to scale to another machine,
  and the 1-minute load average (the machine may be shared: the ratios are the portable part).

    python studies/bench_constant.py [OUT_DIR] [--map MAP] [--ref-stride N] [--quick]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from studies._common import design_and_map, finish, load_average
from designkit import fieldmap
from designkit.render import Hemisphere, Plane, force_constant
from designkit.render.constant import _faces_lambdas, _secant_lambdas, force_matrices

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "bench_constant"
"""Default output folder (git-ignored), whatever the working directory."""


def matmul_seconds(n: int = 2000) -> float:
    """Min of 3 of an n x n float64 matmul, s."""
    a = np.random.default_rng(0).normal(size=(n, n))
    ts = []
    for _ in range(3):
        t = time.perf_counter()
        a @ a
        ts.append(time.perf_counter() - t)
    return min(ts)


def _median_time(fn, repeats=3):
    ts = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts), out


def case(obj, n_side, source, unipolar, tl, stride):
    """One row: whole call and per-point kernels, faces against secant."""
    kw = dict(current_limit_a=6.0, total_current_a=tl, unipolar=unipolar, n_side=n_side,
              progress=False)
    t_call, fc = _median_time(lambda: force_constant(obj, source, **kw))
    pts = fc.points_m
    d = fc.heights_m[:, None] * fc.normals
    fms = force_matrices(source, pts, "force")
    bias = source.bias_force(pts)
    u = np.full(fms.shape[2], 6.0)
    t_faces, lam_f = _median_time(lambda: _faces_lambdas(fms, d, bias, u, tl, unipolar, 1e-6,
                                                         False))
    sub = slice(None, None, stride)
    t = time.perf_counter()
    lam_s = _secant_lambdas(fms[sub], d[sub], bias[sub], u, tl, unipolar, 1e-6, False)
    t_sec = time.perf_counter() - t
    a, b = lam_f[sub], lam_s
    fin = np.isfinite(b) & (b > 0)
    diff = float(np.max(np.abs(a[fin] - b[fin]) / b[fin])) if fin.any() else 0.0
    same = bool(np.array_equal(a == 0, b == 0) and np.array_equal(np.isinf(a), np.isinf(b)))
    n, ns = len(pts), len(b)
    return {"object": type(obj).__name__, "points": n, "unipolar": unipolar, "budget_a": tl,
            "lambda_n_per_m": fc.lam_n_per_m, "call_ms_per_point": 1e3 * t_call / n,
            "faces_ms_per_point": 1e3 * t_faces / n, "secant_ms_per_point": 1e3 * t_sec / ns,
            "secant_points": ns, "ratio_secant_over_faces": (t_sec / ns) / (t_faces / n),
            "max_rel_diff": diff, "same_zero_inf_pattern": same}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(DEFAULT_OUT))
    ap.add_argument("--map", default=None, help="map file of the default design (.npz)")
    ap.add_argument("--ref-stride", type=int, default=8,
                    help="secant reference on every N-th surface point (default 8)")
    ap.add_argument("--quick", action="store_true", help="plane and hemisphere at 11 x 11")
    args = ap.parse_args(argv)
    out, design, _, map_path = design_and_map(args.out, args.map, progress=False)
    source = fieldmap.load(map_path, design)
    mm = matmul_seconds()
    sides = (11, 11) if args.quick else (61, 31)
    rows = [case(obj, ns, source, uni, tl, args.ref_stride)
            for obj, ns in ((Plane(), sides[0]), (Hemisphere(), sides[1]))
            for uni in (True, False) for tl in (54.0, 20.0)]
    return finish(Path(out) / "bench_constant.json",
                  {"matmul_2000_s": mm, "load_average_1min": load_average(), "rows": rows},
                  _print)


def _print(r):
    print(f"2000 x 2000 matmul {r['matmul_2000_s']:.3f} s; load average "
          f"{r['load_average_1min']}")
    print(f"{'object':<11}{'pts':>6} {'drive':<9}{'I_t A':>6}{'lambda N/m':>12}"
          f"{'call ms/pt':>11}{'faces ms/pt':>12}{'secant ms/pt':>13}{'ratio':>8}"
          f"{'max rel diff':>13}")
    for x in r["rows"]:
        print(f"{x['object']:<11}{x['points']:>6} "
              f"{'unipolar' if x['unipolar'] else 'bipolar':<9}{x['budget_a']:>6.0f}"
              f"{x['lambda_n_per_m']:>12.5g}{x['call_ms_per_point']:>11.3f}"
              f"{x['faces_ms_per_point']:>12.3f}{x['secant_ms_per_point']:>13.3f}"
              f"{x['ratio_secant_over_faces']:>8.1f}{x['max_rel_diff']:>13.1e}"
              + ("" if x["same_zero_inf_pattern"] else "  (0/inf differ)"))


if __name__ == "__main__":
    main()
