"""``designkit optimize``: design the real device -> ``OUT/optimize.json`` + ``OUT/design.toml``.

Default (``--problem device``): winding, wire gauge and 1010-steel core optimized together
(:func:`designkit.optimize.solve_device`) under R, supply, 5 L/R, thermal, window and mechanical
constraints; writes every constraint's margin and the optimum as a complete design file that
``--design`` accepts. ``--verify`` adds the global checks (multistart, ISRES, coarse grid).

``--problem coil`` keeps the thesis' eq. 2.14 coil-only problem (fixed wire, ``--core-model``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from .. import rules
from ..design import design_to_toml, load_design
from ..errors import BadInputError
from ..optimize import (CORE_MODEL_NAMES, GLOBAL_METHODS, CoilDesignProblem, device_design,
                        device_problem_for, evaluate_device, getdp_check, solve, solve_device,
                        verify_device)
from ..support.atomic import write_json_atomic, write_text_atomic
from .common import (add_design_argument, add_progress_argument, check_output, parse_lengths,
                     say_unfixable, show_progress, shown_margin)


DEVICE_KEYS = ("coil.", "wire.", "core.", "drive.supply_voltage_v", "drive.max_current_a",
               "workspace.z_min_m")
"""The design keys the device optimum replaces (:func:`designkit.optimize.device_design`):
a rule only other keys fix is broken by the optimum too (said before the solve)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_design_argument(parser)
    parser.add_argument("--out", type=Path, default=Path("designkit-optimize"),
                        help="output folder (default: ./designkit-optimize)")
    parser.add_argument("--problem", choices=("device", "coil"), default="device",
                        help="device (default): coil + wire + saturating core under every "
                             "constraint; coil: the thesis' eq. 2.14 winding-only problem")
    parser.add_argument("--objective", choices=("design-point", "rendering"), default=None,
                        help="device: the upward force at the design point (default) or the "
                             "smallest upward force the array renders over the workspace "
                             "region (bounded LP allocation)")
    parser.add_argument("--vary", action="append", default=[], metavar="KEY[=LO:HI]",
                        help="device: a layout key of the design file ([array]) becomes a "
                             "variable too, within LO:HI (a length in m as its name says, or "
                             "with its unit, 40mm:6cm; tilt_deg in degrees; default ranges in "
                             "docs/optimize.md): pitch_m (grid, hex), radius_m and tilt_deg "
                             "(ring); repeat or join with commas (--vary radius_m,tilt_deg). "
                             "Coils may not overlap; implies --objective rendering")
    parser.add_argument("--vary-pitch", action="store_true",
                        help="device: the same as --vary pitch_m")
    parser.add_argument("--pitch-range", default=None, metavar="LO:HI",
                        help="with --vary-pitch: pitch bounds, e.g. 30:60 or 30mm:6cm (a "
                             "number is mm; default 0.6 x the design's pitch to 2 x max outer "
                             "radius + 1 mm); the same as --vary pitch_m=LO:HI, where a "
                             "number is m as the key's name says")
    parser.add_argument("--verify", action="store_true",
                        help="device: also run the global checks (multistart, ISRES, grid)")
    parser.add_argument("--fem", action="store_true",
                        help="device: check the optimum's force and inductance against GetDP "
                             "(nonlinear 1010 steel; slow)")
    parser.add_argument("--core-model", choices=CORE_MODEL_NAMES, default="air",
                        help="coil problem only: force/inductance model (default air)")
    parser.add_argument("--starts", type=int, default=None,
                        help="multistart local runs (default: 4 device, 8 coil)")
    parser.add_argument("--global", dest="global_method", choices=GLOBAL_METHODS,
                        default="multistart", help="coil problem only: global stage")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the multistart points (default 0)")
    add_progress_argument(parser)


