"""``designkit calibrate``: fit the as-built device to field measurements, or plan them.

``--measurements M.csv --out DIR``: reads the readings (:mod:`designkit.calibration.
measurements`), fits the as-built parameters by regularized nonlinear least squares (priors:
the design's ``[asbuilt.tolerances]``, default :class:`designkit.design.asbuilt.BuildTolerances`) and
writes DIR/asbuilt.toml (a design file) and DIR/calibration.json (parameters with standard
errors, residuals before/after per group, condition, parameters the data cannot see).
``--plan [--points N] --out plan.csv``: probe points and currents from the fit's Fisher
information over the workspace region, and what the onboard sensors alone identify (also in
plan.json next to it). ``--simulate plan.csv --as-built TRUE.toml --out M.csv [--onboard]
[--noise-t SIGMA] [--seed N]``: the measurement file an as-built device would give.
A fit that does not converge writes nothing. Reference: docs/calibration.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

from .. import calibration as cal
from ..calibration.fit import IDENTIFIABLE_RATIO
from ..calibration.plan import make_plan
from ..design import design_to_toml, load_design
from ..design.asbuilt import PARAMETERS, AsBuilt, BuildTolerances
from ..errors import BadInputError
from ..model.array import CoilArray, array_for_design
from ..support.atomic import atomic_path, write_json_atomic, write_text_atomic
from .common import add_progress_argument, check_output, show_progress, staged_folder


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--measurements", type=Path, default=None,
                        help="CSV: x_m,y_m,z_m,i1_a..iN_a,bx_t,by_t,bz_t[,sigma_t] (m, A, T)")
    parser.add_argument("--design", type=Path, default=None,
                        help="nominal design TOML or name (default: the thesis device); its "
                             "[asbuilt.tolerances] are the priors")
    parser.add_argument("--out", type=Path, default=None,
                        help="output folder (fit) or plan CSV file (--plan)")
    parser.add_argument("--plan", action="store_true",
                        help="propose probe points and currents instead of fitting")
    parser.add_argument("--points", type=int, default=48,
                        help="probe points of the plan (default 48, each coil alone at 1 A)")
    parser.add_argument("--magnet-moment", default=None, metavar="MX,MY,MZ",
                        help="measured magnet moment, A m^2 (e.g. from the localizer's fits), "
                             "recorded in asbuilt.toml's [magnet]")
    parser.add_argument("--simulate", type=Path, default=None, metavar="PLAN.csv",
                        help="write the readings a device would give at the rows of PLAN.csv "
                             "(a --plan file, or any measurement file: its readings are "
                             "replaced) to --out, instead of fitting; the device: --as-built")
    parser.add_argument("--as-built", type=Path, default=None, metavar="TRUE.toml",
                        help="with --simulate: the device as built, a design file whose "
                             "[asbuilt] tables give each coil's offsets, tilt, turns and core "
                             "(without them: the nominal device)")
    parser.add_argument("--onboard", action="store_true",
                        help="with --simulate: also the onboard sensors' readings, each coil "
                             "alone at +-2 A (what the start-up calibration reads)")
    parser.add_argument("--noise-t", type=float, default=None, metavar="SIGMA",
                        help="with --simulate: Gaussian reading noise per axis, T (default: "
                             "each row's sigma_t), written as sigma_t; 0: noiseless readings, "
                             "the plan's sigma_t kept as the fit's weights")
    parser.add_argument("--seed", type=int, default=0,
                        help="with --simulate: seed of the noise (default 0)")
    parser.add_argument("--coupling-rounds", type=int, default=2,
                        help="at most this many refits after an exact coupled solve of the "
                             "fitted device (fewer once the coupling converges; default 2, "
                             "0..3)")
    add_progress_argument(parser)


def run(args: argparse.Namespace) -> int:
    if args.out is None:
        raise BadInputError("--out", "a folder (fit) or a CSV file (--plan, --simulate)", None)
    if args.simulate is not None:
        return _simulate(args)
    for option, given in (("--as-built", args.as_built is not None), ("--onboard", args.onboard),
                          ("--noise-t", args.noise_t is not None)):
        if given:
            raise BadInputError(option, "given together with --simulate", "without it")
    design = load_design(args.design)
    nominal = dataclasses.replace(design, asbuilt=None)
    tol = design.asbuilt.tolerances if design.asbuilt is not None else BuildTolerances()
    if args.plan:
        return _plan(args, nominal, tol)
    if args.measurements is None:
        raise BadInputError("--measurements", "a CSV file (or pass --plan)", None)
    if not 0 <= args.coupling_rounds <= 3:
        raise BadInputError("--coupling-rounds", "in 0..3", args.coupling_rounds)
    moment = _moment(args.magnet_moment)
    check_output(args.out, folder=True)
    meas = cal.read_csv(args.measurements, nominal.n_coils,
                        nominal.sensors.range_t)
    array = array_for_design(nominal)
    res = cal.fit(array, meas, tol, coupling_rounds=args.coupling_rounds,
                  progress=show_progress(args))
    asbuilt = AsBuilt.from_parameters(array.coils, res.params, tol,
                                      f"designkit calibrate --measurements "
                                      f"{args.measurements.name}")
    built = dataclasses.replace(nominal, name=f"{nominal.name}-asbuilt", asbuilt=asbuilt)
    if moment is not None:
        built = _with_moment(built, moment)
    report = _report(res, meas, nominal)
    with staged_folder(args.out) as stage:
        write_text_atomic(stage / "asbuilt.toml", design_to_toml(built))
        write_json_atomic(stage / "calibration.json", report)
    print(f"wrote {args.out}/asbuilt.toml, calibration.json: {len(meas)} readings, residual RMS "
          f"{report['residual_rms_t']['before'] * 1e3:.4f} -> "
          f"{report['residual_rms_t']['after'] * 1e3:.4f} mT, condition "
          f"{report['condition']:.3g}, {len(report['unidentifiable'])} of "
          f"{report['n_parameters']} parameters stay at their priors")
    return 0


def _moment(text):
    if text is None:
        return None
    try:
        m = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise BadInputError("--magnet-moment", "three numbers MX,MY,MZ in A m^2", text) \
            from None
    if m.shape != (3,) or not np.all(np.isfinite(m)) or not np.any(m):
        raise BadInputError("--magnet-moment", "three finite numbers in A m^2, not all 0", text)
    return m


def _with_moment(design, moment):
    """The design with its magnet's moment set to ``moment`` (3,) A m^2."""
    norm = float(np.linalg.norm(moment))
    magnet = dataclasses.replace(design.magnet,
                                 magnetization_a_per_m=norm / design.magnet.volume_m3,
                                 direction=tuple(float(c) / norm for c in moment))
    return dataclasses.replace(design, magnet=magnet)


