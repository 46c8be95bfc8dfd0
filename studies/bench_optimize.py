"""Bench: is the real device (winding + wire + 1010-steel core, every constraint) solved in
<= 5 s, and is the optimum global?

Timed target: :func:`designkit.optimize.solve_device` on the default design (4 starts), median
of 3 runs, with the panel model's cache cleared before each run (no run reuses another's core
solutions). Reference in the same process: one evaluation of the saturating panel model (what a
naive optimizer would pay per point) and, in the full run, the legacy coil-only optimizer with
the linear surface-current core (``CoilDesignProblem(core_model='surface-current')``).
Full run also: :func:`designkit.optimize.verify_device` (multistart, ISRES, grid).
The load average is printed with the timings: this machine is shared, so the solve's CPU
seconds (one thread: the wall time it would take on an idle core) are printed too.

Usage: ``python studies/bench_optimize.py [OUT_DIR] [--quick]`` (default OUT_DIR out/bench_optimize).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from designkit import default_design  # noqa: E402
from designkit.support.blas import one_blas_thread  # noqa: E402
from designkit.cores import panel  # noqa: E402
from designkit.optimize import (CoilDesignProblem, device_problem_for, solve,  # noqa: E402
                                solve_device, verify_device)
from studies._common import finish  # noqa: E402


def _clear_caches():
    panel._solve_nonlinear.cache_clear()
    panel._solve_linear.cache_clear()


def run(out_dir, quick: bool = False) -> dict:
    out = Path(out_dir)
    design = default_design()
    problem = device_problem_for(design)
    starts = 1 if quick else 4
    repeats = 1 if quick else 3
    if not quick:  # imports and first-call setup only (a quick run's time includes them)
        solve_device(problem, starts=1, max_corrections=1)
    times, cpu, results = [], [], []
    for _ in range(repeats):
        _clear_caches()
        t0, c0 = time.perf_counter(), time.process_time()
        res = solve_device(problem, starts=starts, max_corrections=2 if quick else 4)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        results.append(res)
    best = results[-1]
    d = best.as_dict(problem)
    panel_s = None
    if not quick:  # reference: one saturating panel-model evaluation at the optimum
        _clear_caches()
        with one_blas_thread():  # as inside solve_device (threads thrash a loaded machine)
            t0 = time.perf_counter()
            problem.evaluate(best.x, turns=best.turns, model="panel")
            panel_s = time.perf_counter() - t0
    out_d = {
        "quick": quick, "load_average_1min": os.getloadavg()[0], "target_seconds": 5.0,
        "device_seconds": times, "device_median_seconds": float(np.median(times)),
        # CPU seconds of the one-threaded solve: what the wall time is on an idle core
        "device_cpu_seconds": cpu, "device_median_cpu_seconds": float(np.median(cpu)),
        "starts": starts, "fast_evaluations": best.fast_evaluations,
        "panel_evaluations": best.panel_evaluations,
        "panel_evaluation_seconds": panel_s,
        "force_n": d["force_n"], "margins": d["margins"], "feasible": best.feasible,
        "corrections": d["corrections"], "fast_model_check": d["fast_model_check"],
        "optimum": {k: d[k] for k in ("inner_radius_m", "outer_radius_m", "length_m", "turns",
                                      "wire_diameter_m", "core_radius_m", "core_length_m",
                                      "core_protrusion_m", "resistance_ohm", "inductance_h",
                                      "settling_time_s")},
    }
    if not quick:
        t0 = time.perf_counter()
        ver = verify_device(problem, best)
        out_d["verification"] = {k: ver[k] for k in ("agree", "multistart_agree", "isres_agree",
                                                     "grid_not_better", "best_n", "evaluations",
                                                     "seconds")}
        out_d["verification"]["stages"] = {k: ver[k] for k in ("multistart", "isres", "grid")}
        legacy = CoilDesignProblem.from_design(design, core_model="surface-current")
        _clear_caches()
        with one_blas_thread():
            t0 = time.perf_counter()
            res = solve(legacy, starts=2, thesis_point=False)
            out_d["legacy_linear_core_seconds_2_starts"] = time.perf_counter() - t0
        out_d["legacy_linear_core_force_n"] = res.best.force_n
    out_d["ratio_device_to_target"] = out_d["device_median_seconds"] / 5.0
    if panel_s:
        # load-independent-ish: the whole device solve in units of one panel evaluation
        out_d["ratio_device_to_panel_evaluation"] = out_d["device_median_seconds"] / panel_s
    if "legacy_linear_core_seconds_2_starts" in out_d:
        out_d["ratio_device_to_legacy"] = (out_d["device_median_seconds"]
                                           / out_d["legacy_linear_core_seconds_2_starts"])
    return finish(out / "bench_optimize.json", out_d, _print)


def _print(r: dict) -> None:
    print(f"load average (1 min): {r['load_average_1min']:.2f}  {'QUICK RUN (1 start, 2 panel evaluations at most, imports included)' if r['quick'] else ''}")
    print(f"{'case':<52}{'seconds':>10}")
    for i, t in enumerate(r["device_seconds"]):
        print(f"{'device problem, run ' + str(i + 1):<52}{t:>10.2f}")
    print(f"{'device problem, median (target 5 s)':<52}{r['device_median_seconds']:>10.2f}")
    print(f"{'device problem, median CPU seconds (= idle wall time)':<52}"
          f"{r['device_median_cpu_seconds']:>10.2f}")
    if r["panel_evaluation_seconds"] is not None:
        print(f"{'one saturating panel-model evaluation (reference)':<52}"
              f"{r['panel_evaluation_seconds']:>10.2f}")
    if "legacy_linear_core_seconds_2_starts" in r:
        print(f"{'legacy linear-core coil optimizer, 2 starts':<52}"
              f"{r['legacy_linear_core_seconds_2_starts']:>10.2f}")
    for key, what in (("ratio_device_to_panel_evaluation", "one panel evaluation"),
                      ("ratio_device_to_legacy", "the legacy linear-core optimizer")):
        if key in r:
            print(f"median / {what} = {r[key]:.2f}")
    print(f"median / target = {r['ratio_device_to_target']:.2f}; {r['fast_evaluations']} fast + "
          f"{r['panel_evaluations']} panel evaluations; upward Fz {r['force_n'] * 1e3:.1f} mN; "
          f"feasible {r['feasible']}")
    chk = r["fast_model_check"]
    print(f"fast model at the optimum vs the panel model: corrected "
          f"{chk['force_rel_err'] * 100:+.2f} % force, {chk['inductance_rel_err'] * 100:+.2f} % "
          f"inductance (bound {chk['bound_rel'] * 100:g} %, met: {chk['within_bound']}); "
          f"uncorrected {chk['uncorrected_force_rel_err'] * 100:+.1f} % / "
          f"{chk['uncorrected_inductance_rel_err'] * 100:+.1f} %")
    if "verification" in r:
        v = r["verification"]
        st = v["stages"]
        print(f"{'global check (corrected fast model)':<36}{'best (mN)':>12}{'evaluations':>13}"
              f"{'seconds':>10}")
        print(f"{'multistart, ' + str(st['multistart']['starts']) + ' SLSQP starts':<36}"
              f"{(st['multistart']['best_n'] or 0) * 1e3:>12.2f}"
              f"{st['multistart']['evaluations']:>13}{st['multistart']['seconds']:>10.1f}")
        print(f"{'ISRES ' + str(st['isres']['evaluations_requested']) + ' + SLSQP polish':<36}"
              f"{st['isres']['polished_value_n'] * 1e3:>12.2f}{st['isres']['evaluations']:>13}"
              f"{st['isres']['seconds']:>10.1f}")
        print(f"{'grid ' + str(st['grid']['levels']) + '^6 = ' + str(st['grid']['designs']):<36}"
              f"{(st['grid']['best_n'] or 0) * 1e3:>12.2f}{st['grid']['evaluations']:>13}"
              f"{st['grid']['seconds']:>10.1f}")
        print(f"verified global: {v['agree']} (multistart agree {v['multistart_agree']}, ISRES "
              f"agree {v['isres_agree']}, grid not better {v['grid_not_better']}; "
              f"{v['evaluations']} evaluations, {v['seconds']:.1f} s)")


if __name__ == "__main__":
    from studies._common import study_parser

    a = study_parser(__doc__, ROOT / "out" / "bench_optimize",
                     quick="one start, one repeat").parse_args()
    run(a.out, quick=a.quick)