def run(args: argparse.Namespace) -> int:
    check_output(args.out, folder=True)
    design = load_design(args.design)
    starts = args.starts if args.starts is not None else (4 if args.problem == "device" else 8)
    if starts < 1:
        raise BadInputError("--starts", "a whole number >= 1", starts)
    if args.problem == "coil":
        if args.vary or args.vary_pitch:
            raise BadInputError("--vary", "only with --problem device (the coil problem has no "
                                "layout)", ",".join(args.vary) or "pitch_m")
        return _run_coil(args, design, starts)
    return _run_device(args, design, starts)


def _run_device(args, design, starts: int) -> int:
    t0 = time.perf_counter()
    vary = layout_variables(args.vary, args.vary_pitch, args.pitch_range)
    objective = args.objective or ("rendering" if vary else "design-point")
    problem = device_problem_for(design, objective=objective, vary=vary)
    say_unfixable("optimize", design, DEVICE_KEYS + tuple(f"array.{key}" for key in vary))
    if problem.supply_voltage_v < design.drive.supply_voltage_v:
        print(f"note: drive.supply_voltage_v = {design.drive.supply_voltage_v:g} V is above "
              f"drive.driver_max_voltage_v = {problem.supply_voltage_v:g} V (the driver "
              f"{design.drive.driver!r}); optimizing for {problem.supply_voltage_v:g} V")
    result = solve_device(problem, starts=starts, seed=args.seed,
                          progress=show_progress(args))
    data = {"design_name": design.name, "design_hash": design.spec_hash(),
            "problem": "device", **result.as_dict(problem)}
    optimum = device_design(design, result, problem)
    data["optimized_design_hash"] = optimum.spec_hash()
    data["rules_violated"] = [r.name for r in rules.violations(optimum)]
    if args.verify:
        data["verification"] = verify_device(problem, result, seed=args.seed,
                                             progress=show_progress(args))
    if getattr(args, "fem", False):
        data["getdp_check"] = getdp_check(optimum, data)
    if design.core is not None:
        data["base_design"] = evaluate_device(design, problem)
    data["total_seconds"] = time.perf_counter() - t0
    out = Path(args.out)
    # both files are complete before either is visible (atomic renames)
    write_json_atomic(out / "optimize.json", data)
    write_text_atomic(out / "design.toml", design_to_toml(optimum))
    print(device_summary(data))
    print(f"wrote {out / 'optimize.json'} and {out / 'design.toml'}")
    return 0


def _pitch_range(text: str | None):
    """``--pitch-range`` 'LO:HI' (the command line's lengths, :func:`parse_lengths`: a number
    is mm) -> (lo, hi) m; None passes through."""
    if text is None:
        return None
    return parse_lengths(text, "--pitch-range", 2, sep=":", valid_m=(1e-3, 1.0))


def _layout_range(name: str, text: str) -> tuple[float, float]:
    """``--vary NAME=LO:HI`` -> (lo, hi) in the key's unit: a length key (``*_m``) takes
    lengths with a unit or numbers in metres, as the design file's key (:func:`parse_lengths`
    with ``bare='m'``); an angle (``*_deg``) numbers in degrees."""
    option = f"--vary {name}"
    if name.endswith("_m"):
        return parse_lengths(text, option, 2, sep=":", valid_m=(1e-3, 1.0), bare="m")
    try:
        lo, hi = (float(q) for q in text.split(":"))
    except ValueError:
        raise BadInputError(option, "LO:HI, e.g. 0:40 (deg)", text) from None
    return lo, hi


def layout_variables(vary: list[str], vary_pitch: bool = False,
                     pitch_range: str | None = None) -> dict:
    """``--vary`` (and its pitch aliases) -> {layout key: (lo, hi) or None}; a key's layout is
    checked by the device problem (:func:`designkit.optimize.search_space.device_space`)."""
    if pitch_range is not None and not vary_pitch:
        raise BadInputError("--pitch-range", "given together with --vary-pitch", pitch_range)
    out: dict = {"pitch_m": _pitch_range(pitch_range)} if vary_pitch else {}
    for item in vary:
        for part in (q.strip() for q in item.split(",")):
            if not part:
                raise BadInputError("--vary", "KEY[=LO:HI][,KEY...]", item)
            name, _, rng = part.partition("=")
            name = name.strip()
            if name in out:
                raise BadInputError("--vary", "each layout key once", name)
            out[name] = _layout_range(name, rng) if rng else None
    return out


