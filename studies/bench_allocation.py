"""Question: is firmware_io.allocation.allocate exact and fast enough for the control loop?

Random 9-coil problems on the default design: random magnet positions in the workspace with the
real A(p) (designkit.CoilArray, default core), rows Fz / force / force+torque, targets from 2 %
to 5x the reachable scale (inside and outside the reachable set), random per-coil limits
(0..6 A, or 6 A) and budgets (0.5..60 A or none), unipolar and bipolar.

* Speed, cold (``n_time`` problems, one solve each, perf_counter): median and p99 per solve on
  the random mix and on the design's own limits (6 A per coil, 54 A budget: never binding),
  against scipy.optimize.lsq_linear on the box-only version of the same problems, same process.
  Each problem is timed 3 times: the first pass is the one-run figure; the per-problem minimum
  of the 3 is also given, because on a shared machine a solve preempted by another process
  shows up as an outlier of several milliseconds that is not the allocator's.
* Speed, warm (the control loop): a smooth 1 kHz path of the magnet (about 0.1 m/s) with smooth
  targets, solved cold by ``allocate`` and warm by ``Allocator`` (the last final face as the
  start); the answers must agree (max difference reported).
* Exactness here: on ``n_kkt`` problems the KKT certificate (studies/alloc_reference.py, 1e-9
  relative) and bound violations (> 1e-9 A); on ``n_verify`` problems the objective against
  scipy SLSQP. The 1e5-problem independent check is studies/allocation_check.py.

    python studies/bench_allocation.py [OUT_DIR] [--n-time N] [--n-kkt N] [--n-verify N] [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
from scipy.optimize import lsq_linear

from studies.alloc_reference import kkt_violation, slsqp_reference
from designkit import default_design
from designkit.support.atomic import write_json_atomic
from designkit.support.progress import tqdm
from designkit.model.array import CoilArray, force_matrix, skew_matrix
from designkit.support.blas import one_blas_thread  # the control loop's setting; fair to lsq_linear
from firmware_io.allocation import Allocator, allocate

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "bench_allocation"
"""Default output folder (git-ignored), whatever the working directory."""


ROWS = {1: [2], 3: [0, 1, 2], 6: [0, 1, 2, 3, 4, 5]}


def wrenches(n_pos: int, seed: int = 0, design=None) -> np.ndarray:
    """(n_pos, 6, n_coils) force and torque per ampere at random workspace points."""
    d = design or default_design()
    rng = np.random.default_rng(seed)
    ws = d.workspace
    h = ws.half_width_m
    pts = rng.uniform([-h, -h, ws.z_min_m], [h, h, ws.z_max_m], (n_pos, 3))
    a = CoilArray.from_design(d).actuation_matrix(pts, rtol=1e-7)
    m = np.asarray(d.magnet.moment_vector_a_m2)
    return np.concatenate([force_matrix(m) @ a[:, 3:, :], skew_matrix(m) @ a[:, :3, :]], axis=1)


def problems(w: np.ndarray, n: int, seed: int, design_limits: bool = False):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        k = int(rng.choice([1, 3, 6]))
        fm = w[rng.integers(len(w))][ROWS[k]]
        uni = bool(rng.integers(2))
        if design_limits:
            u, tl = 6.0, 54.0
        else:
            u = rng.uniform(0.0, 6.0, fm.shape[1]) if rng.random() < 0.5 else 6.0
            tl = float(rng.choice([rng.uniform(0.5, 20.0), rng.uniform(20, 60), np.inf]))
        reach = np.abs(fm).sum(axis=1) * 6.0
        f = rng.normal(size=k) * reach * rng.choice([0.02, 0.2, 1.0, 5.0])
        out.append((fm, f, u, tl, uni))
    return out


def _times(probs):
    t = np.empty(len(probs))
    for i, (fm, f, u, tl, uni) in enumerate(probs):
        t0 = time.perf_counter()
        allocate(fm, f, u, tl, unipolar=uni)
        t[i] = time.perf_counter() - t0
    return t


def path_problems(n_steps: int, design=None):
    """A smooth 1 kHz path (n_steps, ~0.1 m/s) with smooth targets: (name, [(F, f, u, I_t,
    unipolar)] per step) for 3-D bipolar (design limits, and a 12 A budget with targets near
    reach), Fz unipolar and force+torque bipolar (20 A budget)."""
    d = design or default_design()
    ws = d.workspace
    h = ws.half_width_m
    t = np.arange(n_steps) * 1e-3
    pts = np.stack([0.7 * h * np.sin(2 * np.pi * 0.37 * t),
                    0.7 * h * np.sin(2 * np.pi * 0.23 * t + 1.0),
                    ws.z_min_m + (ws.z_max_m - ws.z_min_m)
                    * (0.5 + 0.4 * np.sin(2 * np.pi * 0.31 * t))], axis=1)
    a = CoilArray.from_design(d).actuation_matrix(pts, rtol=1e-7)
    m = np.asarray(d.magnet.moment_vector_a_m2)
    w = np.concatenate([force_matrix(m) @ a[:, 3:, :], skew_matrix(m) @ a[:, :3, :]], axis=1)
    out = []
    for name, rows, uni, tl, amp in (("3-D, bipolar, 6 A / 54 A", [0, 1, 2], False, 54.0, 0.5),
                                     ("3-D, bipolar, 6 A / 12 A", [0, 1, 2], False, 12.0, 1.0),
                                     ("Fz, unipolar, 6 A / 54 A", [2], True, 54.0, 0.6),
                                     ("F+T, bipolar, 6 A / 20 A", [0, 1, 2, 3, 4, 5], False, 20.0,
                                      0.7)):
        fms = w[:, rows]
        reach = np.abs(fms).sum(axis=2) * 6.0
        sig = np.stack([np.sin(2 * np.pi * (0.5 + 0.1 * j) * t + j) for j in range(len(rows))],
                       axis=1)
        f = amp * reach * (np.abs(sig) if uni else sig)
        out.append((name, [(fms[i], f[i], 6.0, tl, uni) for i in range(n_steps)]))
    return out


def warm_vs_cold(paths, repeats: int = 3) -> dict:
    """Cold allocate vs warm Allocator along each path: timing stats and the largest difference
    of the answers (A)."""
    res = {}
    for name, probs in paths:
        cold, warm = [], []
        diff = 0.0
        for _ in range(repeats):
            alloc = Allocator()
            tc, tw = np.empty(len(probs)), np.empty(len(probs))
            for i, (fm, f, u, tl, uni) in enumerate(probs):
                t0 = time.perf_counter()
                xc, _ = allocate(fm, f, u, tl, unipolar=uni)
                t1 = time.perf_counter()
                xw, _ = alloc(fm, f, u, tl, unipolar=uni)
                t2 = time.perf_counter()
                tc[i], tw[i] = t1 - t0, t2 - t1
                diff = max(diff, float(np.abs(xc - xw).max()))
            cold.append(tc)
            warm.append(tw)
        c1, w1 = cold[0], warm[0]
        cm, wm = np.minimum.reduce(cold), np.minimum.reduce(warm)
        res[name] = {"n": len(probs), "max_difference_a": diff,
                     "cold_median_us": float(np.median(c1) * 1e6),
                     "cold_p99_us": float(np.percentile(c1, 99) * 1e6),
                     "warm_median_us": float(np.median(w1) * 1e6),
                     "warm_p99_us": float(np.percentile(w1, 99) * 1e6),
                     "cold_min3_median_us": float(np.median(cm) * 1e6),
                     "cold_min3_p99_us": float(np.percentile(cm, 99) * 1e6),
                     "warm_min3_median_us": float(np.median(wm) * 1e6),
                     "warm_min3_p99_us": float(np.percentile(wm, 99) * 1e6)}
    return res


def _times_lsq(probs):
    t = np.empty(len(probs))
    for i, (fm, f, u, tl, uni) in enumerate(probs):
        ub = np.broadcast_to(np.asarray(u, float), (fm.shape[1],)) + 1e-12
        lb = np.zeros_like(ub) if uni else -ub
        t0 = time.perf_counter()
        lsq_linear(fm, f, bounds=(lb, ub))
        t[i] = time.perf_counter() - t0
    return t


def verify(probs, progress: bool = True, checkpoint=None) -> dict:
    """KKT + bounds + SLSQP objective on every problem. SLSQP starts from 0; only when it is
    worse than ours does it get a second, independent start (the clipped least squares)."""
    worst_kkt, worst_viol, n_mis, n_lower, worst_rel = 0.0, 0.0, 0, 0, 0.0
    for i, (fm, f, u, tl, uni) in enumerate(tqdm(probs, desc="verify", disable=not progress,
                                                 mininterval=5)):
        x, res = allocate(fm, f, u, tl, unipolar=uni)
        kv, infeas = kkt_violation(fm, f, u, tl, x, uni)
        worst_kkt, worst_viol = max(worst_kkt, kv), max(worst_viol, infeas)
        floor = 1e-12 * float(f @ f)
        ref = slsqp_reference(fm, f, u, tl, uni, starts=1)
        if res - ref > 1e-6 * ref + floor:
            ref = slsqp_reference(fm, f, u, tl, uni, starts=2)
        rel = (res - ref) / max(ref, floor, 1e-300)
        if abs(res - ref) > 1e-6 * ref + floor:
            n_mis += 1
            n_lower += res < ref
        if res >= ref:
            worst_rel = max(worst_rel, rel)
        if checkpoint is not None and (i + 1) % 5000 == 0:
            checkpoint({"n_done": i + 1, "max_kkt_rel": worst_kkt,
                        "max_bound_violation_a": worst_viol, "n_objective_mismatch": n_mis,
                        "n_mismatch_ours_lower": n_lower})
    return {"n": len(probs), "max_kkt_rel": worst_kkt, "max_bound_violation_a": worst_viol,
            "n_objective_mismatch": n_mis, "n_mismatch_ours_lower": n_lower,
            "n_mismatch_ours_higher": n_mis - n_lower, "max_rel_excess_over_ref": worst_rel}


def certify(probs, progress: bool = True) -> dict:
    """KKT certificate (sufficient for global optimality of this convex QP) and bounds only:
    cheap enough for 1e5 problems."""
    worst_kkt, worst_viol = 0.0, 0.0
    for fm, f, u, tl, uni in tqdm(probs, desc="certify", disable=not progress, mininterval=5):
        x, res = allocate(fm, f, u, tl, unipolar=uni)
        kv, infeas = kkt_violation(fm, f, u, tl, x, uni)
        worst_kkt, worst_viol = max(worst_kkt, kv), max(worst_viol, infeas)
    return {"n": len(probs), "max_kkt_rel": worst_kkt, "max_bound_violation_a": worst_viol}


def run(out_dir=DEFAULT_OUT, *, n_time: int = 20000, n_verify: int = 500,
        n_kkt: int = 100000, n_pos: int = 400, n_path: int = 2000, quick: bool = False,
        progress: bool = True) -> dict:
    out_dir = Path(out_dir)
    if quick:
        n_time, n_verify, n_kkt, n_pos, n_path = 300, 30, 300, 12, 60
    with one_blas_thread():
        w = wrenches(n_pos)
        paths = path_problems(n_path)
        mix = problems(w, n_time, seed=1)
        design = problems(w, n_time, seed=2, design_limits=True)
        for p in mix[:200]:  # warm-up (imports, caches)
            allocate(p[0], p[1], p[2], p[3], unipolar=p[4])
        t_mix = [_times(mix) for _ in range(3)]
        t_des = [_times(design) for _ in range(3)]
        n_lsq = min(len(mix), 3000)
        t_lsq = [_times_lsq(mix[:n_lsq]) for _ in range(3)]
        path_res = warm_vs_cold(paths)
    res = {"n_time": n_time, "n_positions": n_pos}
    for key, ts in (("mix", t_mix), ("design_limits", t_des), ("lsq_linear_box_only", t_lsq)):
        tmin = np.minimum.reduce(ts)
        res[key + "_median_us"] = float(np.median(ts[0]) * 1e6)
        res[key + "_p99_us"] = float(np.percentile(ts[0], 99) * 1e6)
        res[key + "_min3_median_us"] = float(np.median(tmin) * 1e6)
        res[key + "_min3_p99_us"] = float(np.percentile(tmin, 99) * 1e6)
    res["speedup_vs_lsq_linear_median"] = (res["lsq_linear_box_only_median_us"]
                                           / res["mix_median_us"])
    res["path"] = path_res
    out_dir.mkdir(parents=True, exist_ok=True)
    with one_blas_thread():
        res["certify"] = certify(problems(w, n_kkt, seed=4), progress=progress)
        write_json_atomic(out_dir / "bench_allocation.partial.json", res)
        res["verify"] = verify(problems(w, n_verify, seed=3), progress=progress,
                               checkpoint=lambda part: write_json_atomic(
                                   out_dir / "bench_allocation.partial.json",
                                   {**res, "verify": part}))
    write_json_atomic(out_dir / "bench_allocation.json", res)
    print(f"{'cold, per solve (us)':<34}{'median':>9}{'p99':>9}{'min3 med':>10}{'min3 p99':>10}")
    for name, key in (("allocate, random mix", "mix"),
                      ("allocate, design limits 6 A/54 A", "design_limits"),
                      ("lsq_linear, box only (mix)", "lsq_linear_box_only")):
        print(f"{name:<34}{res[key + '_median_us']:>9.1f}{res[key + '_p99_us']:>9.1f}"
              f"{res[key + '_min3_median_us']:>10.1f}{res[key + '_min3_p99_us']:>10.1f}")
    print(f"speed-up vs lsq_linear (median): {res['speedup_vs_lsq_linear_median']:.1f}x")
    print(f"{'1 kHz path (us)':<26}{'cold med':>9}{'cold p99':>9}{'warm med':>9}{'warm p99':>9}"
          f"{'min3 c/w med':>14}{'max diff A':>11}")
    for name, p in path_res.items():
        print(f"{name:<26}{p['cold_median_us']:>9.1f}{p['cold_p99_us']:>9.1f}"
              f"{p['warm_median_us']:>9.1f}{p['warm_p99_us']:>9.1f}"
              f"{p['cold_min3_median_us']:>7.0f}/{p['warm_min3_median_us']:<6.0f}"
              f"{p['max_difference_a']:>11.1e}")
    c = res["certify"]
    print(f"KKT-certified {c['n']} problems: max KKT {c['max_kkt_rel']:.2e} (rel), max bound "
          f"violation {c['max_bound_violation_a']:.1e} A")
    v = res["verify"]
    print(f"verified {v['n']} problems: max KKT {v['max_kkt_rel']:.2e} (rel), max bound "
          f"violation {v['max_bound_violation_a']:.1e} A, objective mismatches > 1e-6: "
          f"{v['n_objective_mismatch']} (ours higher {v['n_mismatch_ours_higher']}, "
          f"ours lower {v['n_mismatch_ours_lower']})")
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out_dir", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--n-time", type=int, default=20000)
    ap.add_argument("--n-verify", type=int, default=500)
    ap.add_argument("--n-kkt", type=int, default=100000)
    ap.add_argument("--n-positions", type=int, default=400)
    ap.add_argument("--n-path", type=int, default=2000)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    run(a.out_dir, n_time=a.n_time, n_verify=a.n_verify, n_kkt=a.n_kkt, n_pos=a.n_positions,
        n_path=a.n_path, quick=a.quick)


if __name__ == "__main__":
    main()
