"""Question: how long does one control step of the rendering runner take -- with and without a
new sensor result, stage by stage -- how long does the fit take on the sensor side, and what does
skipping what the scene does not need save?

The closed loop (designkit.sim: firmware_io's Runner on the simulated device, a slide over the
hemisphere, the fit on the sensor side with the sensor thread's timing) runs with the runner's
stage timer on: per control step the compute time (this thread's CPU clock, the simulated PWM
boards' own time subtracted) of 'fix' (taking the sensor side's result, Kalman update),
'predict', 'object_force', 'force_matrix' (A(p) rows the law uses + the bias force, the map),
'allocation' and 'drive' (voltage feed-forward, MD10C duty/direction, PCA9685 bytes, the block
writes). Split by step kind (with / without a new sensor result) as median and p99, and the fit's
time on the sensor side separately. Target: p99 <= one control period for every step. Per
runner state (running = tracking, gated, lost = the sensor side re-acquiring, the fault states)
from a run with every fault injected once: median, p99 and max of the step, next to a
same-process reference (a fixed numpy workload on the same clock) and their ratio.
"Skip what the scene doesn't need", against the full evaluation in the same process, one point
at a time along the path: all 8 rows of A(p) for all coils, then only the rows the force law uses
(firmware_io.runner.force_law_rows: 4 for the 3-D force of a z-dipole, 2 for Fz alone; selected
inside the map's kernel, or sliced after it as the runner does), then also only the coils whose
bound of force per ampere near p (firmware_io.runner.CoilSkipBound) times the current limit
exceeds a stated force; with the allocation on the kept coils and the force it then misses.
``--design``: another design (1010-steel cores: the map's saturation factor applied);
``--no-saturation``: its factor set to 1; ``--magnets F``: the two-magnet case (bench_magnets).

    python studies/bench_runner.py [OUT] [--map F] [--design F] [--no-saturation] [--magnets F]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit.design import load_design
from designkit.render.scenefile import make_object
from designkit.sim import RunSettings, drive_data, run_simulation, slide_trajectory
from firmware_io.allocation import allocate
from firmware_io.mapfile import MapFile
from firmware_io.runner import CoilSkipBound, force_law_rows
from firmware_io.scene import Scene
from studies import bench_magnets
from studies._common import design_and_map, finish, load_average, without_saturation

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "bench_runner"
"""Default output folder (git-ignored), whatever the working directory."""

SKIP_FORCES_N = (1e-3, 1e-2, 0.1, 0.3)
"""Coil-skip forces benchmarked, N (the human force detection threshold is ~10-30 mN at the
fingertip; 1 mN is far below it; 0.1 and 0.3 N show where the 3x3 array's coils start to be
skipped -- every coil can add more than 10 mN at its limit anywhere on the path)."""


def _us(times_s) -> dict:
    t = np.asarray(times_s, float) * 1e6
    return {"median_us": float(np.median(t)), "p99_us": float(np.percentile(t, 99)),
            "n": int(len(t))}


def _timed(fn, n, clock=time.thread_time):
    out = []
    for k in range(n):
        t0 = clock()
        fn(k)
        out.append(clock() - t0)
    return out


def _reference_us(n: int = 300) -> dict:
    """A fixed workload on the step's clock (thread CPU time) in this process: a 9 x 9 solve and
    a few small products, the size of a step's numerics. Ratios to it compare machines."""
    rng = np.random.default_rng(0)
    a = rng.normal(size=(9, 9)) + 9 * np.eye(9)
    b = rng.normal(size=9)
    m = rng.normal(size=(4, 9))

    def work(_):
        x = np.linalg.solve(a, b)
        for _ in range(10):
            x = np.tanh(m.T @ (m @ x)) + b
        return x
    return _us(_timed(work, n))


def _by_state(summary: dict) -> dict:
    """The step per runner state in microseconds (n, median, p99, max)."""
    out = {}
    for name, v in summary["loop_by_state"].items():
        out[name] = {"n": v["n"], "median_us": v["p50_s"] * 1e6, "p99_us": v["p99_s"] * 1e6,
                     "max_us": v["max_s"] * 1e6}
    return out


def _loop(summary: dict) -> dict:
    """The closed loop's timing in microseconds, from run_simulation's summary."""
    lk = summary["loop_by_kind"]

    def conv(d):
        return {"median_us": None if d["p50_s"] is None else d["p50_s"] * 1e6,
                "p99_us": None if d["p99_s"] is None else d["p99_s"] * 1e6, "n": d["n"]}

    out = {k: conv(lk[k]) for k in ("without_frame", "with_frame", "sensor_side_fit")}
    out["stages"] = {name: {kind: conv(v[kind]) for kind in ("without_frame", "with_frame")}
                     for name, v in lk.get("stages", {}).items()}
    out["running_fraction"] = summary["running_fraction"]
    return out