LAYOUT_ROWS = {"pitch_m": ("array pitch (mm)", 1e3, ".2f"),
               "radius_m": ("ring radius (mm)", 1e3, ".2f"),
               "tilt_deg": ("ring tilt (deg)", 1.0, ".2f")}
"""Summary rows of the layout keys: label, scale, format."""


def device_summary(data: dict) -> str:
    """Table of the optimum and its constraint margins (units in the labels)."""
    rows = [
        ("winding inner/outer radius (mm)",
         f"{data['inner_radius_m'] * 1e3:.2f} / {data['outer_radius_m'] * 1e3:.2f}"),
        ("winding length (mm)", f"{data['length_m'] * 1e3:.2f}"),
        ("turns", f"{data['turns']}"),
        ("wire bare/insulated (mm)",
         f"{data['wire_diameter_m'] * 1e3:.3f} / {data['insulated_wire_diameter_m'] * 1e3:.3f}"),
        ("core radius/length/protrusion (mm)",
         f"{data['core_radius_m'] * 1e3:.2f} / {data['core_length_m'] * 1e3:.2f} / "
         f"{data['core_protrusion_m'] * 1e3:.2f}"),
        (f"R at {data['temperature_c']:g} C (ohm)", f"{data['resistance_ohm']:.4g}"),
        (f"L secant at {data['current_a']:g} A (mH)", f"{data['inductance_h'] * 1e3:.4g}"),
        ("5 tau (ms)", f"{data['settling_time_s'] * 1e3:.4g}"),
        ("supply (V) / current (A)", f"{data['supply_voltage_v']:g} / {data['current_a']:g}"),
        (f"upward Fz at {data['design_height_m'] * 1e3:g} mm (mN)",
         f"{data['force_n'] * 1e3:.1f}"),
    ]
    rend = data.get("rendering")
    if rend:
        varied = data.get("layout_varied", [])
        layout = data.get("layout", {})
        for key in [k for k in LAYOUT_ROWS if k in layout] or ["pitch_m"]:
            label, scale, fmt = LAYOUT_ROWS[key]
            value = layout.get(key, data["pitch_m"])
            rows.append((f"{label}{' (optimized)' if key in varied else ''}",
                         f"{value * scale:{fmt}}"))
        rows.append((f"rendering: smallest upward Fz over {len(rend['points_m'])} points (mN)",
                     f"{rend['min_upward_force_n'] * 1e3:.1f}"))
    w = max(len(r[0]) for r in rows)
    lines = [f"{k:<{w}}  {v}" for k, v in rows]
    lines.append("constraints (margin >= 0 is met):")
    for name, c in data["constraints"].items():
        lines.append(f"  {name:<28} value {c['value']:.5g}  limit {c['limit']:.5g}  "
                     f"margin {shown_margin(c):+.4g}  {'ok' if c['met'] else 'VIOLATED'}  ({c['note']})")
    lines.append(f"core model: {data['core_model']}; {data['fast_evaluations']} fast + "
                 f"{data['panel_evaluations']} panel evaluations in {data['seconds']:.2f} s")
    chk = data.get("fast_model_check")
    if chk:
        lines.append(
            f"fast model vs panel model at the optimum: corrected {chk['force_rel_err'] * 100:+.2f} % "
            f"force, {chk['inductance_rel_err'] * 100:+.2f} % inductance (bound "
            f"{chk['bound_rel'] * 100:g} %: {'met' if chk['within_bound'] else 'NOT MET'}); "
            f"uncorrected {chk['uncorrected_force_rel_err'] * 100:+.1f} % / "
            f"{chk['uncorrected_inductance_rel_err'] * 100:+.1f} %")
    ver = data.get("verification")
    if ver:
        lines.append(
            f"verified global on the corrected fast model (its values, not the panel model's "
            f"optimum above): {ver['agree']} (multistart {ver['multistart']['feasible']}/"
            f"{ver['multistart']['starts']} agree={ver['multistart_agree']}, ISRES polished "
            f"{ver['isres']['polished_value_n'] * 1e3:.1f} mN agree={ver['isres_agree']}, grid "
            f"{ver['grid']['designs']} designs best "
            f"{(ver['grid']['best_n'] or 0) * 1e3:.1f} mN not better={ver['grid_not_better']}; "
            f"{ver['evaluations']} evaluations, {ver['seconds']:.1f} s)")
    fem = data.get("getdp_check")
    if fem:
        lines.append(f"GetDP check (level {fem['mesh_level']}, {fem['fem_nodes']} nodes): force "
                     f"{fem['force_fem_n'] * 1e3:.1f} mN ({fem['force_rel_err'] * 100:+.2f} %), "
                     f"inductance {fem['inductance_fem_h'] * 1e3:.3f} mH "
                     f"({fem['inductance_rel_err'] * 100:+.2f} %); within 3 %: "
                     f"{fem['within_3_percent']}")
    if "rules_violated" in data:
        lines.append("rule book (designkit check; cad builds it when no cad rule is broken): "
                     f"violates {', '.join(data['rules_violated']) or 'none'}")
    base = data.get("base_design")
    if base:
        bad = ", ".join(base["violated"]) or "none"
        lines.append(f"base design '{base['name']}': upward Fz {base['force_n'] * 1e3:.1f} mN; "
                     f"violates: {bad}")
    return "\n".join(lines)


