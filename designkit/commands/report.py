"""``designkit report``: the main job on a design (default: the embedded thesis device).

Writes a report folder ``OUT`` (default ``./designkit-report``): ``report.json`` (version, the
design and its hash, the single coil's field, gradient, force and torque at the design point,
the whole array's force there, the design next to the shipped optimized device -- only for a
device of its layout kind and coil count, else the entry says why --, the files written, the
steps ``skipped`` and the parts ``failed`` with the reason, ``quick``); ``report.md`` (the same
for people); ``design.json`` / ``design.md`` / ``design.toml`` (every field, SI, derived coil
quantities, the TOML that reproduces it); ``designs.json`` (the comparison in full);
``figures/*.png`` and ``vtk/*`` (:func:`designkit.viz.write_figures`,
:func:`designkit.viz.export_vtk`); ``map/forcemap.npz`` (a coarse map, :data:`MAP_SPACING_M`;
the controller's comes from ``designkit map``).

Files are written atomically, without time stamps: re-running is idempotent. ``--quick``: coarse
grids, small images, fewer optimizer starts. ``--no-figures``: no figures, no VTK files. A
figure that fails is named with its error and the rest is written.

The design point is the magnet's centre at the design height above the coil nearest the
layout's centre, on its axis (:func:`designkit.viz.design_point_m`); the single-coil rows are
that coil alone, upright at the origin (the problem of thesis eq. 2.14).
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np

from .. import __version__, fieldmap, viz
from ..design import (Design, GridLayout, default_design, design_to_toml, load_design,
                      named_design)
from ..model.array import array_for_design, force_matrix, g5_from_gradient
from ..geometry.pose import Pose
from ..model.coil import Coil
from ..model.sensor_headroom import sensor_headroom
from ..sensing.layout_report import layout_report, layout_report_markdown, planned_layout
from ..optimize import device_problem_for, evaluate_device, rendering_force
from ..support.atomic import write_json_atomic, write_text_atomic
from ..support.progress import tqdm
from .common import (add_currents_arguments, add_design_argument, add_progress_argument,
                     check_current_limit, check_output, parse_currents, show_progress,
                     shown_margin, staged_folder)

MAP_SPACING_M = {"quick": 0.025, "full": 0.01}
"""Step of the report map's grid of magnet positions (bias force), m: coarse, quick."""

