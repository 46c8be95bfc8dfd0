"""``designkit sweep``: evaluate a grid of coil designs in parallel -> CSV + PNG.

``designkit sweep --param inner_radius_m=0.005:0.02:40 --param length_m=0.02:0.1:40``
evaluates every combination (other parameters from the design) on local worker processes, or
on a Dask cluster with ``--scheduler tcp://host:8786``; writes ``OUT/sweep.csv`` and
``OUT/sweep.png`` (feasible region and the best feasible design).

``designkit sweep --array --param pitch_m=0.05:0.06:3 --param core_length_m=...`` sweeps whole
arrays (pitch x core length x coil size x wire) with the rendering objective: the smallest
upward force the array renders over the workspace region (LP per point), the 1010-steel core
by the fast slice model, every device constraint (designkit.optimize.sweep.evaluate_array_chunk).
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from ..design import load_design
from ..errors import BadInputError
from ..optimize import CORE_MODEL_NAMES
from ..optimize.sweep import (ARRAY_COLUMNS, ARRAY_CORE_MODEL, ARRAY_PARAMETERS, PARAMETERS,
                              Grid, design_core_model, parse_param, plot, reason_summary,
                              run_array_sweep, run_sweep, write_csv)
from .common import (add_design_argument, add_progress_argument, check_output, parse_length,
                     say_unfixable, show_progress, staged_folder)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--param", action="append", default=[], metavar="NAME=START:STOP:N",
                        help=f"swept parameter (repeat); NAME one of {sorted(PARAMETERS)}; "
                             "a length in m as its name says, or with its unit (20mm:100mm)")
    add_design_argument(parser)
    parser.add_argument("--out", type=Path, default=Path("designkit-sweep"),
                        help="output folder (default: ./designkit-sweep)")
    parser.add_argument("--workers", type=int, default=None,
                        help="local worker processes (default: CPU count)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="dask.distributed scheduler address: run the sweep there")
    parser.add_argument("--core-model", choices=CORE_MODEL_NAMES, default=None,
                        help="force model of a coil sweep (default: the design's own: "
                             "surface-current with a core, air without); a cheaper model is "
                             "named in stdout, the CSV column core_model and the figure")
    parser.add_argument("--array", action="store_true",
                        help="sweep whole arrays with the rendering objective; NAME one of "
                             f"{sorted(ARRAY_PARAMETERS)}")
    add_progress_argument(parser)


def run(args: argparse.Namespace) -> int:
    check_output(args.out, folder=True)
    if not args.param:
        raise BadInputError("--param", "at least one NAME=START:STOP:N", "nothing")
    array = getattr(args, "array", False)
    ranges = [parse_param(si_param(p), ARRAY_PARAMETERS if array else None) for p in args.param]
    g = Grid.of(ranges)  # checks duplicates and size before any work
    if args.workers is not None and args.workers < 1:
        raise BadInputError("--workers", "a whole number >= 1", args.workers)
    design = load_design(args.design)
    where = (f"the dask scheduler {args.scheduler}" if args.scheduler else
             f"{args.workers or os.cpu_count() or 1} local worker process(es)")
    print(f"planned: {g.describe()} on {where}", flush=True)
    say_unfixable("sweep", design, g.varied_keys())
    if array:
        result = run_array_sweep(design, ranges, workers=args.workers, scheduler=args.scheduler,
                                 progress=show_progress(args))
    else:
        result = run_sweep(design, ranges, workers=args.workers, scheduler=args.scheduler,
                           core_model=args.core_model, progress=show_progress(args))
    out = Path(args.out)
    # the CSV and the PNG are written only after every design is evaluated, staged together
    # (a failure or Ctrl-C while drawing leaves neither)
    with staged_folder(out) as stage:
        if array:
            write_csv(result, stage / "sweep.csv", ARRAY_COLUMNS)
            plot(result, stage / "sweep.png",
                 objective="smallest upward force over the workspace",
                 limits="device constraints")
        else:
            write_csv(result, stage / "sweep.csv")
            plot(result, stage / "sweep.png", limits="R, 5 L/R and the rule table")
    csv_path, png_path = out / "sweep.csv", out / "sweep.png"
    n = len(result.rows)
    feas = sum(1 for r in result.rows if r["feasible"])
    model = ARRAY_CORE_MODEL if array else (args.core_model or design_core_model(design))
    own = "" if array or args.core_model is None else (
        " (the design's own)" if args.core_model == design_core_model(design) else
        f" (not the design's own {design_core_model(design)}: --core-model)")
    print(f"core model: {model}{own}")
    print(f"{n} {'arrays' if array else 'designs'} ({feas} feasible) in {result.seconds:.2f} s "
          f"on {result.workers} worker(s) [{result.backend}]: "
          f"{n / max(result.seconds, 1e-9):.2f} designs/s")
    if result.best_index is not None:
        describe = _best_array if array else _best_coil
        print("best feasible: " + describe(result.rows[result.best_index]))
    if feas == 0:
        print(f"no feasible design; why (column 'reason' of {csv_path.name}):\n"
              + reason_summary(result))
    print(f"wrote {csv_path} and {png_path}")
    return 0


def si_param(text: str) -> str:
    """``NAME=START:STOP:N`` with START and STOP of a length given with a unit
    (:func:`~designkit.commands.common.parse_length`: ``20mm``, ``2cm``) written in metres; a
    bare number stays as given (metres, as the ``_m`` name says: the library checks its
    range and says when it reads as millimetres)."""
    name, eq, rng = text.partition("=")
    parts = rng.split(":")
    if not eq or len(parts) != 3 or not name.strip().endswith("_m"):
        return text
    for k, which in ((0, "START"), (1, "STOP")):
        if parts[k].strip() and parts[k].strip()[-1].isalpha():
            parts[k] = repr(parse_length(parts[k], f"--param {name.strip()} {which}",
                                         valid_m=None, bare="m"))
    return f"{name}={':'.join(parts)}"


def _best_coil(b: dict) -> str:
    return (f"Ri {b['inner_radius_m'] * 1e3:.2f} mm, Ro {b['outer_radius_m'] * 1e3:.2f} mm, "
            f"L {b['length_m'] * 1e3:.2f} mm, {b['turns']} turns, "
            f"R({b['resistance_temperature_c']:g} C) {b['resistance_ohm']:.3f} ohm, "
            f"5 tau {5e3 * b['time_constant_s']:.2f} ms, force {b['force_n'] * 1e3:.1f} mN")


def _best_array(b: dict) -> str:
    return (f"pitch {b['pitch_m'] * 1e3:.1f} mm, Ri/Ro/L {b['inner_radius_m'] * 1e3:.2f}/"
            f"{b['outer_radius_m'] * 1e3:.2f}/{b['length_m'] * 1e3:.2f} mm, wire "
            f"{b['wire_diameter_m'] * 1e3:.3f} mm, core {b['core_length_m'] * 1e3:.1f} mm, "
            f"{b['turns']} turns: smallest upward Fz over the workspace "
            f"{b['force_n'] * 1e3:.1f} mN")
