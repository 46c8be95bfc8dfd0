"""``designkit sensors plan``: place N Hall sensors to minimize the worst Cramer-Rao bound of the
magnet positions over the workspace, for one magnet or two, and compare with the design's own
layout.

Sites: the design's boards (``sensors.offset_m`` above the coil tops and below their bottoms)
or one board at ``--plane``, every ``--spacing``, outside every winding and core, each chip
within 80 % of its linear range with every coil at ``--max-current`` (default the design's
limit) and the worst signs. Scenarios: one magnet on a lattice of the workspace (``--lattice``,
``--heights``), or two magnets ``--separation`` apart. Bounds: 5 unknowns a magnet plus the
uniform background, TLV493D noise (``--noise-mt``) with the readout's rounding, the cores the
magnets magnetize (``--no-cores`` leaves them out). Writes into ``--out``: ``sensors.toml`` (a
``[sensors]`` table a design file can hold as is), ``design.toml`` (the design with it),
``plan.json`` (settings, both layouts' bounds by height and separation, which sensors saturate
at which currents) and ``bound_maps.png``. Deterministic for a ``--seed``; Ctrl-C leaves nothing
written. docs/sensors.md.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path


from ..design import design_to_toml, load_design
from ..design.tables import SensorSpec
from ..errors import BadInputError
from ..sensing.crb import BoundSettings
from ..sensing.design_plan import (PlanRequest, check_count, check_magnets, plan_design,
                                   prepare)
from ..sensing.figure import bound_figure
from ..sensing.maps import summary_text
from ..sensing.planner import PlanSettings
from ..sensing.region import RegionSettings
from ..support.atomic import write_json_atomic, write_text_atomic
from ..support.progress import tqdm
from .common import (add_design_argument, add_progress_argument, check_output, parse_length,
                     parse_lengths, show_progress, staged_folder)

ACTIONS = ("plan",)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    # the action first, as it is typed (argparse would list the positional after the options)
    parser.usage = "%(prog)s {" + ",".join(ACTIONS) + "} [options]"
    parser.add_argument("action", choices=ACTIONS, help="plan: place the sensors")
    add_design_argument(parser)
    parser.add_argument("--count", type=int, default=None,
                        help="sensors to place (default: as many as the design has)")
    parser.add_argument("--magnets", type=int, default=1,
                        help="magnets tracked at once: 1 (default) or 2")
    parser.add_argument("--out", type=Path, default=Path("sensor-plan"),
                        help="output folder (default: ./sensor-plan)")
    parser.add_argument("--plane", default=None, metavar="Z",
                        help="one board at this height instead of the design's two (mm, or "
                             "with a unit), above or below the coils and the workspace")
    parser.add_argument("--spacing", default="10", metavar="LENGTH",
                        help="step of the candidate sites on a board (default 10 mm)")
    parser.add_argument("--lattice", default="15", metavar="LENGTH",
                        help="step of the magnet positions judged, x-y and z (default 15 mm)")
    parser.add_argument("--heights", default=None, metavar="LO:HI",
                        help="magnet-centre heights judged (default: the workspace's)")
    parser.add_argument("--separation", default="30:60", metavar="LO:HI",
                        help="two magnets' centre distance (default 30:60 mm)")
    parser.add_argument("--max-current", type=float, default=None, metavar="A",
                        help="per-coil current every sensor must stay linear at (default: the "
                             "design's drive.max_current_a)")
    parser.add_argument("--noise-mt", type=float, default=0.1, metavar="MT",
                        help="sensor noise per axis, mT rms (default 0.1, the TLV493D's)")
    parser.add_argument("--no-cores", action="store_true",
                        help="leave out the field of the cores the magnets magnetize")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the search, an integer >= 0 (default 0)")
    add_progress_argument(parser)


def request_of(args: argparse.Namespace, design) -> PlanRequest:
    """The plan request from the options, every one checked (one line naming it)."""
    bound = BoundSettings(noise_t=_positive("--noise-mt", args.noise_mt) * 1e-3,
                          cores="none" if args.no_cores else "coupled")
    magnets = check_magnets(design, args.magnets)
    count = len(design.sensor_poses()[0]) if args.count is None else args.count
    check_count(count, magnets, bound)
    ws = design.workspace
    heights = (ws.z_min_m, ws.z_max_m) if args.heights is None else parse_lengths(
        args.heights, "--heights", 2, sep=":", valid_m=(ws.z_min_m, ws.z_max_m))
    if heights[1] < heights[0]:
        raise BadInputError("--heights", "LO:HI with LO <= HI", args.heights)
    sep = parse_lengths(args.separation, "--separation", 2, sep=":", valid_m=(1e-3, 1.0))
    if sep[1] < sep[0]:
        raise BadInputError("--separation", "LO:HI with LO <= HI", args.separation)
    lattice = parse_length(args.lattice, "--lattice", valid_m=(1e-3, 0.1))
    spacing = parse_length(args.spacing, "--spacing", valid_m=(1e-3, 0.1))
    plane = None if args.plane is None else parse_length(args.plane, "--plane", valid_m=None)
    current = None if args.max_current is None else _positive("--max-current",
                                                              args.max_current)
    if isinstance(args.seed, bool) or not 0 <= args.seed < 2 ** 63:
        raise BadInputError("--seed", "an integer in [0, 2^63)", args.seed)
    return PlanRequest(count, magnets, RegionSettings(tuple(heights), lattice, lattice,
                                                      tuple(sep)),
                       spacing, plane, current, bound, PlanSettings(count=count, seed=args.seed))


def _positive(param: str, value: float) -> float:
    if not (math.isfinite(value) and value > 0):
        raise BadInputError(param, "a finite number > 0", value)
    return float(value)


def run(args: argparse.Namespace) -> int:
    out = check_output(args.out, folder=True)
    design = load_design(args.design)
    request = request_of(args, design)
    start = time.perf_counter()
    prepared = prepare(design, request)          # every refusal before the bar starts
    total = request.count * (1 + 4 * (request.search.exchange_passes + 1))
    with tqdm(total=total, desc="designkit sensors plan", unit="step",
              disable=not show_progress(args)) as bar:
        outcome = plan_design(design, request, bar, prepared)
        bar.update(bar.total - bar.n)
    seconds = time.perf_counter() - start
    with staged_folder(out) as stage:
        spec = sensor_spec(design, outcome.layouts["planned"])
        write_text_atomic(stage / "sensors.toml", sensors_toml(spec))
        write_text_atomic(stage / "design.toml",
                          design_to_toml(design.replace(sensors=spec,
                                                        name=f"{design.name}-planned")))
        write_json_atomic(stage / "plan.json", plan_json(design, request, outcome, seconds))
        blocks = [(outcome.scenarios[k], [(outcome.layouts[n], outcome.bounds[k][n],
                                           outcome.boards_of[n]) for n in ("design", "planned")])
                  for k in outcome.scenarios]
        bound_figure(blocks, design, stage / "bound_maps.png")
    print(report_text(design, request, outcome, out, seconds))
    return 0


def sensor_spec(design, layout) -> SensorSpec:
    """The design's sensors table with the planned layout ('free')."""
    s = design.sensors
    return SensorSpec(layout="free", offset_m=s.offset_m, range_t=s.range_t, lsb_t=s.lsb_t,
                      positions_m=tuple(tuple(round(float(c), 9) for c in p)
                                        for p in layout.positions_m),
                      rotations=tuple(tuple(tuple(round(float(c), 12) for c in row)
                                            for row in r) for r in layout.frames))