def run(out_dir=DEFAULT_OUT, *, map_path=None, duration_s: float = 2.0,
        quick: bool = False, design=None, saturation: bool = True, magnets=None) -> dict:
    """The study (module docstring); ``magnets``: None, or (a design with two magnets, its
    map path or None) for the two-magnet case."""
    out_dir, design, array, map_path = design_and_map(out_dir, map_path, progress=not quick,
                                                      design=design)
    if not saturation:
        map_path = without_saturation(map_path, out_dir / "map_factor_1.npz")
    duration_s = min(duration_s, 0.4) if quick else duration_s
    res: dict = {"load_average_1min": load_average(), "duration_s": duration_s,
                 "clock": "thread CPU time", "target_p99_us": 1000.0, "design": design.name,
                 "saturation_applied": not MapFile.load(map_path).saturation_table().linear}

    # -- the closed loop, stage by stage, 3-D force and Fz alone
    for rows in (("force",) if quick else ("force", "fz")):
        s = run_simulation(RunSettings(duration_s=duration_s, rows=rows, profile=True),
                           design=design, map_path=map_path, out=out_dir / f"loop-{rows}",
                           progress=False, array=array)
        res[f"loop_{rows}"] = _loop(s)

    # -- the step per runner state: every fault injected once (the hemisphere's slide)
    s = run_simulation(RunSettings(duration_s=4.0 if not quick else 1.0, faults="default"),
                       design=design, map_path=map_path, out=out_dir / "loop-faults",
                       progress=False, array=array)
    res["reference"] = _reference_us()
    res["by_state"] = _by_state(s)
    res["recovery"] = [{k: f[k] for k in ("fault", "injected_s", "time_to_safe_s",
                                          "resumed_s", "recovered_s")} for f in s["faults"]]

    # -- skipping rows and coils, one point at a time along the path
    fmap = MapFile.load(map_path)
    obj = make_object("hemisphere")
    n = 100 if quick else 1000
    path = slide_trajectory(lambda x, y: obj.height(np.c_[x, y, np.zeros_like(x)]),
                            duration_s=4.0, samples=n).position_m
    scene = Scene.load(out_dir / "loop-force" / "scene.npz")
    f_obj = scene.force(path, np.zeros_like(path))
    bias = fmap.bias_force(path)
    m = fmap.moment_a_m2
    drive = drive_data(design)
    limit = np.full(fmap.n_coils, drive.current_limit_a)
    total = drive.total_current_a
    rows3, mat3 = force_law_rows(m, "xyz")
    full_mat = np.zeros((3, 8))           # the same force from all 8 rows
    full_mat[:, rows3] = mat3
    skip = {"rows_used_3d": rows3.tolist(), "rows_used_fz": force_law_rows(m, "z")[0].tolist()}
    skip["all_rows"] = _us(_timed(lambda k: full_mat @ fmap.actuation(path[k]), n))
    skip["law_rows"] = _us(_timed(lambda k: mat3 @ fmap.actuation(path[k], rows=rows3), n))
    skip["law_rows_sliced"] = _us(_timed(lambda k: mat3 @ fmap.actuation(path[k])[rows3], n))
    rows_z, mat_z = force_law_rows(m, "z")
    skip["law_rows_fz"] = _us(_timed(lambda k: mat_z @ fmap.actuation(path[k], rows=rows_z), n))
    t0 = time.perf_counter()
    bound = CoilSkipBound(fmap)
    skip["bound_table_s"] = time.perf_counter() - t0
    full_i = [allocate(mat3 @ fmap.actuation(path[k], rows=rows3), f_obj[k] - bias[k], limit,
                       total)[0] for k in range(n)]
    skip["allocate_all_coils"] = _us(_timed(
        lambda k: allocate(mat3 @ fmap.actuation(path[k], rows=rows3), f_obj[k] - bias[k],
                           limit, total), n))
    # the bound must hold: the exact force per ampere at the path points is below it
    exact = np.linalg.norm(np.einsum("ij,njk->nik", mat3, fmap.actuation(path)[:, rows3]), axis=1)
    m_norm = float(np.linalg.norm(m))
    skip["bound_holds"] = bool(np.all(exact <= m_norm * np.array([bound.at(p) for p in path])
                                      + 1e-15))
    for force in SKIP_FORCES_N:
        kept, miss = [], []

        def step(k, force=force):
            keep = bound.keep(path[k], limit, force, m_norm)
            fm = mat3 @ fmap.actuation(path[k], coils=keep)[rows3]
            i, _ = allocate(fm, f_obj[k] - bias[k], limit[keep], total)
            kept.append(len(keep))
            full = np.zeros(fmap.n_coils)
            full[keep] = i
            return full

        t = _timed(step, n)
        for k in range(n):
            i = step(k)
            fk = mat3 @ fmap.actuation(path[k], rows=rows3)
            miss.append(float(np.linalg.norm(fk @ (i - full_i[k]))))
        kept = kept[n:]
        skip[f"skip_{force * 1e3:g}mN"] = {
            **_us(t), "coils_kept_mean": float(np.mean(kept)), "coils_kept_min": int(min(kept)),
            "force_change_p95_n": float(np.percentile(miss, 95)),
            "force_change_max_n": float(np.max(miss))}
    res["skip"] = skip
    if magnets is not None:
        res["two_magnets"] = bench_magnets.run(out_dir / "two-magnets", design=magnets[0],
                                               map_path=magnets[1], quick=quick)
    return finish(out_dir / "bench_runner.json", res, _print)


