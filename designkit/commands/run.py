"""``designkit run --simulate``: the hardware rendering runner closed around the simulated device.

The runner is firmware_io's (the code that runs on the controller); the device is
:mod:`designkit.sim` (exact array physics, R-L coils, register-level sensors and PWM boards).
Writes ``run.csv`` (one row per control step), ``summary.json``, ``run.png`` (thesis Fig. 4.5-like)
and ``loop_timing.png`` into ``--out``. ``--scene FILE`` runs a compiled scene (``designkit scene
compile``: its objects and lambda); otherwise ``--object`` is compiled with ``--lambda`` or, by
default, the design's ``render.stiffness_n_per_m`` capped at what the device renders over the
object (:func:`designkit.sim.run.choose_lambda`). On the controller itself use
``python -m firmware_io.run --bus 1 --map FILE --scene FILE``.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from ..design import load_design
from ..errors import BadInputError
from ..sim import RunSettings, run_simulation
from ..sim.magnets_run import run_pinch
from ..support.atomic import write_json_atomic
from .common import add_design_argument, add_progress_argument, show_progress, staged_folder

OBJECTS = ("plane", "hemisphere", "half-cylinder", "wedge")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--simulate", action="store_true",
                        help="run on the simulated device (required here; on the controller use "
                             "python -m firmware_io.run)")
    parser.add_argument("--object", default=None,
                        help=f"virtual object: {', '.join(OBJECTS)} or an STL/PLY mesh path "
                             "(default hemisphere; not with --scene)")
    parser.add_argument("--scene", type=Path, default=None,
                        help="a compiled scene (designkit scene compile ... --out FILE.npz) to "
                             "run: its objects and lambda, compiled for the map's design")
    parser.add_argument("--trajectory", default="slide",
                        help="slide | poke | tilt (a slide tilting the magnet up to 45 deg) | "
                             "pinch (two fingers squeeze a block: a design with two [[magnets]]) | "
                             "FILE.csv with columns t_s,x_m,y_m,z_m and optionally tilt_deg "
                             "(0..180), azimuth_deg (default slide)")
    parser.add_argument("--duration", type=float, default=None,
                        help="simulated time, s, up to 600 (default: the trajectory's own, 4 s "
                             "slide and tilt, 3 s poke); the finger keeps the trajectory's speed: a "
                             "shorter run cuts it, a longer one holds its last point")
    parser.add_argument("--faults", default="none",
                        help="none | default (each fault type once) | TYPE@S,TYPE@S,...")
    add_design_argument(parser)
    parser.add_argument("--map", type=Path, default=None,
                        help="map file (default: build one for the design into --out)")
    parser.add_argument("--method", default="model", help="localization method (default model)")
    parser.add_argument("--period-ms", type=float, default=1.0,
                        help="control period, ms, 0.1..50 (default 1)")
    parser.add_argument("--unipolar", action="store_true", help="unipolar drive (the thesis')")
    parser.add_argument("--rows", choices=["force", "fz"], default="force",
                        help="render the object's 3-D force (default) or only Fz (thesis eq. 4.6)")
    parser.add_argument("--lambda", dest="lam", type=float, default=None,
                        help="force constant, N/m (default: the design's "
                             "render.stiffness_n_per_m, capped at what the device renders over "
                             "the object, eq. 4.3; not with --scene)")
    parser.add_argument("--as-built", dest="as_built", type=Path, default=None,
                        help="design TOML of the device as built ([asbuilt]): the simulated "
                             "plant; the runner uses the map of --design (nominal or "
                             "calibrated) and, when --design is calibrated, the summary also "
                             "gives the force error with the nominal map")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the simulated sensor noise, an integer (default 0)")
    parser.add_argument("--keep-sensors", dest="keep_sensors", default="",
                        help="sensors the scene keeps in their linear range while rendering "
                             "(indices in the map's order, e.g. 0-8 or 3,4,5; default none: "
                             "`designkit check` lists the currents that blind each sensor)")
    parser.add_argument("--background-mt", dest="background_mt", default="0,0,0",
                        help="a uniform ambient field X,Y,Z in mT (array frame) that appears "
                             "after the start-up calibration, e.g. 0,0,1 (default none)")
    parser.add_argument("--out", type=Path, default=Path("run-out"),
                        help="output folder (default ./run-out)")
    add_progress_argument(parser)


def run(args: argparse.Namespace) -> int:
    if not args.simulate:
        raise BadInputError("--simulate", "given (this machine has no coil hardware; on the "
                            "controller run `python -m firmware_io.run --bus N --map F --scene F`)",
                            False)
    if args.trajectory == "pinch":
        return _pinch(args)
    # staged: a run that fails (bad trajectory file, a fault, Ctrl-C) leaves no half-written
    # folder (map and scene without a summary) behind
    with staged_folder(args.out) as stage:
        summary = run_simulation(_settings(args), design=args.design, map_path=args.map,
                                 out=stage, progress=show_progress(args), plant=args.as_built)
        if args.as_built is not None:
            _as_built_comparison(args, summary, stage)
    print(f"wrote {args.out}/run.csv, summary.json, run.png, loop_timing.png: force error RMS "
          f"{_mn(summary['force_error_rms_n'])} (p95 {_mn(summary['force_error_p95_n'])}) on an "
          f"object force RMS {_mn(summary['object_force_rms_n'])}, localization MAE "
          f"{_mm(summary['localization_mae_m'])}, loop p99 {_us(summary['loop_p99_s'])}")
    print("  " + lambda_line(summary))
    print(f"  faults injected {len(summary['faults'])}, faults the runner detected "
          f"{len(summary['fault_log'])}")
    if summary["fixes"]:
        print(f"  sensor side: {summary['fixes']} fixes, {summary['fixes_trusted_fraction']:.1%} "
              f"trusted, {summary['trusted_fixes_beyond_5mm']} trusted more than 5 mm off; "
              "fault detection excluded sensors "
              f"{summary['fault_excluded_sensors'] or 'none'}")
    if summary["trajectory_played"] != "whole":
        print(f"  simulated {summary['duration_s']:g} s of the "
              f"{summary['trajectory_duration_s']:g} s trajectory at its own speed "
              f"({summary['trajectory_played']})")
    for line in summary["drive_violations"]:
        print(f"  drive: {line} -- simulated as designed; python -m firmware_io.run refuses it")
    for f in summary["faults"]:
        print("  fault " + _fault_line(f))
    for f in summary.get("faults_not_injected", []):
        print(f"  fault {f['fault']} @ {f['scheduled_s']:.3f} s: not injected ({f['why']})")
    return 0


def _pinch(args: argparse.Namespace) -> int:
    """``--trajectory pinch``: two magnets squeeze a block (:func:`designkit.sim.magnets_run.
    run_pinch`); one line per magnet."""
    if args.as_built is not None:
        raise BadInputError("--as-built", "left out with --trajectory pinch", args.as_built)
    with staged_folder(args.out) as stage:
        summary = run_pinch(_settings(args), design=args.design, map_path=args.map, out=stage,
                            progress=show_progress(args))
    print(f"wrote {args.out}/run.csv, summary.json, "
          + ", ".join(f"run_{m['name']}.png" for m in summary["magnets"])
          + f" (and no-pair-compensation/): running fraction {summary['running_fraction']:.1%}, "
          "condition number median "
          + ("n/a" if summary["condition_median"] is None
             else f"{summary['condition_median']:.3g}"))
    for m in summary["magnets"]:
        print(f"  {m['name']}: force error RMS {_mn(m['force_error_rms_n'])} on a commanded "
              f"force RMS {_mn(m['force_rms_n'])} (without the pair force compensated "
              f"{_mn(m['force_error_rms_without_pair_compensation_n'])}), localization MAE "
              f"{_mm(m['localization_mae_m'])}, {m['trusted_wrong_fixes']} trusted fixes more "
              "than 5 mm off")
    if summary["running_fraction"] == 0 and summary["fault_log"]:
        first = summary["fault_log"][0]
        print(f"  the coils stayed off (the safe state while a magnet is untrusted): "
              f"{first['state']}: {first['detail']}")
    return 0


def _settings(args: argparse.Namespace) -> RunSettings:
    """The :class:`designkit.sim.RunSettings` every run of this command shares."""
    return RunSettings(obj=args.object, trajectory=args.trajectory, duration_s=args.duration,
                       faults=args.faults, method=args.method, period_s=args.period_ms * 1e-3,
                       unipolar=args.unipolar, rows=args.rows, lam_n_per_m=args.lam,
                       seed=args.seed, keep_sensors=_sensor_list(args.keep_sensors),
                       background_t=_field_t(args.background_mt), scene_path=args.scene)


def _field_t(text: str) -> tuple:
    """'0,0,1' (mT) -> (0.0, 0.0, 0.001) T."""
    try:
        values = tuple(float(v) * 1e-3 for v in text.split(","))
    except ValueError:
        raise BadInputError("--background-mt", "three numbers X,Y,Z in mT, e.g. 0,0,1",
                            text) from None
    if len(values) != 3:
        raise BadInputError("--background-mt", "three numbers X,Y,Z in mT, e.g. 0,0,1", text)
    return values


def _sensor_list(text: str) -> tuple:
    """'0-8,12' -> (0, 1, ..., 8, 12); '' -> ()."""
    out = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        a, _, b = part.partition("-")
        try:
            lo, hi = int(a), int(b or a)
        except ValueError:
            raise BadInputError("--keep-sensors", "sensor indices or ranges, e.g. 0-8 or 3,4,5",
                                text) from None
        if not 0 <= lo <= hi:
            raise BadInputError("--keep-sensors", "ranges lo-hi with 0 <= lo <= hi", part)
        out.extend(range(lo, hi + 1))
    return tuple(out)


def lambda_line(summary: dict) -> str:
    """Which force constant the run used and why (:func:`designkit.sim.run.choose_lambda`)."""
    lam, source = summary["lambda_n_per_m"], summary["lambda_source"]
    if "lambda_renderable_n_per_m" not in summary:
        return f"lambda = {lam:.4g} N/m ({source})"
    where = ", ".join(f"{x * 1e3:.0f}" for x in summary["lambda_limiting_point_m"])
    cant = summary["lambda_unrenderable_points"]
    return (f"lambda = {lam:.4g} N/m: the design asks {summary['lambda_design_n_per_m']:.4g}, "
            f"the device renders up to {summary['lambda_renderable_n_per_m']:.4g} over the "
            f"object (eq. 4.3, limited at ({where}) mm)"
            + (f"; at {cant} of its {summary['lambda_surface_points']} surface points it "
               "cannot cancel the cores' pull, and renders no object force there" if cant
               else ""))


def _fault_line(f: dict) -> str:
    """One fault's row: injected, its own detection, currents off, resumed (ms after it), and
    the time to run again once the fault's cause is gone."""
    def ms(v):
        return "-" if v is None else f"{v * 1e3:.0f} ms"

    back = ("" if f.get("recovered_s") is None else
            f", running again {ms(f['recovered_s'])} after it cleared")
    if f["state"] is None:
        return (f"{f['fault']} @ {f['injected_s']:.3f} s: not detected in its own state "
                f"(state then: {f['state_at_injection']}){back}")
    ended = ("still on at the end" if f["ended_s"] is None else
             f"ended +{ms(f['ended_s'])} into {f['ended_into']}")
    return (f"{f['fault']} @ {f['injected_s']:.3f} s: detected +{ms(f['time_to_safe_s'])}, "
            f"currents off +{ms(f['currents_off_s'])}, {ended}{back}")