def sensors_toml(spec: SensorSpec) -> str:
    """A ``[sensors]`` table (TOML) of ``spec``."""
    lines = ["# planned by designkit sensors plan: paste into a design file (replacing its "
             "[sensors] table)", "[sensors]"]
    for key in ("layout", "offset_m", "range_t", "lsb_t"):
        lines.append(f"{key} = {json.dumps(getattr(spec, key))}")
    lines.append("positions_m = [")
    lines += [f"    {json.dumps(list(p))}," for p in spec.positions_m]
    lines += ["]", "rotations = ["]
    lines += [f"    {json.dumps([list(r) for r in rot])}," for rot in spec.rotations]
    lines.append("]")
    return "\n".join(lines) + "\n"


def headroom_rows(outcome, name: str) -> list[dict]:
    """Per sensor of a layout: position, board, the currents that take it beyond the usable
    level (worst signs on every coil; one coil alone, and which)."""
    lay, room = outcome.layouts[name], outcome.headroom[name]
    return [{"sensor": k, "position_m": lay.positions_m[k].tolist(),
             "board": outcome.boards_of[name][k],
             "all_coils_a": _finite(room.worst_signs_a[k]),
             "one_coil_a": _finite(room.one_coil_a[k]), "coil": int(room.coil[k])}
            for k in range(len(lay.positions_m))]


