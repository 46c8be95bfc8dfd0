"""Question: how long does one control step of the rendering runner take, part by part, and what
does skipping what the scene does not need save?

A control step of firmware_io.runner is: the localization update (on a new sensor frame: the fit
of firmware_io.localization, warm-started), the Kalman prediction to now, the object's force
(firmware_io.scene), the force matrix at p (the map), the bounded allocation
(firmware_io.allocation), the duty conversion (voltage feed-forward + MD10C duty/direction) and
the PCA9685 byte building (firmware_io.coils.CoilDriver.plan). Each part is timed alone on
realistic inputs (positions along a slide over the hemisphere, simulated sensor frames with
coil currents), then whole Runner.step calls on the simulated buses, with the time spent inside
the simulated devices subtracted (SimBus.model_time_s). Target: p99 <= 1 ms per step (a 1 kHz
haptic loop in Python).

"Skip what the scene doesn't need", measured against the full evaluation in the same run:
(a) Fz only (the thesis' law on a z-dipole): 2 rows of A(p) and a 1 x n allocation instead of 8
rows and 3 x n; (b) coil skipping: coils whose force per ampere at p is below a fraction of the
largest are left out of the allocation -- the force they could add is bounded by that fraction
times the largest coil's force at the current limit, stated per row.

    python studies/bench_runner.py [OUT_DIR] [--map FILE] [--n N] [--quick]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit import default_design
from designkit._io import write_json_atomic


DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "bench_runner"
"""Default output folder (git-ignored), whatever the working directory."""


def _stats(times_s) -> dict:
    t = np.asarray(times_s) * 1e6
    return {"median_us": float(np.median(t)), "p99_us": float(np.percentile(t, 99)),
            "n": int(len(t))}


def _timed(fn, args_list, clock=time.perf_counter):
    out = []
    for a in args_list:
        t0 = clock()
        fn(*a)
        out.append(clock() - t0)
    return out


def run(out_dir=DEFAULT_OUT, *, map_path=None, n: int = 2000, quick: bool = False) -> dict:
    from designkit import fieldmap
    from designkit.array import CoilArray
    from designkit.localize import SensorSimulator
    from designkit.plant import drive_data, slide_trajectory
    from designkit.render.laws import ConstraintLaw
    from designkit.render.scenefile import compile_scene, make_object
    from firmware_io.allocation import allocate
    from firmware_io.localization import ConstantVelocityKalman, Localizer
    from firmware_io.mapfile import MapFile
    from firmware_io.md10c import current_to_command
    from firmware_io.runner import RunnerConfig, feedforward_voltage
    from firmware_io.scene import Scene

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    design = default_design()
    array = CoilArray.from_design(design)
    if map_path is None:
        map_path = out_dir / "map.npz"
        fieldmap.write(map_path, fieldmap.build(design, array=array, progress=not quick))
    fmap = MapFile.load(map_path)
    obj = make_object("hemisphere")
    lam = design.render.stiffness_n_per_m
    scene = Scene.load(compile_scene(obj, out_dir / "scene.npz", lam_n_per_m=lam,
                                     law=ConstraintLaw(lam), map_design_sha256=fmap.design_sha256),
                       expected_design_sha256=fmap.design_sha256)
    n = 200 if quick else n
    path = slide_trajectory(lambda x, y: obj.height(np.c_[x, y, np.zeros_like(x)]),
                            duration_s=4.0, samples=n)
    p = path.position_m
    rng = np.random.default_rng(0)
    drive = drive_data(design)
    u = drive["current_limit_a"]
    currents = rng.uniform(-0.3, 0.3, (n, array.n_coils)) * u
    sim = SensorSimulator(design, array=array, errors="default",
                          moment_direction=design.magnet.moment_vector_a_m2,
                          induced="coupled" if not quick else "off", seed=1)
    k_frames = min(n, 60 if quick else 400)
    idx = np.linspace(0, n - 1, k_frames).astype(int)
    frames = sim.read(p[idx], currents[idx])
    res: dict = {"n_steps": n, "frames": k_frames, "clock": "perf_counter (wall)"}

    # -- localization update (warm start along the path) and the Kalman filter
    for method in ("model", "dipole"):
        loc = Localizer.from_map(map_path, method=method)
        loc.locate(frames.top_t[0], frames.bottom_t[0], currents[idx[0]])   # cold start once
        t = _timed(lambda k: loc.locate(frames.top_t[k], frames.bottom_t[k], currents[idx[k]]),
                   [(k,) for k in range(1, k_frames)])
        res[f"localize_{method}"] = _stats(t)
    kf = ConstantVelocityKalman()
    kf.update(p[0], 0.0)
    res["kalman_update"] = _stats(_timed(lambda k: kf.update(p[k], k * 1e-3),
                                         [(k,) for k in range(1, n)]))
    res["kalman_predict"] = _stats(_timed(lambda k: kf.predict(k * 1e-3 + 5e-4),
                                          [(k,) for k in range(1, n)]))

    # -- object force
    res["object_force"] = _stats(_timed(lambda k: scene.force(p[k][None], np.zeros((1, 3))),
                                        [(k,) for k in range(n)]))

    # -- force matrix: full 3-D vs Fz only (2 rows) vs the (1, 3) shape of the point
    m = np.asarray(fmap.moment_a_m2, float)
    fm3 = np.array([[m[0], m[1], m[2], 0, 0], [0, m[0], 0, m[1], m[2]],
                    [-m[2], 0, m[0], -m[2], m[1]]])

    def force3(k):
        return fm3 @ fmap.actuation(p[k])[3:]

    def force_z(k):
        rows = getattr(fmap, "actuation_rows", None)
        a = rows(p[k], (3, 6)) if rows is not None else fmap.actuation(p[k])[[3, 6]]
        return -m[2] * (a[0] + a[1])[None]

    res["force_matrix_3d"] = _stats(_timed(force3, [(k,) for k in range(n)]))
    res["force_matrix_fz"] = _stats(_timed(force_z, [(k,) for k in range(n)]))
    res["force_matrix_fz_note"] = ("rows-only interpolation" if hasattr(fmap, "actuation_rows")
                                   else "the map interpolates all 8 rows; Fz uses 2 of them")

    # -- allocation: 3-D, Fz, Fz with coil skipping
    f_obj = scene.force(p, np.zeros_like(p))
    bias = fmap.bias_force(p)
    F3 = [force3(k) for k in range(n)]
    Fz = [force_z(k) for k in range(n)]
    tl = drive["total_current_a"]
    res["allocate_3d"] = _stats(_timed(
        lambda k: allocate(F3[k], f_obj[k] - bias[k], np.full(9, u), tl), [(k,) for k in range(n)]))
    res["allocate_fz"] = _stats(_timed(
        lambda k: allocate(Fz[k], f_obj[k, 2:] - bias[k, 2:], np.full(9, u), tl),
        [(k,) for k in range(n)]))
    skip = {}
    for frac in (0.02, 0.05, 0.1):
        kept, err = [], []

        def alloc_skip(k, frac=frac):
            norms = np.abs(F3[k]).max(axis=0)
            keep = norms >= frac * norms.max()
            i, _ = allocate(F3[k][:, keep], f_obj[k] - bias[k], np.full(keep.sum(), u), tl)
            kept.append(int(keep.sum()))
            full = np.zeros(9)
            full[keep] = i
            err.append(float(np.linalg.norm(F3[k] @ full - (f_obj[k] - bias[k]))))

        t = _timed(alloc_skip, [(k,) for k in range(n)])
        full_err = [float(np.linalg.norm(F3[k] @ allocate(F3[k], f_obj[k] - bias[k],
                                                            np.full(9, u), tl)[0]
                                         - (f_obj[k] - bias[k]))) for k in range(0, n, 10)]
        skip[str(frac)] = {**_stats(t), "coils_kept_mean": float(np.mean(kept)),
                           "residual_p95_n": float(np.percentile(err, 95)),
                           "residual_full_p95_n": float(np.percentile(full_err, 95)),
                           "bound_per_skipped_coil": f"{frac} x max_k |F_k| x {u:.2f} A"}
    res["allocate_3d_skip"] = skip

    # -- duty conversion and PCA9685 byte building
    from firmware_io.coils import CoilDriver
    from firmware_io.devices import PCA9685, pca9685_channel_bytes
    from firmware_io.md10c import CoilDrive
    from firmware_io.sim import SimBus, SimPCA9685

    cfg = RunnerConfig(**{kk: tuple(v) if isinstance(v, list) else v for kk, v in drive.items()})
    r_ohm, ind = np.asarray(cfg.resistance_ohm), np.asarray(cfg.inductance_h)
    dr = [CoilDrive(cfg.supply_voltage_v, r, min(cfg.supply_voltage_v / r, 13.0)) for r in r_ohm]

    def duty(k):
        v = feedforward_voltage(currents[k], currents[k - 1], r_ohm, ind, 1e-3,
                                cfg.supply_voltage_v)
        return [current_to_command(float(x), d) for x, d in zip(v / r_ohm, dr)]

    res["duty_conversion"] = _stats(_timed(duty, [(k,) for k in range(1, n)]))
    bus = SimBus([SimPCA9685(0x40), SimPCA9685(0x41)])
    coils = CoilDriver([PCA9685(bus, 0x40), PCA9685(bus, 0x41)], dr)
    coils.initialize()

    def build_bytes(k):
        _, first, _, _ = coils.plan(np.clip(currents[k], -u, u))
        return [b"".join(pca9685_channel_bytes(v) for _, v in sorted(w.items())) for w in first]

    res["pca9685_bytes"] = _stats(_timed(build_bytes, [(k,) for k in range(n)]))

    # -- the sum of the parts, per step without and with a new frame
    base = ["kalman_predict", "object_force", "force_matrix_3d", "allocate_3d",
            "duty_conversion", "pca9685_bytes"]
    med = sum(res[k]["median_us"] for k in base)
    p99 = sum(res[k]["p99_us"] for k in base)
    res["step_without_frame"] = {"median_us": med, "p99_us_bound": p99}
    res["step_with_frame"] = {"median_us": med + res["localize_model"]["median_us"]
                              + res["kalman_update"]["median_us"],
                              "p99_us_bound": p99 + res["localize_model"]["p99_us"]
                              + res["kalman_update"]["p99_us"]}
    res["target_p99_us"] = 1000.0
    write_json_atomic(out_dir / "bench_runner.json", res)
    _print(res)
    return res


def _print(res: dict) -> None:
    print(f"runner step parts, {res['n_steps']} steps, {res['frames']} frames ({res['clock']})")
    print(f"{'part':28s} {'median us':>10s} {'p99 us':>10s}")
    for k, v in res.items():
        if isinstance(v, dict) and "median_us" in v and "p99_us" in v:
            print(f"{k:28s} {v['median_us']:10.1f} {v['p99_us']:10.1f}")
    for k in ("step_without_frame", "step_with_frame"):
        v = res[k]
        print(f"{k:28s} {v['median_us']:10.1f} {v['p99_us_bound']:10.1f} (sum of p99s)")
    print("coil skipping (3-D allocation):")
    for frac, v in res["allocate_3d_skip"].items():
        print(f"  below {float(frac):4.0%} of the largest: {v['coils_kept_mean']:.1f} coils kept, "
              f"median {v['median_us']:.1f} us (all 9: {res['allocate_3d']['median_us']:.1f}), "
              f"residual p95 {v['residual_p95_n'] * 1e3:.3f} mN (all: "
              f"{v['residual_full_p95_n'] * 1e3:.3f} mN)")
    print(f"Fz only: force matrix {res['force_matrix_fz']['median_us']:.1f} us vs 3-D "
          f"{res['force_matrix_3d']['median_us']:.1f} us ({res['force_matrix_fz_note']}); "
          f"allocation {res['allocate_fz']['median_us']:.1f} vs {res['allocate_3d']['median_us']:.1f} us")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--map", default=None, help="an existing map file (default: build one)")
    ap.add_argument("--n", type=int, default=2000)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    run(a.out, map_path=a.map, n=a.n, quick=a.quick)
