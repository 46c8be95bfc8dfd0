"""Bench: does one BLAS thread speed up designkit's hot paths (designkit.support.blas)?

The coupled core solve and the device optimizer are built of many small dense products;
a threaded BLAS wakes its threads for each, and on a busy machine they wait for a core longer than
they compute. Each case runs with the limit (designkit as shipped) and without it (the limit
replaced by a no-op, the BLAS library's default threads), alternating, ``repeats`` times; every run in
a fresh process, because the core models are cached in-process and a second run in one process
would be faster for that reason alone. Prints the median seconds and the ratio default / one
thread with the load average (the machine is shared: say so with the numbers).

Usage: ``python studies/bench_blas.py [OUT_DIR] [--quick]`` (default OUT_DIR out/bench_blas).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from designkit.support.atomic import write_json_atomic  # noqa: E402

_CHILD = """
import contextlib, json, sys, time
import numpy as np
import designkit.support.blas as blas, designkit.cores.coupled, designkit.optimize as op
if sys.argv[1] == "default":
    # every module that took the limit by name gets the no-op instead
    for mod in list(sys.modules.values()):
        if getattr(mod, "one_blas_thread", None) is blas.one_blas_thread:
            mod.one_blas_thread = contextlib.nullcontext
from designkit.model.array import CoilArray
from designkit.design import default_design
d = default_design()
if sys.argv[3] == "quick":
    d = d.replace(**{"array.rows": 1, "array.columns": 2})
t0 = time.perf_counter()
if sys.argv[2] == "array build":
    arr = CoilArray.from_design(d)
    arr.actuation_matrix(np.array([[0.0, 0.0, 0.03]]))
else:
    op.solve_device(op.DeviceProblem.from_design(d), starts=2)
print(json.dumps(time.perf_counter() - t0))
"""

CASES = ("array build", "solve_device")
"""'array build': the 3 x 3 coupled array's assembly and factorization and one
actuation matrix; 'solve_device': the device optimizer, 2 starts."""


def _seconds(mode: str, case: str, quick: bool) -> float:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    res = subprocess.run([sys.executable, "-c", _CHILD, mode, case, "quick" if quick else "full"],
                         cwd=ROOT, env=env, capture_output=True, text=True, check=True)
    return float(json.loads(res.stdout.strip().splitlines()[-1]))


def run(out_dir, quick: bool = False, repeats: int = 3) -> dict:
    cases = CASES[:1] if quick else CASES
    repeats = 1 if quick else repeats
    load = os.getloadavg()[0]
    rows = {}
    for case in cases:
        runs = {"one_thread": [], "default": []}
        for _ in range(repeats):
            for mode in ("one_thread", "default"):
                runs[mode].append(_seconds(mode, case, quick))
        med = {m: float(np.median(v)) for m, v in runs.items()}
        rows[case] = {"seconds": runs, "median_s": med,
                      "default_over_one_thread": med["default"] / med["one_thread"]}
    end = os.getloadavg()[0]
    table = [f"load average (1 min): {load:.2f} -> {end:.2f}{'  QUICK RUN' if quick else ''}",
             f"{'case':<14}{'one thread s':>14}{'default s':>12}{'default/one':>13}"]
    table += [f"{case:<14}{r['median_s']['one_thread']:>14.2f}{r['median_s']['default']:>12.2f}"
              f"{r['default_over_one_thread']:>13.2f}" for case, r in rows.items()]
    print("\n".join(table))
    out = {"quick": quick, "repeats": repeats, "load_average_1min_start": load,
           "load_average_1min_end": end, "cases": rows}
    write_json_atomic(Path(out_dir) / "bench_blas.json", out)
    return out

if __name__ == "__main__":
    from studies._common import study_parser

    a = study_parser(__doc__, ROOT / "out" / "bench_blas",
                     quick="a 1 x 2 array, fewer repeats").parse_args()
    run(a.out, quick=a.quick)