def _as_built_comparison(args, summary, stage) -> None:
    """With a calibrated --design, the same run with the nominal map (into nominal-map/); the
    force error of both in summary.json's ``as_built``."""
    design = load_design(args.design)
    out = {"plant": summary.get("plant"), "map_design": design.name,
           "force_error_rms_n": summary["force_error_rms_n"]}
    if design.asbuilt is not None:
        nominal = dataclasses.replace(design, asbuilt=None)
        other = run_simulation(_settings(args), design=nominal, out=stage / "nominal-map",
                               progress=show_progress(args), plant=args.as_built)
        out["nominal_map_force_error_rms_n"] = other["force_error_rms_n"]
    summary["as_built"] = out
    write_json_atomic(stage / "summary.json", summary)
    print(f"as built ({out['plant']}): force error RMS {_mn(out['force_error_rms_n'])} with the "
          f"map of {design.name}" + (f", {_mn(out['nominal_map_force_error_rms_n'])} with the "
                                     "nominal map" if "nominal_map_force_error_rms_n" in out
                                     else ""))


def _mn(v):
    return "n/a" if v is None else f"{v * 1e3:.2f} mN"


def _mm(v):
    return "n/a" if v is None else f"{v * 1e3:.2f} mm"


def _us(v):
    return "n/a" if v is None else f"{v * 1e6:.0f} us"
