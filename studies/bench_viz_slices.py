"""Question: what does a figure's slice cost with the windings at a picture's tolerance
(designkit.viz.array_field(tolerance=PICTURE_TOLERANCE), the skipping evaluator) against the
exact coupled model, and where does the time go?  The coupled cores' part alone in CPU time
of this process (min of ``--repeats``: less noisy than the wall clock on a shared machine).

On the points of ``designkit.viz.slice_data``'s two slices (vertical y = 0 and horizontal at
the design height) at the given quality: array_field exact and at the picture tolerance (min
of ``--repeats``), the coupled cores' part alone, the largest difference relative to the
largest value, and a 2000 x 2000 matmul of the same process (the machine may be shared).

The field lines' volume (``designkit.viz.field_line_data``'s grid) likewise: array_field
exact against FIELDLINE_TOLERANCE, B only.

    python studies/bench_viz_slices.py [OUT_DIR] [--quality quick|full] [--repeats N]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from studies._common import finish, load_average
from studies.bench_constant import matmul_seconds
from designkit import default_design
from designkit.model.array import array_for_design
from designkit.viz.common import GRID_POINTS
from designkit.viz.physics import (FIELDLINE_TOLERANCE, PICTURE_TOLERANCE, footprint_half_m,
                                   array_field, resolve_currents)

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "bench_viz_slices"
"""Default output folder (git-ignored), whatever the working directory."""


def slice_points(design, quality):
    """The two slices' points (as slice_data lays them out), (n, 3) m."""
    nx, nz = GRID_POINTS[quality]["slice"]
    half = footprint_half_m(design)
    x = np.linspace(-half, half, nx)
    vert = np.stack(np.meshgrid(x, [0.0], np.linspace(0.002, design.workspace.z_max_m, nz),
                                indexing="ij"), -1).reshape(-1, 3)
    horiz = np.stack(np.meshgrid(x, x, [design.optimize.height_m], indexing="ij"),
                     -1).reshape(-1, 3)
    return np.concatenate([vert, horiz])


def volume_points(design, quality):
    """The field lines' volume grid (as field_line_data lays it out), (n, 3) m."""
    half = footprint_half_m(design) + 0.02
    lo = (-half, -half, -design.coil.length_m - 0.03)
    hi = (half, half, design.workspace.z_max_m + 0.03)
    axes = [np.linspace(a, b, d) for a, b, d in zip(lo, hi, GRID_POINTS[quality]["volume"])]
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


def _best(fn, repeats, clock=time.perf_counter):
    ts = []
    for _ in range(repeats):
        t = clock()
        out = fn()
        ts.append(clock() - t)
    return min(ts), out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(DEFAULT_OUT))
    ap.add_argument("--quality", default="quick", choices=("quick", "full"))
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    design = default_design()
    arr = array_for_design(design)
    system = arr.coupled()
    pts = slice_points(design, args.quality)
    cur = resolve_currents(design)
    mm = matmul_seconds()
    t_exact, (b0, g0) = _best(lambda: array_field(design, pts, cur), args.repeats)
    t_pic, (b1, g1) = _best(lambda: array_field(design, pts, cur,
                                                tolerance=PICTURE_TOLERANCE), args.repeats)
    x = system.coil_solution()
    t_core, _ = _best(lambda: system.core_field(pts, x, gradient=True, coil_columns=True),
                      args.repeats, time.process_time)
    vol = volume_points(design, args.quality)
    t_vol, v0 = _best(lambda: array_field(design, vol, cur, gradient=False), args.repeats)
    t_vol_tol, v1 = _best(lambda: array_field(design, vol, cur, gradient=False,
                                              tolerance=FIELDLINE_TOLERANCE), args.repeats)
    res = {"quality": args.quality, "points": len(pts), "matmul_2000_s": mm,
           "volume_points": len(vol), "volume_exact_s": t_vol, "volume_tolerance_s": t_vol_tol,
           "volume_tolerance": FIELDLINE_TOLERANCE,
           "volume_err_rel_max": float(np.max(np.abs(v1 - v0)) / np.max(np.abs(v0))),
           "load_average_1min": load_average(), "exact_s": t_exact, "picture_s": t_pic,
           "cores_cpu_s": t_core,
           "ratio_exact_over_picture": t_exact / t_pic,
           "b_err_rel_max": float(np.max(np.abs(b1 - b0)) / np.max(np.abs(b0))),
           "g_err_rel_max": float(np.max(np.abs(g1 - g0)) / np.max(np.abs(g0)))}
    Path(args.out).mkdir(parents=True, exist_ok=True)
    return finish(Path(args.out) / "bench_viz_slices.json", res, _print)


def _print(r):
    print(f"{r['points']} slice points ({r['quality']}); 2000 x 2000 matmul "
          f"{r['matmul_2000_s']:.3f} s; load average {r['load_average_1min']}")
    print(f"exact {r['exact_s']:.2f} s, picture tolerance {r['picture_s']:.2f} s (ratio "
          f"{r['ratio_exact_over_picture']:.2f}); max error / max: B {r['b_err_rel_max']:.1e}, "
          f"grad B {r['g_err_rel_max']:.1e}")
    print(f"coupled cores alone (B + G, CPU s): {r['cores_cpu_s']:.2f}")
    print(f"field lines' volume, {r['volume_points']} points, B: exact {r['volume_exact_s']:.2f} s, "
          f"at tolerance {r['volume_tolerance']:.0e} {r['volume_tolerance_s']:.2f} s (ratio "
          f"{r['volume_exact_s'] / r['volume_tolerance_s']:.2f}); max error / max "
          f"{r['volume_err_rel_max']:.1e}")


if __name__ == "__main__":
    main()