def _report(res, meas, nominal) -> dict:
    groups = meas.groups(nominal.sensor_poses()[0], cal.sensor_groups(nominal))
    by_group = {}
    for g in sorted(set(groups)):
        sel = groups == g
        by_group[g] = {"rows": int(sel.sum()),
                       "rms_before_t": _rms(res.residual_before_t[sel]),
                       "rms_after_t": _rms(res.residual_after_t[sel]),
                       "chi2_per_reading_before": _chi(res.residual_before_t[sel], meas, sel),
                       "chi2_per_reading_after": _chi(res.residual_after_t[sel], meas, sel)}
    params, unident = [], []
    paired = {kj for c in res.combined if c["identifiable"] for kj in c["parameters"]}
    for k in range(nominal.n_coils):
        for j, name in enumerate(PARAMETERS):
            if not res.fitted[k, j]:
                continue
            ident = bool(res.identifiable[k, j])
            params.append({"coil": k + 1, "parameter": name, "value": float(res.params[k, j]),
                           "std_error": float(res.std_error[k, j]),
                           "prior": float(res.prior[k, j]), "identifiable": ident})
            if not ident and (k, j) not in paired:
                unident.append(f"coil {k + 1} {name}")
    return {"design": nominal.name, "design_sha256": nominal.spec_hash(), "rows": len(meas),
            "n_parameters": len(params), "iterations": res.iterations,
            "condition": res.condition, "cost_before": res.cost_before,
            "cost_after": res.cost_after,
            "residual_rms_t": {"before": _rms(res.residual_before_t),
                               "after": _rms(res.residual_after_t)},
            "residual_by_group": by_group, "parameters": params, "unidentifiable": unident,
            "combined": [{"parameters": [f"coil {k + 1} {PARAMETERS[j]}" for k, j in
                                         c["parameters"]],
                          **{key: c[key] for key in ("correlation", "coefficients", "value",
                                                     "std_error", "identifiable")}}
                         for c in res.combined]}


def _rms(r) -> float:
    return float(np.sqrt(np.mean(np.square(r)))) if len(r) else 0.0