def _fmt(v) -> str:
    return "    n/a" if v is None else f"{v:7.0f}"


def _print(res: dict) -> None:
    print(f"runner control step, {res['duration_s']} s slide over the hemisphere per mode "
          f"({res['clock']}; load average {res['load_average_1min']}; target p99 "
          f"{res['target_p99_us']:.0f} us); design {res['design']}, saturation factor "
          f"{'applied' if res['saturation_applied'] else 'none (linear cores or set to 1)'}")
    for key in [k for k in res if k.startswith("loop_")]:
        lp = res[key]
        print(f"\n{key[5:]}: step kind / stage        median us   p99 us    steps")
        for kind in ("without_frame", "with_frame", "sensor_side_fit"):
            v = lp[kind]
            label = {"without_frame": "step, no new frame", "with_frame": "step, new frame",
                     "sensor_side_fit": "fit (sensor side)"}[kind]
            print(f"  {label:30s} {_fmt(v['median_us'])}  {_fmt(v['p99_us'])}  {v['n']:7d}")
        for name, v in lp["stages"].items():
            a, b = v["without_frame"], v["with_frame"]
            print(f"    {name:14s} no frame {_fmt(a['median_us'])} / {_fmt(a['p99_us'])}   "
                  f"new frame {_fmt(b['median_us'])} / {_fmt(b['p99_us'])}")
    ref = res["reference"]["median_us"]
    print(f"\nstep per runner state, every fault injected once (reference workload median "
          f"{ref:.0f} us, same process; ratio = step median / reference)")
    print("  state              steps  median us   p99 us   max us   ratio")
    for name, v in res["by_state"].items():
        print(f"  {name:16s} {v['n']:7d}  {_fmt(v['median_us'])}  {_fmt(v['p99_us'])}  "
              f"{_fmt(v['max_us'])}  {v['median_us'] / ref:6.2f}")
    print("  (an injected overrun step counts in 'overrun': its clock jumps by design)")
    print("\nrecovery, ms: detected after the injection / running again after the injection / "
          "running again after the cause is gone")
    for f in res["recovery"]:
        def ms(v):
            return "      -" if v is None else f"{v * 1e3:7.0f}"
        print(f"  {f['fault']:16s} {ms(f['time_to_safe_s'])} {ms(f['resumed_s'])} "
              f"{ms(f['recovered_s'])}")
    s = res["skip"]
    print(f"\nskipping (one point, median / p99 us): rows used 3-D {s['rows_used_3d']}, "
          f"Fz {s['rows_used_fz']}")
    for k in ("all_rows", "law_rows", "law_rows_sliced", "law_rows_fz", "allocate_all_coils"):
        print(f"  {k:28s} {_fmt(s[k]['median_us'])} / {_fmt(s[k]['p99_us'])}")
    print(f"  coil bound table: {s['bound_table_s']:.2f} s at start-up; bound holds on the path: "
          f"{s['bound_holds']}")
    for k, v in s.items():
        if k.startswith("skip_"):
            print(f"  {k:28s} {_fmt(v['median_us'])} / {_fmt(v['p99_us'])}  (map + allocation), "
                  f"coils kept {v['coils_kept_mean']:.1f} (min {v['coils_kept_min']}), force "
                  f"change p95 {v['force_change_p95_n'] * 1e3:.3f} mN, max "
                  f"{v['force_change_max_n'] * 1e3:.3f} mN")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--map", default=None, help="an existing map file (default: build one)")
    ap.add_argument("--duration", type=float, default=2.0, help="simulated seconds per mode")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--design", default=None,
                    help="design TOML file or a shipped design (default: the thesis device)")
    ap.add_argument("--no-saturation", action="store_true",
                    help="run with the map's saturation factor table set to 1")
    ap.add_argument("--magnets", default=None,
                    help="a design with two [[magnets]]: also the two-magnet case")
    ap.add_argument("--magnets-map", default=None, help="that design's map (default: build)")
    a = ap.parse_args()
    run(a.out, map_path=a.map, duration_s=a.duration, quick=a.quick,
        design=None if a.design is None else load_design(a.design),
        saturation=not a.no_saturation,
        magnets=None if a.magnets is None else (load_design(a.magnets), a.magnets_map))
