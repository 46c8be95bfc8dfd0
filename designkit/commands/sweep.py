"""``designkit sweep``: evaluate a grid of coil designs in parallel -> CSV + PNG.

``designkit sweep --param inner_radius_m=0.005:0.02:40 --param length_m=0.02:0.1:40``
evaluates every combination (other parameters from the design) on local worker processes, or
on a Dask cluster with ``--scheduler tcp://host:8786``; writes ``OUT/sweep.csv`` and
``OUT/sweep.png`` (feasible region and the best feasible design).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..design import load_design
from ..errors import BadInputError
from ..optimize import CORE_MODEL_NAMES
from ..sweep import PARAMETERS, grid, parse_param, plot, reason_summary, run_sweep, write_csv
from ._common import add_progress_argument, check_output, show_progress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--param", action="append", default=[], metavar="NAME=START:STOP:N",
                        help=f"swept parameter (repeat); NAME one of {sorted(PARAMETERS)}")
    parser.add_argument("--design", type=Path, default=None)
    parser.add_argument("--out", type=Path, default=Path("designkit-sweep"))
    parser.add_argument("--workers", type=int, default=None,
                        help="local worker processes (default: CPU count)")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="dask.distributed scheduler address: run the sweep there")
    parser.add_argument("--core-model", choices=CORE_MODEL_NAMES, default="air")
    add_progress_argument(parser)


def run(args: argparse.Namespace) -> int:
    check_output(args.out, folder=True)
    if not args.param:
        raise BadInputError("--param", "at least one NAME=START:STOP:N", "nothing")
    ranges = [parse_param(p) for p in args.param]
    grid(ranges)  # checks duplicates and size before any work
    if args.workers is not None and args.workers < 1:
        raise BadInputError("--workers", "a whole number >= 1", args.workers)
    design = load_design(args.design)
    result = run_sweep(design, ranges, workers=args.workers, scheduler=args.scheduler,
                       core_model=args.core_model, progress=show_progress(args))
    out = Path(args.out)
    # the CSV and the PNG are written only after every design is evaluated (atomic renames)
    csv_path = write_csv(result, out / "sweep.csv")
    png_path = plot(result, out / "sweep.png")
    n = len(result.rows)
    feas = sum(1 for r in result.rows if r["feasible"])
    print(f"{n} designs ({feas} feasible) in {result.seconds:.2f} s on {result.workers} "
          f"worker(s) [{result.backend}]")
    if result.best_index is not None:
        b = result.rows[result.best_index]
        print(f"best feasible: Ri {b['inner_radius_m'] * 1e3:.2f} mm, Ro "
              f"{b['outer_radius_m'] * 1e3:.2f} mm, L {b['length_m'] * 1e3:.2f} mm, "
              f"{b['turns']} turns, R {b['resistance_ohm']:.3f} ohm, 5 tau "
              f"{5e3 * b['time_constant_s']:.2f} ms, force {b['force_n'] * 1e3:.1f} mN")
    if feas == 0:
        print(f"no feasible design; why (column 'reason' of {csv_path.name}):\n"
              + reason_summary(result))
    print(f"wrote {csv_path} and {png_path}")
    return 0