def _chi(r, meas, sel) -> float:
    return float(np.mean(np.square(r / meas.sigma_t[sel, None])))


def _plan(args, nominal, tol) -> int:
    if not 1 <= args.points <= 500:
        raise BadInputError("--points", "in 1..500", args.points)
    out = check_output(args.out, folder=False)
    array = array_for_design(nominal)
    res = make_plan(nominal, array, args.points, tol)
    summary = {"points": args.points, "onboard": _seen(res["onboard_ratio"], res["mask"]),
               "with_plan": _seen(res["plan_ratio"], res["mask"])}
    cal.write_csv(out, res["plan"], readings=False)
    write_json_atomic(out.with_suffix(".json"), summary)
    on = summary["onboard"]
    print(f"wrote {out} ({len(res['plan'])} probe readings at {args.points} points, each coil "
          f"alone at 1 A) and {out.with_suffix('.json').name}")
    print(f"onboard arrays alone identify {len(on['identifiable'])} of {on['n_parameters']} "
          f"parameters; they cannot identify: {', '.join(on['unidentifiable']) or 'none'}")
    print(f"with the plan: {len(summary['with_plan']['unidentifiable'])} stay at their priors")
    return 0


def _seen(ratio, mask) -> dict:
    ident, unident = [], []
    for k, j in zip(*np.nonzero(mask)):
        name = f"coil {k + 1} {PARAMETERS[j]}"
        (ident if ratio[k, j] < IDENTIFIABLE_RATIO else unident).append(name)
    return {"n_parameters": int(mask.sum()), "identifiable": ident, "unidentifiable": unident,
            "posterior_over_prior": {f"coil {k + 1} {PARAMETERS[j]}": float(ratio[k, j])
                                     for k, j in zip(*np.nonzero(mask))
                                     if math.isfinite(ratio[k, j])}}


def _simulate(args) -> int:
    """``--simulate PLAN.csv --as-built TRUE.toml --out M.csv``: the readings of the as-built
    device (its exact coupled model, sensors where the nominal design puts them) at the plan's
    rows, plus Gaussian noise; refused when a reading would clip at the sensor range."""
    if args.plan or args.measurements is not None:
        raise BadInputError("--simulate", "alone (not with --plan or --measurements)",
                            str(args.simulate))
    if args.as_built is None:
        raise BadInputError("--as-built", "a design file of the device to simulate (with "
                            "--simulate)", None)
    if args.noise_t is not None and not (math.isfinite(args.noise_t) and args.noise_t >= 0):
        raise BadInputError("--noise-t", "a noise >= 0 T (0: noiseless)", args.noise_t)
    out = check_output(args.out, folder=False)
    true = load_design(args.as_built)
    plan = cal.read_csv(args.simulate, true.n_coils, true.sensors.range_t, readings=False,
                        option="--simulate")
    n_onboard = 0
    if args.onboard:
        onboard = cal.onboard_plan(true.sensor_poses()[0], true.n_coils)
        n_onboard, plan = len(onboard), onboard.concat(plan)
    noise = plan
    if args.noise_t is not None:
        noise = cal.Measurements(plan.points_m, plan.currents_a, plan.b_t,
                                 np.full(len(plan), float(args.noise_t)))
    meas = cal.simulate(CoilArray.from_design(true), noise, np.random.default_rng(args.seed))
    if args.noise_t is not None and args.noise_t > 0:
        plan = noise  # the file's sigma_t is the noise it was drawn with
    meas = cal.Measurements(meas.points_m, meas.currents_a, meas.b_t, plan.sigma_t)
    over = np.flatnonzero((np.abs(meas.b_t) >= true.sensors.range_t * (1 - 1e-9)).any(axis=1))
    if len(over):
        k = int(over[0])
        where = (f"onboard reading {k + 1}" if k < n_onboard
                 else f"{args.simulate.name}: row {k - n_onboard + 2}")
        raise BadInputError(f"--simulate: {where}", f"readings below the sensor range "
                            f"{true.sensors.range_t:g} T (lower that row's currents)",
                            [round(float(q), 6) for q in meas.b_t[k]])
    with atomic_path(out) as tmp:
        cal.write_csv(tmp, meas)
    print(f"wrote {out}: {len(meas)} readings of '{true.name}' "
          f"({'as built' if true.asbuilt is not None else 'nominal'}), noise "
          + (f"{args.noise_t:g} T" if args.noise_t is not None else "sigma_t of each row")
          + f", seed {args.seed}")
    return 0
