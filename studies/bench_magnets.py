"""Question: how long do the two-magnet allocation and the runner's step with two magnets take?

Allocation: at every control step of the simulated pinch (designkit.sim.pinch: two fingers 52 ->
30 mm apart squeezing a block, 35 mm above the thesis array), the runner's N-magnet allocation
(firmware_io.runner.MagnetsRunner.allocate_forces: both magnets' rows of A(p) from the map, their
F0, the pair force of the finite cylinders, the conditioning, the weighted stack, the
warm-started bounded solve of eq. 4.9) with two magnets, the same code with one magnet, and the
fixed reference workload of studies/bench_runner.py (a 9 x 9 solve and small products),
interleaved in one process on this thread's CPU clock; median and p99, and the ratios, next
to the issue's target (printed); and its pieces at the pinch's middle step (the map's F0 and
A(p) at one point, the pair force, the two- and one-magnet allocation), each the fastest of 7
blocks of 200 calls (a minimum is robust to the host's load, a median is not).

Step: the simulated pinch (designkit run --simulate --trajectory pinch's code,
designkit.sim.magnets_run.run_pinch) with each control step's measured CPU time (the simulated
PWM boards' own time subtracted): p50 and p99 of the running steps; in the same process, the
single-magnet runner's step (the first magnet sliding over the hemisphere on the same map) as
the reference, next to the issue's target (printed). The sensor side runs the N-magnet
estimator (its fit is not part of the step); the default design is the thesis device with the
36 sensors planned for two magnets (on the thesis' 18 no fix is trusted: nothing runs).

    python studies/bench_magnets.py [OUT] [--map F] [--design F.toml] [--quick]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit.design import load_design
from designkit.sim.magnets import MagnetsDevice
from designkit.sim.magnets_run import run_pinch
from designkit.sim.pinch import Pinch, pinch_trajectory
from designkit.sim.run import RunSettings, run_simulation
from firmware_io.allocation import Allocator
from firmware_io.localization import MagnetsEstimator
from firmware_io.mapfile import MapFile
from firmware_io.runner import MagnetsRunner, MagnetsSettings, RunnerIO, config_from_map
from firmware_io.scene import penetration_force
from studies._common import design_and_map, finish, load_average, study_parser

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "out" / "bench_magnets"
"""Default output folder (git-ignored), whatever the working directory."""

DEFAULT_DESIGN = ROOT / "docs" / "gallery" / "thesis-pinch-planned.toml"
"""The thesis device with two magnets and the 36 sensors planned for them."""

STIFFNESS_N_PER_M = 60.0
"""The block's stiffness in the allocation benchmark, N/m (the pinch run's)."""


def _us(t) -> dict:
    t = np.asarray(t, float) * 1e6
    return {"median_us": float(np.median(t)), "p99_us": float(np.percentile(t, 99)),
            "n": int(len(t))}


def _min_us(fn, number: int = 200, repeat: int = 7) -> float:
    """The fastest of ``repeat`` blocks of ``number`` calls, us per call (thread CPU time)."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.thread_time()
        for _ in range(number):
            fn()
        best = min(best, (time.thread_time() - t0) / number)
    return best * 1e6