def _run_coil(args, design, starts: int) -> int:
    problem = CoilDesignProblem.from_design(design, core_model=args.core_model)
    result = solve(problem, starts=starts, global_method=args.global_method,
                   seed=args.seed, progress=show_progress(args))
    data = {"design_name": design.name, "design_hash": design.spec_hash(),
            "problem": "coil", "core_model": args.core_model, **result.as_dict()}
    out = Path(args.out) / "optimize.json"
    write_json_atomic(out, data)
    print(summary_table(result))
    print(f"wrote {out}")
    return 0


def summary_table(result) -> str:
    b, t = result.best, result.thesis_point
    rows = [
        ("inner diameter (mm)", 2e3 * b.inner_radius_m, 2e3 * t.get("inner_radius_m", 0)),
        ("outer diameter (mm)", 2e3 * b.outer_radius_m, 2e3 * t.get("outer_radius_m", 0)),
        ("length (mm)", 1e3 * b.length_m, 1e3 * t.get("length_m", 0)),
        ("turns", b.turns, t.get("turns", 0)),
        ("resistance (ohm)", b.resistance_ohm, t.get("resistance_ohm", 0)),
        ("inductance (mH)", 1e3 * b.inductance_h, 1e3 * t.get("inductance_h", 0)),
        ("5 tau (ms)", 5e3 * b.time_constant_s, 5e3 * t.get("time_constant_s", 0)),
        (f"force at {b.current_a:g} A (mN)", 1e3 * b.force_n, 1e3 * t.get("force_n", 0)),
    ]
    lines = [f"{'':<24}{'optimum':>12}{'thesis 24/38/100':>18}"]
    for name, a, c in rows:
        fa = f"{a:.0f}" if name == "turns" else f"{a:.4g}"
        fc = f"{c:.0f}" if name == "turns" else f"{c:.4g}"
        lines.append(f"{name:<24}{fa:>12}{fc:>18}")
    active = [k for k, c in b.constraints.items() if c["active"]]
    lines.append(f"model: {b.core_model}; active constraints: {', '.join(active) or 'none'}")
    lines.append(f"{result.evaluations} evaluations ({result.model_evaluations} distinct) in "
                 f"{result.seconds:.2f} s; {result.starts_at_best}/{len(result.runs)} starts "
                 f"reach the optimum; thesis reports 780 mN")
    return "\n".join(lines)
