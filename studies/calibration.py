"""Question: how close does the as-built calibration bring the model to a built device, for
random devices within the build tolerances, by plan (onboard arrays only; onboard + a probe
scan) and by tolerance scale -- and what does it cost?

Devices: :func:`designkit.design.asbuilt.random_asbuilt` with the default tolerances (0.6 mm per axis,
5 mrad tilt, 2 % turns, 0.5 mm core depth) times ``scale``, every core's steel at mu_r 450
(nominal 1000). Readings from the device's exact coupled model: onboard arrays, each coil alone
at +-2 A, 0.05 mT noise; probe, ``--probe`` random workspace points, each coil alone at 1 A,
0.02 mT noise. Fit: :func:`designkit.calibration.fit` (``--coupling-rounds``; its whitened
cost per reading axis is printed: about 1 when the model fits the readings to their noise).
Held out: 200 random workspace points; error of A(p) per point and row relative to the row's largest value
over those points (:func:`designkit.calibration.actuation_error`), nominal and calibrated.
Parameters: the fraction within 3 standard errors of the truth among those the fit calls
identifiable, and of the identifiable combined pairs (nearly collinear parameters) the count
within 3 standard errors; "at priors" names what is neither. Benchmark: the fit's wall and
CPU time on the onboard + probe rows (``--probe 53``: 801 rows) with the same-process
2000 x 2000 matmul time as the machine's speed reference and the load average.

``--run`` (3 x 3 only): each device of the first scale as the plant of ``designkit run
--simulate`` (slide over the hemisphere, ``--duration`` s, no start-up sensor calibration), the
runner on the map of the true device, the calibrated and the nominal design (slow; true.toml,
calibrated.toml): force error RMS, calibrated / true per run and the median; ``--repeats``:
each map again with other sensor noise. ``--seed`` draws other devices.

Usage: python studies/calibration.py --out study-out/calibration [--quick | --run]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit import calibration as cal
from designkit.model.array import CoilArray
from designkit.design.asbuilt import AsBuilt, BuildTolerances, PARAMETERS, random_asbuilt
from designkit.design import default_design, design_to_toml
from designkit.sim import RunSettings, run_simulation
from firmware_io.scene import Scene
from studies._common import finish, load_average
from studies.bench_map import matmul_s


def _device(design, nom, scale, rng):

    base = BuildTolerances()
    tol = dataclasses.replace(base, position_m=base.position_m * scale,
                              tilt_rad=base.tilt_rad * scale,
                              turns_relative=base.turns_relative * scale,
                              core_offset_m=base.core_offset_m * scale)
    ab = random_asbuilt(nom.coils, tol, rng, mu_r=450.0)
    return ab, tol, CoilArray.from_design(design.replace(asbuilt=ab))


def _one(design, nom, ab, tol, truth, plan_name, n_probe, rng, held_out, a_true, rounds=2):

    plan = cal.onboard_plan(nom.sensor_positions_m(), nom.n_coils)
    if plan_name != "onboard":
        plan = plan.concat(cal.probe_plan(cal.workspace_points(design, n_probe, rng),
                                          nom.n_coils))
    meas = cal.simulate(truth, plan, rng)
    t0, c0 = time.perf_counter(), time.process_time()
    res = cal.fit(nom, meas, tol, progress=False, coupling_rounds=rounds)
    fit_s, fit_cpu_s = time.perf_counter() - t0, time.process_time() - c0
    calib = CoilArray.from_design(design.replace(
        asbuilt=AsBuilt.from_parameters(nom.coils, res.params, tol)))
    e_cal = cal.actuation_error(calib.actuation_matrix(held_out), a_true)
    e_nom = cal.actuation_error(nom.actuation_matrix(held_out), a_true)
    true = ab.parameters(nom.coils)
    ident = res.identifiable
    z = np.abs(res.params - true)[ident] / res.std_error[ident]
    paired = {kj for c in res.combined if c["identifiable"] for kj in c["parameters"]}
    zc = [abs(c["value"] - sum(w * true[kj] for w, kj in zip(c["coefficients"],
                                                            c["parameters"]))) / c["std_error"]
          for c in res.combined if c["identifiable"]]
    return {"plan": plan_name, "rows": len(meas), "fit_s": fit_s, "fit_cpu_s": fit_cpu_s,
            "nominal_max": float(e_nom.max()), "nominal_median": float(np.median(e_nom)),
            "calibrated_max": float(e_cal.max()), "calibrated_median": float(np.median(e_cal)),
            "identifiable": int(ident.sum()), "parameters": int(res.fitted.sum()),
            "within_3se": float((z < 3).mean()) if len(z) else float("nan"),
            "combined": len(zc), "combined_within_3se": int(np.sum(np.array(zc) < 3)),
            "cost_per_reading_axis": res.cost_after / (3 * len(meas)),
            "worst_z": float(max(z.max() if len(z) else 0.0, max(zc, default=0.0))),
            "unidentifiable": sorted({n for (k, j), n in np.ndenumerate(_names(res))
                                      if res.fitted[k, j] and not ident[k, j]
                                      and (k, j) not in paired}),
            "calibrated": calib, "asbuilt": res.params}


def _names(res):

    out = np.empty(res.params.shape, dtype=object)
    for k in range(out.shape[0]):
        for j, name in enumerate(PARAMETERS):
            out[k, j] = name
    return out


def _run_part(design, truth_design, calibrated_design, out_dir, duration, repeats=1):

    result, maps = {"repeats": []}, {}
    for seed in range(repeats):
        dirs, rms = {}, {}
        for name, map_design in (("true", truth_design), ("calibrated", calibrated_design),
                                 ("nominal", design)):
            # the maps are compared, not the sensor calibration; a repeat reuses the map and
            # draws other sensor noise (and meets other loop timing)
            dirs[name] = out_dir / (f"run-{name}" + (f"-seed{seed}" if seed else ""))
            s = run_simulation(RunSettings(duration_s=duration, calibrate=False, seed=seed),
                               design=map_design, out=dirs[name], progress=False,
                               plant=truth_design, map_path=maps.get(name))
            maps.setdefault(name, dirs[name] / "map.npz")
            rms[name] = s["force_error_rms_n"]
            rms[f"{name}_running_fraction"] = s["running_fraction"]
        rms["calibrated_over_true"] = rms["calibrated"] / rms["true"]
        common = _common_steps({k: dirs[k] for k in ("true", "calibrated")})
        rms.update({f"{k}_common": v for k, v in common.items()})
        rms["calibrated_over_true_common"] = common["calibrated"] / common["true"]
        result["repeats"].append(rms)
    result.update(result["repeats"][0])
    for key in ("calibrated_over_true", "calibrated_over_true_common"):
        result[f"{key}_median"] = float(np.median([r[key] for r in result["repeats"]]))
    return result


def _common_steps(dirs: dict) -> dict:
    """Force error RMS (N) of each run over the steps where every run renders (state
    'running'): a localizer that declares itself lost (protection level over the alert limit)
    drops those steps from its own RMS, so the maps are compared on the same steps."""

    cols = {k: np.genfromtxt(d / "run.csv", delimiter=",", names=True, dtype=None,
                             encoding=None) for k, d in dirs.items()}
    first = next(iter(dirs))
    c0 = cols[first]
    p = np.c_[c0["x_m"], c0["y_m"], c0["z_m"]]
    period = float(np.median(np.diff(c0["t_s"])))
    f_obj = Scene.load(dirs[first] / "scene.npz").force(p, np.gradient(p, period, axis=0))
    both = np.logical_and.reduce([c["state"] == "running" for c in cols.values()])
    out = {}
    for k, c in cols.items():
        err = np.c_[c["fx_n"], c["fy_n"], c["fz_n"]] - f_obj
        out[k] = float(np.sqrt(np.mean(np.sum(err[both] ** 2, axis=1)))) if both.any() \
            else float("nan")
    out["steps"] = int(both.sum())
    return out


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("study-out/calibration"))
    ap.add_argument("--devices", type=int, default=2)
    ap.add_argument("--probe", type=int, default=48)
    ap.add_argument("--scales", default="1,2", help="tolerance scales, comma-separated")
    ap.add_argument("--plans", default="onboard,onboard+probe",
                    help="measurement plans, comma-separated: onboard, onboard+probe")
    ap.add_argument("--quick", action="store_true", help="2 x 2 array, one device, scale 1")
    ap.add_argument("--run", action="store_true", help="also the run --simulate comparison")
    ap.add_argument("--duration", type=float, default=2.0, help="run duration, s")
    ap.add_argument("--seed", type=int, default=0, help="seed of the devices and readings")
    ap.add_argument("--repeats", type=int, default=1,
                    help="runs per map (other sensor-noise seeds), with --run")
    ap.add_argument("--coupling-rounds", type=int, default=2,
                    help="at most this many exact coupled solves of the fitted device")
    args = ap.parse_args(argv)

    design = default_design()
    scales = [float(s) for s in args.scales.split(",")]
    if args.quick:
        if args.run:
            ap.error("--run needs the 3 x 3 board (the runner's sensor pipeline reads 18 "
                     "sensors): drop --quick")
        design = design.replace(**{"array.rows": 2, "array.columns": 2})
        args.devices, scales = 1, [1.0]
    args.out.mkdir(parents=True, exist_ok=True)
    nom = CoilArray.from_design(design)
    rng = np.random.default_rng(args.seed)
    held_out = cal.workspace_points(design, 200, rng)
    rows, runs = [], []
    for scale in scales:
        for dev in range(args.devices):
            ab, tol, truth = _device(design, nom, scale, rng)
            a_true = truth.actuation_matrix(held_out)
            for plan_name in args.plans.split(","):
                r = _one(design, nom, ab, tol, truth, plan_name, args.probe, rng, held_out,
                         a_true, args.coupling_rounds)
                if scale == scales[0] and plan_name != "onboard" and len(runs) == dev:
                    runs.append((ab, r["asbuilt"], tol))
                r.pop("calibrated")
                r.pop("asbuilt")
                rows.append({"scale": scale, "device": dev, **r})
                print(_row(rows[-1]), flush=True)
    result = {"design": f"{design.array.rows} x {design.array.columns}", "rows": rows,
              "load_average": load_average(),
              "matmul_2000_s": matmul_s()}
    if args.run:

        result["run"] = []
        for dev, (ab, params, tol) in enumerate(runs):
            truth_design = design.replace(asbuilt=ab, name="true-device")
            calibrated = design.replace(asbuilt=AsBuilt.from_parameters(nom.coils, params,
                                                                        tol),
                                        name="calibrated")
            (args.out / f"device{dev}").mkdir(parents=True, exist_ok=True)
            for name, d in (("true", truth_design), ("calibrated", calibrated)):
                (args.out / f"device{dev}" / f"{name}.toml").write_text(design_to_toml(d))
            result["run"].append(_run_part(design, truth_design, calibrated,
                                           args.out / f"device{dev}", args.duration,
                                           args.repeats))
            print(_run_row(dev, result["run"][-1]), flush=True)
        if runs:
            for key in ("calibrated_over_true", "calibrated_over_true_common"):
                result[f"run_median_{key}"] = float(np.median(
                    [x[key] for r in result["run"] for x in r["repeats"]]))
    return finish(args.out / "calibration.json", result, _print)


def _row(r) -> str:
    return (f"scale {r['scale']:.1f} device {r['device']} {r['plan']:<14} rows {r['rows']:4d} "
            f"fit {r['fit_s']:6.1f} s (CPU {r['fit_cpu_s']:.1f} s, cost/reading axis "
            f"{r['cost_per_reading_axis']:.2f}) | A(p) error max/median: nominal {r['nominal_max']:.2%} / "
            f"{r['nominal_median']:.3%}, calibrated {r['calibrated_max']:.2%} / "
            f"{r['calibrated_median']:.3%} | identifiable {r['identifiable']}/"
            f"{r['parameters']}, within 3 SE {r['within_3se']:.0%}, identifiable pairs "
            f"{r['combined_within_3se']}/{r['combined']} within 3 SE, worst "
            f"{r['worst_z']:.1f} SE | at priors: "
            f"{', '.join(r['unidentifiable']) or '-'}")


def _print(result) -> None:
    print(f"\n{result['design']} array, load average {result['load_average']}, same-process "
          f"2000 x 2000 matmul {result['matmul_2000_s'] * 1e3:.0f} ms")
    for r in result["rows"]:
        print(_row(r))
    for dev, run in enumerate(result.get("run", [])):
        print(_run_row(dev, run))
    if result.get("run"):
        print(f"run: median over devices and runs calibrated / true = "
              f"{result['run_median_calibrated_over_true']:.3f}, on the common running steps "
              f"{result['run_median_calibrated_over_true_common']:.3f}")


def _run_row(dev: int, run: dict) -> str:
    maps = ("true", "calibrated", "nominal")
    lines = []
    for seed, r in enumerate(run["repeats"]):
        lines.append(
            f"run --simulate --as-built, device {dev} seed {seed}, force error RMS (running "
            "fraction): " + ", ".join(f"{k} map {r[k] * 1e3:.1f} mN "
                                      f"({r[k + '_running_fraction']:.0%})" for k in maps)
            + f"; calibrated / true = {r['calibrated_over_true']:.3f} | on the "
            f"{r['steps_common']} steps both render: "
            + ", ".join(f"{k} {r[k + '_common'] * 1e3:.1f} mN" for k in maps[:2])
            + f"; calibrated / true = {r['calibrated_over_true_common']:.3f}")
    lines.append(f"device {dev}: median over {len(run['repeats'])} runs calibrated / true = "
                 f"{run['calibrated_over_true_median']:.3f}, on the common steps "
                 f"{run['calibrated_over_true_common_median']:.3f}")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