def allocation_times(design, map_path, *, steps: int | None = None) -> dict:
    """The two-magnet allocation, the one-magnet one and the reference workload along the
    pinch (module docstring), interleaved, thread CPU time."""
    fmap = MapFile.load(map_path)
    cfg = config_from_map(fmap, force_axes="xyz")
    device = MagnetsDevice(design, seed=0, drive=cfg.drive)
    path = pinch_trajectory(Pinch(), design.magnets, fmap.bounds)
    block = Pinch().block().scene_object()
    ms = [np.asarray(m.moment_vector_a_m2, float) for m in design.magnets]

    def runner(specs):
        return MagnetsRunner(fmap, None, MagnetsEstimator.from_map(map_path, specs), RunnerIO(
            device.coils, lambda t: None, lambda line: None, time.thread_time), cfg,
            MagnetsSettings.of_specs(specs), allocate=Allocator())

    two, one = runner(design.magnets), runner(design.magnets[:1])
    rng = np.random.default_rng(0)
    a, b, c = rng.normal(size=(9, 9)) + 9 * np.eye(9), rng.normal(size=9), rng.normal(size=(4, 9))
    idx = range(len(path.t_s)) if steps is None else range(0, len(path.t_s),
                                                           max(1, len(path.t_s) // steps))
    t2, t1, tr, cond = [], [], [], []
    for k in idx:
        ps = path.positions_m[:, k]
        fs = penetration_force(block, ps, np.zeros((2, 3)), STIFFNESS_N_PER_M, 0.0)
        t0 = time.thread_time()
        two.allocate_forces(list(ps), list(fs), ms)
        t1_ = time.thread_time()
        one.allocate_forces([ps[0]], [fs[0]], ms[:1])
        t2_ = time.thread_time()
        x = np.linalg.solve(a, b)
        for _ in range(10):
            x = np.tanh(c.T @ (c @ x)) + b
        t3_ = time.thread_time()
        t2.append(t1_ - t0)
        t1.append(t2_ - t1_)
        tr.append(t3_ - t2_)
        cond.append(two.condition)
    res = {"two_magnets": _us(t2), "one_magnet": _us(t1), "reference": _us(tr),
           "condition_median": float(np.median(cond)), "condition_max": float(np.max(cond))}
    res["ratio_two_to_one"] = res["two_magnets"]["median_us"] / res["one_magnet"]["median_us"]
    # the allocation's pieces at the pinch's middle step: minimum over repeats (robust to load)
    k = len(path.t_s) // 2
    ps = list(path.positions_m[:, k])
    fs = list(penetration_force(block, np.array(ps), np.zeros((2, 3)), STIFFNESS_N_PER_M, 0.0))
    res["pieces_min_us"] = {
        "bias_force": _min_us(lambda: fmap.bias_force(ps[0])),
        "actuation": _min_us(lambda: fmap.actuation(ps[0])),
        "pair_forces": _min_us(lambda: two.pairs.forces(np.array(ps), np.array(ms))),
        "allocate_two": _min_us(lambda: two.allocate_forces(ps, fs, ms)),
        "allocate_one": _min_us(lambda: one.allocate_forces(ps[:1], fs[:1], ms[:1]))}
    res["ratio_two_to_reference"] = (res["two_magnets"]["median_us"]
                                     / res["reference"]["median_us"])
    return res


def step_times(design, map_path, out_dir, *, duration_s: float | None = None) -> dict:
    """The pinch's control step with two magnets (module docstring), from the run's summary
    and run.csv-level arrays: p50 / p99 of the running steps, us."""
    s = run_pinch(RunSettings(trajectory="pinch", duration_s=duration_s), design=design,
                  map_path=map_path, out=out_dir / "pinch", progress=False)
    # the same process's one-magnet step: the first magnet sliding over the hemisphere on
    # the same map (the single-magnet runner, its pose estimator on the sensor side)
    one = run_simulation(RunSettings(duration_s=duration_s or Pinch().duration_s),
                         design=design, map_path=map_path, out=out_dir / "one-magnet",
                         progress=False)
    return {"p50_us": s["loop_p50_s"] * 1e6, "p99_us": s["loop_p99_s"] * 1e6,
            "one_magnet_p50_us": one["loop_p50_s"] * 1e6,
            "one_magnet_p99_us": one["loop_p99_s"] * 1e6,
            "running_fraction": s["running_fraction"],
            "force_error_rms_n": [m["force_error_rms_n"] for m in s["magnets"]],
            "force_rms_n": [m["force_rms_n"] for m in s["magnets"]]}


def run(out_dir=DEFAULT_OUT, *, map_path=None, design=None, quick: bool = False) -> dict:
    design = load_design(DEFAULT_DESIGN) if design is None else design
    out_dir, design, _, map_path = design_and_map(out_dir, map_path, progress=not quick,
                                                  design=design)
    res = {"load_average_1min": load_average(), "clock": "thread CPU time",
           "design": design.name, "target_allocation_median_us": 200.0,
           "target_step_p99_us": 1000.0}
    res["allocation"] = allocation_times(design, map_path, steps=200 if quick else None)
    res["step"] = step_times(design, map_path, out_dir, duration_s=0.5 if quick else None)
    return finish(out_dir / "bench_magnets.json", res, _print)


def _print(res: dict) -> None:
    a = res["allocation"]
    print(f"design {res['design']}, load average {res['load_average_1min']}, "
          f"{res['clock']}")
    print("| allocation | steps | median us | p99 us |")
    print("| --- | --- | --- | --- |")
    for k in ("two_magnets", "one_magnet", "reference"):
        print(f"| {k} | {a[k]['n']} | {a[k]['median_us']:.0f} | {a[k]['p99_us']:.0f} |")
    print(f"ratio two / one magnet {a['ratio_two_to_one']:.2f}, two / reference "
          f"{a['ratio_two_to_reference']:.2f}; condition number median "
          f"{a['condition_median']:.3g}, max {a['condition_max']:.3g}")
    print("pieces at the pinch's middle step, fastest of 7 x 200 calls, us: " + ", ".join(
        f"{k} {v:.1f}" for k, v in a["pieces_min_us"].items()))
    s = res["step"]
    print("| step (running steps) | p50 us | p99 us |")
    print("| --- | --- | --- |")
    print(f"| two magnets (pinch) | {s['p50_us']:.0f} | {s['p99_us']:.0f} |")
    print(f"| one magnet (slide, same map) | {s['one_magnet_p50_us']:.0f} | "
          f"{s['one_magnet_p99_us']:.0f} |")
    print(f"ratio two / one magnet (p99) {s['p99_us'] / s['one_magnet_p99_us']:.2f}; target "
          f"p99 {res['target_step_p99_us']:.0f} us; running fraction "
          f"{s['running_fraction']:.3f}")


if __name__ == "__main__":
    ap = study_parser(__doc__, DEFAULT_OUT, quick="a 0.5 s pinch, 200 allocation points")
    ap.add_argument("--map", default=None, help="the design's map file (default: build one)")
    ap.add_argument("--design", default=None,
                    help=f"a design with two [[magnets]] (default {DEFAULT_DESIGN.name})")
    a = ap.parse_args()
    run(a.out, map_path=a.map, quick=a.quick,
        design=None if a.design is None else load_design(a.design))
