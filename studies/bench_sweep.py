"""Bench: array sweeps (rendering objective) on Dask -- designs per second vs workers.

Runs the same whole-array sweep (pitch x core length x winding outer radius x wire, the
shipped optimized device as the base) serially in this process (reference) and on a
dask.distributed LocalCluster (worker processes, one thread each, BLAS/OpenMP pinned to one
thread) with 1 and 2 workers, and prints designs/s, the speed-up over the serial run and the
CPU the workers actually got (their CPU seconds over wall x workers, from psutil): on this
shared 2-core machine a second worker only helps when a second core is free, and the CPU
share says whether it was. The load average is printed with the numbers.

Usage: ``python studies/bench_sweep.py [OUT_DIR] [--quick]`` (default OUT_DIR out/bench_sweep).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from designkit.support.atomic import write_json_atomic  # noqa: E402
from designkit.design import load_design  # noqa: E402
from designkit.optimize.sweep import ARRAY_PARAMETERS, parse_param, run_array_sweep  # noqa: E402

ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}


def _cpu_seconds(pids) -> float:
    import psutil

    total = 0.0
    for pid in pids:
        t = psutil.Process(pid).cpu_times()
        total += t.user + t.system
    return total


def run(out_dir, quick: bool = False) -> dict:
    from dask.distributed import Client, LocalCluster

    design = load_design("optimized")
    n = 2 if quick else 4
    specs = [f"pitch_m=0.05:0.06:{n}", f"core_length_m=0.05:0.0756:{n}",
             f"outer_radius_m=0.02:0.0243:{n}", "wire_diameter_m=0.0008:0.0009:2"]
    ranges = [parse_param(s, ARRAY_PARAMETERS) for s in specs]
    load0 = os.getloadavg()[0]
    c0, t0 = time.process_time(), time.perf_counter()
    ser = run_array_sweep(design, ranges, workers=1, progress=False)
    cpu = (time.process_time() - c0) / (time.perf_counter() - t0)
    rows = {"serial": {"workers": 1, "designs": len(ser.rows), "seconds": ser.seconds,
                       "designs_per_s": len(ser.rows) / ser.seconds, "cpu_share": cpu}}
    for w in ((2,) if quick else (1, 2)):
        with LocalCluster(n_workers=w, threads_per_worker=1, processes=True,
                          dashboard_address=None, env=ONE_THREAD) as cluster:
            # warm-up: every worker imports designkit/scipy once (not part of the rate)
            run_array_sweep(design, [parse_param("pitch_m=0.05:0.06:" + str(2 * w),
                                                 ARRAY_PARAMETERS)],
                            scheduler=cluster.scheduler_address, chunk_size=1, progress=False)
            with Client(cluster.scheduler_address) as client:
                pids = list(client.run(os.getpid).values())
            c0 = _cpu_seconds(pids)
            res = run_array_sweep(design, ranges, scheduler=cluster.scheduler_address,
                                  progress=False)
            cpu = (_cpu_seconds(pids) - c0) / (res.seconds * w)
        assert [r["force_n"] for r in res.rows] == [r["force_n"] for r in ser.rows]
        rows[f"dask_{w}"] = {"workers": w, "designs": len(res.rows), "seconds": res.seconds,
                             "designs_per_s": len(res.rows) / res.seconds, "cpu_share": cpu}
    for r in rows.values():
        r["speedup_vs_serial"] = r["designs_per_s"] / rows["serial"]["designs_per_s"]
        # per CPU-second the load of other jobs cancels: what each core does when it runs
        r["designs_per_cpu_s"] = r["designs_per_s"] / max(r["cpu_share"] * r["workers"], 1e-9)
    out = {"quick": quick, "load_average_1min_before": load0,
           "load_average_1min_after": os.getloadavg()[0], "cores": os.cpu_count(),
           "parameters": specs, "runs": rows}
    if "dask_1" in rows and "dask_2" in rows:
        out["scaling_2_over_1_workers"] = (rows["dask_2"]["designs_per_s"]
                                           / rows["dask_1"]["designs_per_s"])
        # with two free cores: 2 x the per-core efficiency of the 2-worker run
        out["scaling_2_over_1_if_cores_free"] = (2 * rows["dask_2"]["designs_per_cpu_s"]
                                                 / rows["dask_1"]["designs_per_cpu_s"])
    write_json_atomic(Path(out_dir) / "bench_sweep.json", out)
    print(f"load average (1 min): {load0:.2f} before, {out['load_average_1min_after']:.2f} after;"
          f" {out['cores']} cores shared with other jobs{'  QUICK RUN' if quick else ''}")
    print(f"{'run':<10}{'workers':>8}{'designs':>9}{'seconds':>10}{'designs/s':>11}"
          f"{'x serial':>10}{'CPU share':>11}{'designs/CPU-s':>15}")
    for name, r in rows.items():
        print(f"{name:<10}{r['workers']:>8}{r['designs']:>9}{r['seconds']:>10.2f}"
              f"{r['designs_per_s']:>11.2f}{r['speedup_vs_serial']:>10.2f}"
              f"{r['cpu_share']:>11.2f}{r['designs_per_cpu_s']:>15.2f}")
    if "scaling_2_over_1_workers" in out:
        print(f"2 workers / 1 worker = {out['scaling_2_over_1_workers']:.2f} measured (CPU share "
              f"< 1: the workers waited for a core); "
              f"{out['scaling_2_over_1_if_cores_free']:.2f} with two free cores (per-CPU-second "
              f"rates; ideal 2.00)")
    return out


if __name__ == "__main__":
    from studies._common import study_parser

    a = study_parser(__doc__, ROOT / "out" / "bench_sweep",
                     quick="2 x 2 arrays on 2 workers").parse_args()
    run(a.out, quick=a.quick)
