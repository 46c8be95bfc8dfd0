"""Bench: array sweeps (rendering objective) on Dask -- designs per second vs workers.

Runs the same whole-array sweep (pitch x core length x winding outer radius x wire, the
shipped optimized device as the base) serially in this process (reference) and on a
dask.distributed LocalCluster (worker processes, one thread each) with 1 and 2 workers, and
prints designs/s and the speed-up over the serial run. The machine is shared: the load average
is printed with the numbers.

Usage: ``python studies/bench_sweep.py [OUT_DIR] [--quick]`` (default OUT_DIR out/bench_sweep).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from designkit._io import write_json_atomic  # noqa: E402
from designkit.design import load_design  # noqa: E402
from designkit.sweep import ARRAY_PARAMETERS, parse_param, run_array_sweep  # noqa: E402


def run(out_dir, quick: bool = False) -> dict:
    from dask.distributed import LocalCluster

    design = load_design("optimized")
    n = 2 if quick else 3
    specs = [f"pitch_m=0.05:0.06:{n}", f"core_length_m=0.05:0.0756:{n}",
             f"outer_radius_m=0.02:0.0243:{n}", "wire_diameter_m=0.0008:0.0009:2"]
    ranges = [parse_param(s, ARRAY_PARAMETERS) for s in specs]
    ser = run_array_sweep(design, ranges, workers=1, progress=False)
    rows = {"serial": {"workers": 1, "designs": len(ser.rows), "seconds": ser.seconds,
                       "designs_per_s": len(ser.rows) / ser.seconds}}
    for w in ((2,) if quick else (1, 2)):
        with LocalCluster(n_workers=w, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster:
            # warm-up: every worker imports designkit/scipy once (not part of the rate)
            run_array_sweep(design, [parse_param("pitch_m=0.05:0.06:" + str(2 * w),
                                                 ARRAY_PARAMETERS)],
                            scheduler=cluster.scheduler_address, chunk_size=1, progress=False)
            res = run_array_sweep(design, ranges, scheduler=cluster.scheduler_address,
                                  progress=False)
        assert [r["force_n"] for r in res.rows] == [r["force_n"] for r in ser.rows]
        rows[f"dask_{w}"] = {"workers": w, "designs": len(res.rows), "seconds": res.seconds,
                             "designs_per_s": len(res.rows) / res.seconds}
    for r in rows.values():
        r["speedup_vs_serial"] = r["designs_per_s"] / rows["serial"]["designs_per_s"]
    out = {"quick": quick, "load_average_1min": os.getloadavg()[0], "parameters": specs,
           "runs": rows}
    write_json_atomic(Path(out_dir) / "bench_sweep.json", out)
    print(f"load average (1 min): {out['load_average_1min']:.2f}"
          f"{'  QUICK RUN' if quick else ''}")
    print(f"{'run':<10}{'workers':>8}{'designs':>9}{'seconds':>10}{'designs/s':>11}{'x serial':>10}")
    for name, r in rows.items():
        print(f"{name:<10}{r['workers']:>8}{r['designs']:>9}{r['seconds']:>10.2f}"
              f"{r['designs_per_s']:>11.2f}{r['speedup_vs_serial']:>10.2f}")
    return out


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    run(args[0] if args else ROOT / "out" / "bench_sweep", quick="--quick" in sys.argv)
