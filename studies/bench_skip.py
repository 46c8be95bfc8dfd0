"""Question: what does the runner's coil skip (firmware_io.runner.skip.CoilSkipBound, the
``skip_force_n`` setting) save per control step, and what does it cost in force?

On a map of the default design (``--map``, or one built into OUT_DIR), along the thesis
hemisphere's surface (the 61 x 61 grid's points inside the map, in grid order: neighbouring
steps at neighbouring points) with the constraint force lambda h n (lambda = 6 N/m) minus the
bias F0: per step the law's rows of A(p) and a warm-started allocation, without skipping and
with skip forces of 1 mN .. 1 N (the kept coils only). Reported: the per-step time (each step
the min of 3 passes, then median and p99 over the steps), the coils kept (mean, min), the
force change against no skipping (p95, max), the bound table's start-up time and a 2000 x 2000
matmul of the same process (the machine may be shared).

    python studies/bench_skip.py [OUT_DIR] [--map MAP]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from studies._common import design_and_map, finish, load_average
from studies.bench_constant import matmul_seconds
from designkit.render import Hemisphere
from firmware_io.allocation import Allocator
from firmware_io.mapfile import MapFile
from firmware_io.runner.forcelaw import force_law_rows
from firmware_io.runner.skip import CoilSkipBound

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "bench_skip"
"""Default output folder (git-ignored), whatever the working directory."""

SKIP_FORCES_N = (0.0, 0.001, 0.01, 0.03, 0.1, 0.3, 1.0)


def run(fmap, bound, law, path, target, limits, force):
    """Per-step times (s), coils kept, the force rendered (n, 3) N, with skip force ``force``;
    ``law`` = (rows, matrix) of the force law, ``limits`` = (per-coil limit, total) A."""
    rows, mat = law
    limit, total = limits
    m_norm = float(np.linalg.norm(fmap.moment_a_m2))
    n = len(path)
    best = np.full(n, np.inf)
    kept = np.empty(n, int)
    out = np.empty((n, 3))
    for _ in range(3):
        alloc = Allocator()
        for k in range(n):
            t = time.perf_counter()
            keep = bound.keep(path[k], limit, force, m_norm) if force > 0 else None
            fm = mat @ fmap.actuation(path[k], rows=rows, coils=keep)
            cur, _ = alloc(fm, target[k], limit if keep is None else limit[keep], total)
            best[k] = min(best[k], time.perf_counter() - t)
            kept[k] = fm.shape[1]
            out[k] = fm @ cur
    return best, kept, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(DEFAULT_OUT))
    ap.add_argument("--map", default=None, help="map file of the default design (.npz)")
    args = ap.parse_args(argv)
    out, design, _, map_path = design_and_map(args.out, args.map, progress=False)
    fmap = MapFile.load(map_path)
    obj = Hemisphere()
    pts, nrm = obj.surface_points(61)
    lo, hi = (np.asarray(b) for b in fmap.bounds)
    inside = np.all((pts >= lo) & (pts <= hi), axis=1)
    path, nrm = pts[inside], nrm[inside]
    target = 6.0 * obj.height(path)[:, None] * nrm - fmap.bias_force(path)
    rows, mat = force_law_rows(fmap.moment_a_m2, "xyz")
    limit = np.full(fmap.n_coils, design.drive.max_current_a)
    total = design.drive.total_current_a
    mm = matmul_seconds()
    t0 = time.perf_counter()
    bound = CoilSkipBound(fmap)
    table_s = time.perf_counter() - t0
    res = {"steps": len(path), "matmul_2000_s": mm, "load_average_1min": load_average(),
           "bound_table_s": table_s, "rows": []}
    ref = None
    for force in SKIP_FORCES_N:
        t, kept, f = run(fmap, bound, (rows, mat), path, target, (limit, total), force)
        ref = f if ref is None else ref
        miss = np.linalg.norm(f - ref, axis=1)
        res["rows"].append({"skip_force_n": force, "median_us": 1e6 * float(np.median(t)),
                            "p99_us": 1e6 * float(np.percentile(t, 99)),
                            "coils_kept_mean": float(kept.mean()), "coils_kept_min": int(kept.min()),
                            "force_change_p95_n": float(np.percentile(miss, 95)),
                            "force_change_max_n": float(miss.max())})
    return finish(Path(out) / "bench_skip.json", res, _print)


_COLS = ("skip force mN", "median us", "p99 us", "coils kept", "kept min", "dF p95 mN",
         "dF max mN")


def _print(r):
    print(f"{r['steps']} steps over the hemisphere; 2000 x 2000 matmul {r['matmul_2000_s']:.3f} "
          f"s; load average {r['load_average_1min']}; bound table {r['bound_table_s']:.2f} s")
    print("".join(f"{c:>14}" for c in _COLS))
    for x in r["rows"]:
        vals = (1e3 * x["skip_force_n"], x["median_us"], x["p99_us"], x["coils_kept_mean"],
                x["coils_kept_min"], 1e3 * x["force_change_p95_n"], 1e3 * x["force_change_max_n"])
        print("".join(f"{v:>14.4g}" for v in vals))


if __name__ == "__main__":
    main()
