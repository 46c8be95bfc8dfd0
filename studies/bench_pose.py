"""Question: what does one pose fix cost -- cold (the global search), warm (a tracker's
prediction as the prior, frame after frame) and with a lying sensor excluded -- against a
reference computed in the same process?

The device of studies/pose_integrity.py (designkit's forward model, the start-up calibration,
default settings), 0.1 mT noise, thesis case 3 currents. Cold: ``n`` random poses 20-50 mm
up, tilted 0-45 degrees, each fixed alone. Warm: a walk (0.3 mm and 0.3 degree a frame) fixed
with the previous fix as the prior (its covariance plus the walk's step). Fault: the cold and
the warm frames with a sensor near the magnet reading zeros (the one below the walk, the one
next to the nearest for the cold frames). Each run times every
fix (thread CPU time, which a loaded host inflates less than the wall clock) and a 2000 x 2000
matmul; the table gives medians, p99 and the ratio to the matmul. ``--runs`` runs in one
process; the acceptance asks the median of 3 idle runs (run it 3 times, take the median).

    nice -n 10 python studies/bench_pose.py [OUT] [--n 200] [--runs 3]   # bench_pose.json
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from firmware_io.localization import EstimatorSettings, ModelEstimator, Pose
from studies._common import finish, load_average
from studies.pose_integrity import _device, _magnet_field, _tilted

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "bench_pose"
STEP = (0.3e-3, math.radians(0.3))
"""The warm walk's step per frame: position sd per axis (m), direction (rad)."""
RESTART = np.diag([1e-3 ** 2] * 3 + [math.radians(3.0) ** 2] * 2)
"""The prior after an untrusted frame: the walk's truth with this covariance (a stand-in for
the runner's re-acquisition)."""


def _frames(sim, cores, poses, dirs, cur, rng):
    mg, size = sim.design.magnet, float(np.linalg.norm(sim.moment_a_m2))
    ind = np.stack([cores.field_of_magnet(poses[k:k + 1], size * dirs[k], mg.radius_m,
                                          mg.length_m)[0] for k in range(len(poses))])
    field = _magnet_field(sim, poses, dirs) + ind + sim.coil_part(cur).reshape(len(poses), -1, 3)
    rd = sim.readout(field.reshape(len(poses), 2, -1, 3), rng=rng)
    return np.concatenate([rd.top_t, rd.bottom_t], 1)


def _timed(fn, k: int) -> np.ndarray:
    out = np.empty(k)
    for j in range(k):
        t0 = time.thread_time()
        fn(j)
        out[j] = time.thread_time() - t0
    return out


def _matmul_s() -> float:
    a = np.random.default_rng(0).normal(size=(2000, 2000))
    t0 = time.perf_counter()
    a @ a
    return time.perf_counter() - t0


def run(n: int = 200, runs: int = 3, seed: int = 0, out_dir=DEFAULT_OUT) -> dict:
    sim, model, cal, cores = _device(seed, 0.1e-3)
    est = ModelEstimator(model, EstimatorSettings(noise_t=0.1e-3), calibration=cal)
    rng = np.random.default_rng(seed + 5)
    axis0 = sim.moment_a_m2 / np.linalg.norm(sim.moment_a_m2)
    size = float(np.linalg.norm(sim.moment_a_m2))
    cold_p = np.c_[rng.uniform(-0.025, 0.025, (n, 2)), rng.uniform(0.02, 0.05, n)]
    cold_u = _tilted(axis0, np.radians(rng.uniform(0, 45, n)), rng.uniform(0, 2 * np.pi, n))
    walk_p = np.array([0.0, 0.0, 0.03]) + np.cumsum(rng.normal(scale=STEP[0], size=(n, 3)), 0)
    walk_u = _tilted(axis0, np.radians(20 + np.cumsum(rng.normal(scale=0.3, size=n))),
                     np.full(n, 0.5))
    cur = np.tile(np.linspace(-0.65, 0.65, 9), (n, 1))
    cold = _frames(sim, cores, cold_p, cold_u, cur, rng)
    warm = _frames(sim, cores, walk_p, walk_u, cur, rng)
    nearest = np.argmin(np.linalg.norm(model.sensor_positions_m[None] - walk_p[:, None], axis=2),
                        axis=1)
    faulty = warm.copy()
    faulty[np.arange(n), nearest] = 0.0
    grow = np.diag([STEP[0] ** 2] * 3 + [STEP[1] ** 2] * 2)
    state = {}

    def warm_fix(frames):
        def fn(j):
            fix = est.estimate(frames[j], cur[j], seed=state.get("prev"))
            # the next prior: this fix and the walk's step, or (untrusted) the walk's truth
            state["prev"] = (Pose(fix.position_m, fix.moment_a_m2, fix.covariance[:5, :5] + grow)
                             if fix.ok else Pose(walk_p[j], size * walk_u[j], RESTART))
        return fn

    def cold_fix(frames):
        def fn(j):
            est.reset()
            est.estimate(frames[j], cur[j])
        return fn

    out = []
    for _ in range(runs):
        row = {"matmul_s": _matmul_s()}
        row["cold"] = _timed(cold_fix(cold), n)
        state.clear()
        row["warm"] = _timed(warm_fix(warm), n)
        state.clear()
        row["warm_fault"] = _timed(warm_fix(faulty), n)
        cold_faulty = cold.copy()
        near_c = np.argmin(np.linalg.norm(model.sensor_positions_m[None] - cold_p[:, None],
                                          axis=2), axis=1)
        cold_faulty[np.arange(n), (near_c + 1) % model.n_sensors] = 0.0
        row["cold_fault"] = _timed(cold_fix(cold_faulty), n)
        out.append(row)
        print(_line(row), flush=True)
    med = {k: float(np.median([np.median(r[k]) for r in out])) for k in
           ("cold", "warm", "warm_fault", "cold_fault")}
    p99 = {k: float(np.median([np.percentile(r[k], 99) for r in out])) for k in med}
    mm = float(np.median([r["matmul_s"] for r in out]))
    print(f"median of {runs} runs: cold {med['cold'] * 1e3:.2f} ms (target <= 2), warm "
          f"{med['warm'] * 1e6:.0f} us (target <= 200), with exclusion p99 warm "
          f"{p99['warm_fault'] * 1e3:.2f} ms / cold {p99['cold_fault'] * 1e3:.2f} ms (target "
          f"<= 3); 2000 x 2000 matmul {mm:.3f} s; load {load_average()}", flush=True)
    res = {"median_s": med, "p99_s": p99, "matmul_s": mm, "load_average": load_average(),
           "n": n, "runs": runs}
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    return finish(Path(out_dir) / "bench_pose.json", res, lambda r: None)


def _line(row) -> str:
    mm = row["matmul_s"]
    parts = []
    for k in ("cold", "warm", "warm_fault", "cold_fault"):
        v = row[k]
        parts.append(f"{k} {np.median(v) * 1e3:.3f}/{np.percentile(v, 99) * 1e3:.3f} ms "
                     f"({np.median(v) / mm:.2e} matmul)")
    return f"matmul {mm:.3f} s; " + "; ".join(parts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(DEFAULT_OUT), help="output folder")
    ap.add_argument("--n", type=int, default=200, help="fixes per kind and run")
    ap.add_argument("--runs", type=int, default=3, help="runs in this process")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    if a.n < 2 or a.runs < 1:
        print(f"error: --n {a.n} / --runs {a.runs}: n >= 2, runs >= 1", file=sys.stderr)
        return 2
    run(a.n, a.runs, a.seed, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