FIGURES = viz.KINDS
"""The figures of the report, in its order: every kind ``designkit viz`` draws."""
FIGURE_TITLES = {
    "scene": "Coil array, magnet at the design point, workspace",
    "fieldlines": "Field lines of B",
    "slice-B": "Magnitude of B on a vertical and a horizontal slice",
    "slice-F": "Force on the magnet on a vertical and a horizontal slice",
    "forcemap": "Force vectors on the magnet at the design height",
    "isosurface": "Where the vertical force reaches the human threshold (0.8 mN)",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_design_argument(parser)
    parser.add_argument("--out", type=Path, default=Path("designkit-report"),
                        help="output folder (default: ./designkit-report)")
    parser.add_argument("--current", type=float, default=None,
                        help="coil current in A for the design point (default: the design's "
                             "per-coil limit)")
    add_currents_arguments(parser, "per-coil currents in A for the figures, comma-separated, "
                                   "in the layout's coil order (default: the coil nearest the "
                                   "design point at the per-coil limit)")
    parser.add_argument("--quick", action="store_const", const="quick", dest="quality",
                        default="full",
                        help="coarse grids, small images, fewer optimizer starts (seconds)")
    parser.add_argument("--no-figures", action="store_false", dest="figures",
                        help="leave out the figures and their VTK files")
    parser.add_argument("--sensors", type=Path, default=None, metavar="FILE.toml",
                        help="a planned [sensors] table (designkit sensors plan's sensors.toml) "
                             "whose bound maps the report shows beside the design's")
    add_progress_argument(parser)


# ----------------------------------------------------------------------------- pieces
def single_coil(design: Design) -> Coil:
    """The coil under the design point (:func:`designkit.viz.design_coil`), alone, upright, its
    top face at z = 0 about the origin: the single-coil problem of thesis eq. 2.14."""
    k = design.design_coil
    c = design.coil_spec(k)
    return Coil.from_specs(c, design.core_spec(k), Pose((0.0, 0.0, -c.length_m / 2)))


def design_point_summary(design: Design, current_a: float) -> dict:
    """Field, gradient, force and torque of the design's coil at its design point (SI): the
    coil under the design point alone (:func:`single_coil`), the magnet on its axis at the
    design height."""
    coil = single_coil(design)
    p = np.array([0.0, 0.0, design.optimize.height_m])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        b, g = coil.field(p, current_a, gradient=True)
    m = np.array(design.magnet.moment_vector_a_m2)
    force = force_matrix(m) @ g5_from_gradient(g)  # thesis eq. 2.5, F = G^T m in air
    torque = np.cross(m, b)
    return {
        "current_a": current_a,
        "point_m": p.tolist(),
        "magnet_moment_a_m2": m.tolist(),
        "flux_density_t": b.tolist(),
        "gradient_t_per_m": g.tolist(),
        "force_n": force.tolist(),
        "torque_n_m": torque.tolist(),
        "core_model": None if coil.core is None else coil.core.model,
        "warnings": sorted({str(w.message) for w in caught}),
    }


def coil_properties(design: Design) -> dict:
    """Electrical quantities of the coil under the design point (SI): R, current at the supply,
    L (with the core, small-signal) and L/R."""
    coil = single_coil(design)
    r = coil.resistance(design.wire)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the saturation warning is reported once, elsewhere
        ind = coil.inductance(design.wire)
    return {
        "dipole_moment_per_amp_a_m2": coil.dipole_moment_per_amp,
        "resistance_ohm": r,
        "current_at_supply_a": design.drive.supply_voltage_v / r,
        "inductance_h": ind,
        "time_constant_s": ind / r,
    }


_UNITS = [("_a_per_m", "A/m"), ("_a_m2", "A m^2"), ("_ohm_m", "ohm m"), ("_per_k", "1/K"),
          ("_n_per_m", "N/m"), ("_ohm", "ohm"), ("_m3", "m^3"), ("_hz", "Hz"), ("_c", "degC"),
          ("_h", "H"), ("_w", "W"), ("_kg", "kg"),
          ("_v", "V"), ("_a", "A"), ("_t", "T"), ("_s", "s"), ("_n", "N"), ("_m", "m")]


def _unit(name: str) -> str:
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return unit
    return ""


def _human(value, unit: str) -> str:
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return str(value)
    if isinstance(value, (tuple, list)):
        if unit == "m":
            return f"{np.round(np.asarray(value, dtype=float) * 1e3, 6).tolist()} mm"
        return str(list(value))
    if unit == "m":
        return f"{value * 1e3:.6g} mm"
    if unit == "N":
        return f"{value * 1e3:.6g} mN"
    if isinstance(value, float):
        return f"{value:.6g} {unit}".strip()
    return f"{value} {unit}".strip()


def _flat(prefix: str, values):
    """(dotted key, value) pairs of a design table, of its groups' tables too."""
    if isinstance(values, dict):
        for key, value in values.items():
            yield from _flat(f"{prefix}.{key}", value)
    elif isinstance(values, (list, tuple)) and values and isinstance(values[0], dict):
        for k, value in enumerate(values):
            yield from _flat(f"{prefix}[{k}]", value)
    else:
        yield prefix, values


def design_markdown(design: Design, derived: dict) -> str:
    """The design as a Markdown table (SI in the JSON; mm and mN here, for people)."""
    lines = [f"# Design `{design.name}`", "", f"spec hash `{design.spec_hash()}`", "",
             "| parameter | value | SI value |", "| --- | --- | --- |"]
    for section, values in design.to_dict().items():
        if section == "name":
            continue
        if values is None:
            lines.append(f"| {section} | none | |")
            continue
        for key, value in _flat(section, values):
            unit = _unit(key)
            si = f"{value} {unit}".strip()
            lines.append(f"| {key} | {_human(value, unit)} | {si} |")
    lines += ["", "## Derived coil quantities", "", "| quantity | value |", "| --- | --- |"]
    for key, value in derived.items():
        lines.append(f"| {key} | {_human(value, _unit(key))} |")
    return "\n".join(lines) + "\n"


ROUND_OFF = 1e-9
"""Components below this fraction of a vector's largest are round-off, printed as 0."""


def _vec(v, scale: float, unit: str) -> str:
    """A 3-vector in ``unit`` (SI x ``scale``), round-off printed as 0."""
    big = max(abs(float(x)) for x in v)
    shown = [0.0 if abs(float(x)) <= ROUND_OFF * big else float(x) * scale for x in v]
    return "(" + ", ".join(f"{x:+.4g}" if x else "0" for x in shown) + f") {unit}"


def _vec_mn(f) -> str:
    return _vec(f, 1e3, "mN")


def _vec_mt(b) -> str:
    return _vec(b, 1e3, "mT")


def _core_text(design: dict) -> str:
    """'linear core (mu_r 1000)', 'saturating core (steel1010 B-H)' or 'no core'."""
    core = design.get("core")
    if not core:
        return "no core"
    if core["bh"] == "linear":
        return f"linear core (mu_r {core['relative_permeability']:g})"
    return f"saturating core ({core['bh']} B-H)"


def _mn1(force_n: float, sign: str = "") -> str:
    """A force in mN to 0.1 mN, never '-0.0'."""
    return f"{round(force_n * 1e3, 1) + 0.0:{sign}.1f}"


def _at_least(force_n: float) -> str:
    """'Fz >= 12.3 mN', or what a smallest upward force of zero (or below) means."""
    if round(force_n * 1e3, 1) <= 0.0:
        return "Fz = 0 mN: somewhere in the region the array cannot push the magnet up"
    return f"Fz >= {_mn1(force_n)} mN"


def forces_markdown(report: dict) -> list[str]:
    """One table: every design-point force of the report with what it assumes."""
    dp, d = report["design_point"], report["design"]
    h = dp["point_m"][2] * 1e3
    n, k = report["n_coils"], report["design_point_coil"]
    where = ", ".join(f"{x * 1e3:.4g}" for x in report["design_point_m"])
    lines = ["## Forces at the design point, side by side", "",
             f"Magnet centre {h:g} mm above the top face of coil {k} (the coil nearest the "
             f"layout's centre), on its axis: the design point, ({where}) mm in the array frame; "
             f"moment {_vec(dp['magnet_moment_a_m2'], 1.0, 'A m^2')}. Each row is a different "
             "question; the columns say what each assumes.", "",
             "| case | coils | core, model | currents | B | dBz/dz | F |",
             "| --- | --- | --- | --- | --- | --- | --- |",
             f"| single coil | 1 (the others absent) | {_core_text(d)}, `{dp['core_model']}` | "
             f"{dp['current_a']:g} A | {_vec_mt(dp['flux_density_t'])} | "
             f"{dp['gradient_t_per_m'][2][2]:+.5g} T/m | {_vec_mn(dp['force_n'])} |"]
    arr = report.get("array")
    if arr:
        lines.append(f"| array, figure currents | {n} "
                     f"(coupled: every core magnetised) | {_core_text(d)}, `{dp['core_model']}` | "
                     f"{arr['currents_text']} | {_vec_mt(arr['flux_density_t'])} | "
                     f"{arr['dbz_dz_t_per_m']:+.5g} T/m | {_vec_mn(arr['force_n'])} |")
    ev = next((e for e in report.get("designs", {}).values()
               if e.get("name") == report["design_name"] and "skipped" not in e), None)
    if ev:
        lines.append(f"| single coil, device problem | 1 | saturating core (steel1010 B-H), "
                     f"`{ev['core_model']}` | {ev['current_a']:g} A | - | - | "
                     f"Fz = {_mn1(ev['upward_force_design_point_n'], '+')} mN |")
        dr = d["drive"]
        lines.append(f"| smallest upward Fz over the workspace region | "
                     f"{n} | saturating core, fast "
                     f"slice model scaled to the panel model | LP allocation, bipolar, <= "
                     f"{dr['max_current_a']:g} A per coil, sum <= {dr['total_current_a']:g} A | "
                     f"- | - | {_at_least(ev['min_upward_force_workspace_n'])} |")
        lines += ["", "Why they differ: a linear core does not saturate, so it overstates the "
                  "force of the saturating 1010-steel core; the array rows drive several coils "
                  "(and magnetise every core), so the smallest force the array can render over "
                  "the workspace region may exceed the single coil's force at the design point "
                  "even though that point is inside the region."]
    lines += ["", "F = (grad B)^T m. Sign convention everywhere: z up (away from the coil "
                  "tops); Fz > 0 pushes the magnet away from the coils."]
    return lines


_ROWS = [
    ("winding inner / outer radius", lambda e: f"{e['inner_radius_m'] * 1e3:.2f} / "
                                               f"{e['outer_radius_m'] * 1e3:.2f} mm"),
    ("winding length", lambda e: f"{e['length_m'] * 1e3:.2f} mm"),
    ("turns (fit the window)", lambda e: f"{e['turns']} ({e['turns_that_fit']})"),
    ("wire (bare)", lambda e: f"{e['wire_diameter_m'] * 1e3:.3f} mm"),
    ("core radius / length / protrusion", lambda e: f"{e['core_radius_m'] * 1e3:.2f} / "
                                                    f"{e['core_length_m'] * 1e3:.2f} / "
                                                    f"{e['core_protrusion_m'] * 1e3:.2f} mm"),
    ("R (hot)", lambda e: f"{e['resistance_ohm']:.4g} ohm at {e['temperature_c']:g} C"),
    ("L secant at the current", lambda e: f"{e['inductance_h'] * 1e3:.4g} mH at "
                                          f"{e['current_a']:g} A"),
    ("5 L/R (cold)", lambda e: f"{e['settling_time_s'] * 1e3:.4g} ms"),
    ("peak core B", lambda e: f"{e['peak_core_flux_density_t']:.3g} T"),
    ("upward Fz at the design point", lambda e: f"{_mn1(e['upward_force_design_point_n'])} "
                                                f"mN at {e['design_height_m'] * 1e3:g} mm"),
    ("smallest upward Fz over the workspace region",
     lambda e: f"{_mn1(e['min_upward_force_workspace_n'])} mN"),
]


def designs_markdown(designs: dict) -> list[str]:
    """Side-by-side tables: quantities, then every constraint with its margin (flagged)."""
    ents = [designs[k] for k in ("design", "optimized") if "skipped" not in designs.get(k, {})]
    omitted = [f"`{e['name']}` omitted: {e['skipped']}." for e in designs.values()
               if "skipped" in e]
    if not ents:
        return ["", "## Design vs the optimized device", ""] + omitted
    head = " | ".join(f"`{e['name']}`" for e in ents)
    lines = ["", "## Design vs the optimized device", "",
             "Saturating 1010-steel core (surface-current panel model, checked against GetDP); "
             "R at the hot limit, 5 L/R with cold copper, I R against the design's supply (at "
             "most its driver's rating). "
             "Workspace region: the inner array footprint at the lowest reachable height and "
             "the design height; allocation |I| <= per-coil limit, sum |I| <= budget, "
             "Fx = Fy = 0 (LP per point).", "",
             f"| quantity | {head} |", "| --- |" + " --- |" * len(ents)]
    for label, fmt in _ROWS:
        lines.append(f"| {label} | " + " | ".join(fmt(e) for e in ents) + " |")
    lines += ["", "### Constraints (margin >= 0 is met)", "",
              f"| constraint | {head} |", "| --- |" + " --- |" * len(ents)]
    names = list(dict.fromkeys(n for e in ents for n in e["constraints"]))
    for n in names:
        cells = []
        for e in ents:
            c = e["constraints"].get(n)
            if c is None:
                cells.append("")
                continue
            flag = "ok" if c["met"] else "**VIOLATED**"
            cells.append(f"{c['value']:.4g} vs {c['kind']} limit {c['limit']:.4g} {c['unit']}"
                         f", margin {shown_margin(c):+.3g}: {flag}")
        note = ents[-1]["constraints"].get(n, ents[0]["constraints"].get(n, {})).get("note", "")
        lines.append(f"| {n} ({note}) | " + " | ".join(cells) + " |")
    for e in ents:
        bad = ", ".join(e["violated"]) or "none"
        lines.append(f"\n`{e['name']}` violates: {bad}.")
    lines += [""] + omitted if omitted else []
    lines += ["", "Full numbers: [designs.json](designs.json)."]
    return lines


def report_markdown(report: dict) -> str:
    dp = report["design_point"]
    lines = [f"# designkit report: design `{report['design_name']}`", ""]
    if report.get("quick"):
        lines += ["> QUICK RUN (--quick): coarse grids and small images; numbers of the design "
                  "comparison are not affected.", ""]
    lines += [
             f"designkit {report['designkit_version']}, spec hash `{report['design_hash']}`; "
             f"the design is in [design.md](design.md) / [design.toml](design.toml).", ""]
    lines += forces_markdown(report)
    for w in dp.get("warnings", []):
        lines.append(f"\n> warning: {w}")
    sen = report.get("sensors")
    if sen:
        lines += ["", f"Upper sensor {sen['sensor_point_m'][2] * 1e3:.0f} mm above its coil: the "
                      f"coil at {sen['coil_current_a']:g} A gives "
                      f"{sen['coil_field_fraction_of_range'] * 100:.0f} % of the "
                      f"{sen['range_t'] * 1e3:g} mT range"
                      + (" (the reading clips)" if sen["clips"] else "")
                      + f"; the magnet at the design point gives "
                      f"{sen['magnet_field_counts']:.0f} counts of {sen['lsb_t'] * 1e3:g} mT."]
    designs = report.get("designs")
    if designs:
        lines += designs_markdown(designs)
    if report.get("sensor_bounds"):
        lines += [""] + layout_report_markdown(report["sensor_bounds"],
                                               f"figures/{report['sensor_bounds']['figure']}")
    figs = report.get("figures", {})
    if figs:
        lines += ["", "## Figures", ""]
        for kind, path in figs.items():
            lines += [f"### {FIGURE_TITLES.get(kind, kind)}", "", f"![{kind}]({path})", ""]
    vtk = report.get("vtk", {})
    if vtk:
        lines += ["## ParaView files", "", ", ".join(f"[{n}]({p})" for n, p in vtk.items()), ""]
    if report.get("map"):
        lines += ["## Force-current map", "", f"[{report['map']}]({report['map']})", ""]
    failed = report.get("failed", {})
    if failed:
        lines += ["## Failed (the rest of the report is complete)", ""] + \
            [f"- {k}: {why}" for k, why in failed.items()] + [""]
    skipped = report.get("skipped", {})
    if skipped:
        lines += ["## Skipped", ""] + [f"- {k}: {why}" for k, why in skipped.items()] + [""]
    return "\n".join(lines) + "\n"


def designs_side_by_side(design: Design) -> dict:
    """The report's design next to the shipped optimized device (or the thesis device next to
    it when the report is of the optimized one), under the device problem's constraints.

    Each entry: the saturating panel model's numbers and constraint table
    (:func:`designkit.optimize.evaluate_device`), ``violated`` (names), the upward force at the
    design point and ``min_upward_force_workspace_n`` (:func:`designkit.optimize.rendering_force`,
    the fast core model scaled by the panel/fast core-force ratio at the design point).
    Fz sign convention: z up (away from the coils); ``*_upward_*`` forces are Fz >= 0 rendered
    with the current's sign chosen (bipolar drive). The optimum only where the comparison means
    something (:func:`not_comparable`); else its entry is ``skipped`` with the reason. A device
    the device problem cannot evaluate is ``skipped`` with the error.
    """
    optimized = named_design("optimized")
    left = default_design() if design.name == optimized.name else design
    out = {}
    why_not = not_comparable(left, optimized)
    for role, d in (("design", left), ("optimized", optimized)):
        if role == "optimized" and why_not:
            out[role] = {"name": d.name, "skipped": why_not}
            continue
        if d.core is None:
            out[role] = {"name": d.name, "skipped": "no core: the device problem has one"}
            continue
        try:
            out[role] = _device_entry(d)
        except (AttributeError, ValueError, TypeError, IndexError, KeyError) as exc:
            out[role] = {"name": d.name, "skipped": "the device problem cannot evaluate this "
                                                    f"layout ({type(exc).__name__}: {exc})"}
    return out


def not_comparable(design: Design, optimum: Design) -> str:
    """Why the design is not put next to the shipped optimum ('' when it is): forces over a
    workspace compare only between devices of one layout kind and coil count (and, for grids,
    the same rows x columns: a 1 x 9 line is not a 3 x 3 square)."""
    a, b = design.array, optimum.array
    same = a.kind == b.kind and design.n_coils == optimum.n_coils
    if same and isinstance(a, GridLayout) and isinstance(b, GridLayout):
        same = sorted((a.rows, a.columns)) == sorted((b.rows, b.columns))
    if same:
        return ""
    return (f"the shipped optimum `{optimum.name}` is a {optimum.array.describe()} "
            f"({optimum.n_coils} coils) and this design a {design.array.describe()} "
            f"({design.n_coils} coils): their forces over their workspaces do not compare")


def _device_entry(d: Design) -> dict:
    """One column of :func:`designs_side_by_side`."""
    problem = device_problem_for(d)
    ev = evaluate_device(d, problem)
    fast = problem.evaluate([ev["inner_radius_m"], ev["outer_radius_m"], ev["length_m"],
                             ev["core_radius_m"], ev["core_length_m"],
                             max(ev["core_protrusion_m"], 0.0), ev["wire_diameter_m"]],
                            turns=ev["turns"])
    ratio = ev["dbz_dz_core_t_per_m"] / fast["dbz_dz_core_t_per_m"]
    rend = rendering_force(d, core_force_ratio=ratio)
    ev["upward_force_design_point_n"] = ev.pop("force_n")
    ev["design_height_m"] = d.optimize.height_m
    ev["min_upward_force_workspace_n"] = rend["min_upward_force_n"]
    ev["rendering"] = rend
    return ev


def _field_map(design: Design, out: Path, quality: str) -> Path:
    """A coarse force-current map (the controller's map: ``designkit map``, 2 mm grid), from
    the array the figures used (:func:`designkit.model.array.array_for_design`: its coupled solve
    is made once)."""
    spacing = MAP_SPACING_M[quality]
    data = fieldmap.build(design, spacing=spacing, progress=False,
                          array=array_for_design(design))
    return fieldmap.write(out / "map" / "forcemap.npz", data)


# ----------------------------------------------------------------------------- main job
def run(args: argparse.Namespace) -> int:
    # every input is checked before the first file is written, and the files are written into
    # a staging folder moved into place at the end: a failing run leaves nothing behind
    out = check_output(args.out, folder=True)
    design = load_design(args.design)
    current = design.drive.max_current_a if args.current is None else float(args.current)
    allow = getattr(args, "allow_over_limit", False)
    check_current_limit(design, [current], allow=allow, param="--current")
    currents_arg = parse_currents(getattr(args, "currents", None))
    if currents_arg is not None:
        check_current_limit(design, viz.resolve_currents(design, currents_arg), allow=allow)
    if getattr(args, "sensors", None) is not None:
        args.planned_sensors = planned_layout(design, args.sensors)
    with staged_folder(out) as stage:
        summary, report = _run(args, design, current, currents_arg, stage)
    _print_summary(design, summary, current, report, out)
    return 0


def _run(args, design, current, currents_arg, out):
    quality = getattr(args, "quality", "full")
    show = show_progress(args)
    steps = ["design summary", "design point", "design vs optimized", "figures", "VTK files",
             "map file", "sensor bounds", "report"]
    bar = tqdm(total=len(steps), desc="designkit report", unit="step", disable=not show)

    def step(name: str):
        bar.set_postfix_str(name)

    def done():
        bar.update(1)

    skipped: dict[str, str] = {}

    # 1. design summary
    step(steps[0])
    derived = coil_properties(design)
    write_json_atomic(out / "design.json", {"design_name": design.name,
                                            "design_hash": design.spec_hash(),
                                            "design": design.to_dict(), "coil": derived})
    write_text_atomic(out / "design.md", design_markdown(design, derived))
    write_text_atomic(out / "design.toml", design_to_toml(design))
    done()

    # 2. force at the design point (single coil, then the array at the figure currents)
    step(steps[1])
    summary = design_point_summary(design, current)
    report: dict = {
        "quick": quality == "quick",
        "designkit_version": __version__,
        "design_name": design.name,
        "design_hash": design.spec_hash(),
        "design": design.to_dict(),
        "design_point": summary,
        "design_point_m": np.asarray(design.design_point_m).tolist(),
        "design_point_coil": design.design_coil + 1,
        "n_coils": design.n_coils,
        "coil": derived,
    }
    currents = viz.resolve_currents(design, currents_arg)
    try:
        point = np.asarray(design.design_point_m)
        b, g = viz.array_field(design, point[None, :], currents)
        f = viz.force_from_gradient(g, viz.magnet_moment(design))[0]
        report["array"] = {"currents_a": currents.tolist(),
                           "currents_text": viz.currents_text(currents),
                           "point_m": point.tolist(),
                           "flux_density_t": b[0].tolist(), "gradient_t_per_m": g[0].tolist(),
                           "dbz_dz_t_per_m": float(g[0, 2, 2]), "force_n": f.tolist()}
    except ImportError as exc:
        skipped["array"] = f"designkit.viz unavailable ({exc})"
    done()

    # 3. the design next to the shipped optimized device
    step(steps[2])
    try:
        designs = designs_side_by_side(design)
        write_json_atomic(out / "designs.json", designs)
        report["designs"] = {k: {q: val for q, val in e.items() if q != "rendering"}
                             for k, e in designs.items()}
    except ImportError as exc:
        skipped["design vs optimized"] = f"designkit.optimize is not available ({exc})"
    done()

    # 4-5. figures and VTK files from the same datasets
    step(steps[3])
    if getattr(args, "figures", True):
        try:
            _figures_and_vtk(design, currents, quality, out, report)
        except ImportError as exc:  # pyvista missing: MissingDependencyError
            skipped["figures"] = skipped["VTK files"] = str(exc)
    else:
        skipped["figures"] = skipped["VTK files"] = "--no-figures"
    done()
    done()

    # 6. map file
    step(steps[5])
    try:
        report["map"] = str(_field_map(design, out, quality).relative_to(out))
    except ImportError as exc:
        skipped["map file"] = f"designkit.fieldmap is not available ({exc})"
    done()

    # 7. the sensor layout's Cramer-Rao bound maps (and a planned layout's)
    step(steps[6])
    _sensor_bounds(args, design, quality, out, report, skipped)
    done()

    # 8. report
    step(steps[7])
    report["skipped"] = skipped
    report["sensors"] = sensor_headroom(design)
    write_json_atomic(out / "report.json", report)
    write_text_atomic(out / "report.md", report_markdown(report))
    done()
    bar.close()
    return summary, report


def _sensor_bounds(args, design, quality, out, report, skipped) -> None:
    """figures/sensor_bounds.png and report["sensor_bounds"]: the design's sensor layout's
    Cramer-Rao bound maps (and a planned layout's, ``--sensors``)."""
    if not getattr(args, "figures", True):
        skipped["sensor bounds"] = "--no-figures"
        return
    (out / "figures").mkdir(exist_ok=True)
    report["sensor_bounds"] = layout_report(design, out / "figures" / "sensor_bounds.png",
                                            quality, getattr(args, "planned_sensors", None))


def _figures_and_vtk(design, currents, quality, out, report) -> None:
    """figures/*.png and vtk/* (the figures' datasets); a figure that fails is named in
    ``report["failed"]`` with its error, the others are written."""
    sizes = ((640, 480), (960, 420)) if quality == "quick" else ((1024, 768), (1500, 640))
    made = viz.write_figures(design, out / "figures", currents, quality=quality, sizes=sizes)
    report["figures"] = {kind: f"figures/{kind}.png" for kind in made.figures}
    report["failed"] = {f"figure {kind}": why for kind, why in made.failed.items()}
    files = viz.export_vtk(design, out / "vtk", currents, quality=quality, data=made.data,
                           compute_missing=False)
    report["vtk"] = {name: f"vtk/{name}" for name in sorted(files)}


def _print_summary(design, summary, current, report, out) -> None:
    b = summary["flux_density_t"]
    f = summary["force_n"]
    print(f"designkit {__version__} - design '{design.name}' ({design.spec_hash()[:12]})")
    print(f"coil: Ri/Ro/L = {design.coil.inner_radius_m * 1e3:.1f}/"
          f"{design.coil.outer_radius_m * 1e3:.1f}/{design.coil.length_m * 1e3:.1f} mm, "
          f"{design.coil.turns} turns, core: {summary['core_model'] or 'none'}")
    where = ", ".join(f"{x * 1e3:.4g}" for x in np.asarray(design.design_point_m))
    print(f"design point: {design.optimize.height_m * 1e3:.1f} mm above the top of coil "
          f"{design.design_coil + 1}, on its axis ({where}) mm; I = {current:g} A (the "
          "single-coil rows: that coil alone)")
    print(f"  B      = ({b[0] * 1e3:+.4f}, {b[1] * 1e3:+.4f}, {b[2] * 1e3:+.4f}) mT")
    print(f"  dBz/dz = {summary['gradient_t_per_m'][2][2]:+.5f} T/m")
    print(f"  F      = ({f[0] * 1e3:+.3f}, {f[1] * 1e3:+.3f}, {f[2] * 1e3:+.3f}) mN on m = "
          f"{design.magnet.moment_a_m2:.4f} A m^2")
    for w in summary.get("warnings", []):
        print(f"  warning: {w}")
    for role, e in report.get("designs", {}).items():
        if "skipped" in e:
            print(f"{role} '{e['name']}' omitted: {e['skipped']}")
            continue
        bad = ", ".join(e["violated"]) or "none"
        print(f"{role} '{e['name']}': upward Fz {_mn1(e['upward_force_design_point_n'])} mN "
              f"at the design point from its coil alone at {e['current_a']:g} A; with every "
              f"coil (bounded allocation) over the workspace region "
              f"{_at_least(e['min_upward_force_workspace_n'])}; violates: {bad}")
    if report.get("quick"):
        print("QUICK RUN (--quick): coarse grids and small images")
    for what, why in report.get("skipped", {}).items():
        print(f"skipped {what}: {why}")
    for what, why in report.get("failed", {}).items():
        print(f"FAILED {what}: {why}")
    print(f"wrote {out / 'report.json'}, {out / 'report.md'}, "
          f"{len(report.get('figures', {}))} figures, {len(report.get('vtk', {}))} VTK files")