def _finite(x: float) -> float | None:
    """A current, or None where no coil current reaches the level (JSON has no inf)."""
    return float(x) if math.isfinite(x) else None


def plan_json(design, request: PlanRequest, outcome, seconds: float) -> dict:
    """plan.json: what was asked, the sites, both layouts' bounds and headroom."""
    r = request.region
    return {
        "design_name": design.name, "design_hash": design.spec_hash(),
        "request": {"count": request.count, "magnets": request.magnets,
                    "heights_m": list(r.heights_m), "lattice_m": r.spacing_m,
                    "separation_m": list(r.separation_m), "site_spacing_m": request.spacing_m,
                    "plane_m": request.plane_m, "max_current_a": outcome.max_current_a,
                    "seed": request.search.seed},
        "bound_settings": {"noise_t": request.bound.noise_t, "lsb_t": request.bound.lsb_t,
                           "sigma_t": math.sqrt(request.bound.variance_t2),
                           "dof": request.bound.dof, "background": request.bound.background,
                           "cores": request.bound.cores,
                           "usable_level_t": request.bound.usable_fraction
                           * request.bound.range_t},
        "sites": {"count": int(len(outcome.sites.positions_m)),
                  "boards": [{"name": b.name, "height_m": b.height_m}
                             for b in outcome.sites.boards],
                  "excluded": outcome.sites.excluded},
        "search": {"history": [{"phase": p, "worst_rms_m": w} for p, w in outcome.plan.history]},
        "summaries": outcome.summaries,
        "layouts": {name: {"positions_m": lay.positions_m.tolist(),
                           "headroom": headroom_rows(outcome, name)}
                    for name, lay in outcome.layouts.items()},
        "seconds": seconds,
    }


def report_text(design, request, outcome, out: Path, seconds: float) -> str:
    """What the command prints: the sites, the bounds side by side, the headroom."""
    ex = ", ".join(f"{v} {k}" for k, v in outcome.sites.excluded.items())
    lines = [f"design '{design.name}': {request.count} sensors for {request.magnets} magnet(s) "
             f"from {len(outcome.sites.positions_m)} sites on "
             + ", ".join(f"{b.name} board z = {b.height_m * 1e3:g} mm"
                         for b in outcome.sites.boards) + f" ({ex}); {seconds:.0f} s"]
    for kind, summ in outcome.summaries.items():
        lines += ["", f"{kind}:", summary_text(summ)]
    for name in ("design", "planned"):
        rows = headroom_rows(outcome, name)
        bad = [r for r in rows if (r["all_coils_a"] or math.inf) < outcome.max_current_a]
        shown = ", ".join(f"{r['sensor']} ({r['all_coils_a']:.2f} A)" for r in bad[:9])
        lines.append(f"{name} layout at {outcome.max_current_a:g} A per coil, worst signs: "
                     + (f"{len(bad)} of {len(rows)} sensors beyond 80 % of the range: {shown}"
                        + (" ..." if len(bad) > 9 else "") if bad else
                        f"all {len(rows)} sensors within 80 % of the range"))
    lines.append(f"wrote {out / 'sensors.toml'}, design.toml, plan.json, bound_maps.png")
    return "\n".join(lines)
