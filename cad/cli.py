"""``designkit cad``: printable parts (STL/STEP/3MF), assembly STEP + PNG, parts list.

Thin: parse, load the design, convert once (:func:`cad.params.from_design`), export, print
a short table. Design-rule errors are raised before anything is written.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from designkit.support import validate as v
from designkit.commands.common import (add_design_argument, add_progress_argument, check_output,
                                       show_progress)
from designkit.design import load_design

from . import export
from .params import PrinterParams, from_design


def _triple(text: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(v) for v in text.lower().replace("x", ",").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y,Z in mm, got {text!r}") from None
    if len(vals) != 3 or not all(v > 0 for v in vals):
        raise argparse.ArgumentTypeError(f"expected three positive numbers X,Y,Z in mm, got {text!r}")
    return vals


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``designkit cad``."""
    add_design_argument(parser)
    parser.add_argument("--out", type=Path, default=Path("cad_out"),
                        help="output folder (default: ./cad_out)")
    parser.add_argument("--format", default="stl,step,3mf",
                        help="comma-separated subset of stl,step,3mf (default: all); the "
                             "assembly is written as assembly.step only when step is asked for")
    parser.add_argument("--mandrel", choices=["auto", "printed_tube", "core"], default=None,
                        help="what carries the winding: a printed tube, or the core itself "
                             "(auto: a tube when the core leaves room for one; default: the "
                             "design's cad.mandrel, 'auto' unless set)")
    parser.add_argument("--build-volume", type=_triple, default=(230.0, 190.0, 200.0),
                        metavar="X,Y,Z", help="printer build volume in mm (default 230,190,200)")
    parser.add_argument("--min-wall", type=float, default=None,
                        help="thinnest printable wall in mm (default: the design's "
                             "cad.min_wall_m, 0.8 mm unless set)")
    parser.add_argument("--tolerance", type=float, default=0.02,
                        help="tessellation linear deflection in mm (default 0.02)")
    parser.add_argument("--finger-diameter", type=float, default=None,
                        help="inner diameter of the finger ring in mm (default: the design's "
                             "cad.finger_diameter_m, 18 mm unless set)")
    parser.add_argument("--press-fit", type=float, default=None,
                        help="radial clearance of the magnet pocket in mm (default: the "
                             "design's cad.press_fit_clearance_m, 0.05 mm unless set)")
    parser.add_argument("--oversize", choices=["error", "skip"], default="error",
                        help="a part larger than the build volume: fail (default) or skip it")
    parser.add_argument("--picture", choices=["png", "none"], default="png",
                        help="assembly.png picture (default png)")
    add_progress_argument(parser)


def _mm(name: str, value, check):
    return None if value is None else check(name, value, "mm")


def run(args: argparse.Namespace) -> int:
    """Export the design's parts to --out and print the parts table; 3 when parts were skipped."""
    check_output(args.out, folder=True)
    formats = export.parse_formats(args.format)
    printer = dataclasses.replace(
        PrinterParams(), build_volume_mm=tuple(args.build_volume),
        tolerance_mm=v.positive("--tolerance", args.tolerance, "mm"))
    min_wall = _mm("--min-wall", args.min_wall, v.positive)
    finger = _mm("--finger-diameter", args.finger_diameter, v.positive)
    press_fit = _mm("--press-fit", args.press_fit, v.finite)
    design = load_design(args.design)
    params = from_design(design, mandrel=args.mandrel, printer=printer, min_wall_mm=min_wall,
                         finger_diameter_mm=finger, press_fit_clearance_mm=press_fit)
    report = export.export_all(params, args.out, formats, picture=args.picture,
                               oversize=args.oversize,
                               progress="bar" if show_progress(args) else "none")
    print(f"designkit cad: {design.name} -> {args.out} ({report['seconds']['total']:.1f} s, "
          f"mandrel {report['mandrel']})")
    print(f"{'part':<20} {'qty':>3} {'material':<8} {'volume mm^3':>12} {'mass g':>8} {'fits':>5}")
    for r in report["parts"]:
        fits = {True: "yes", False: "NO"}.get(r.get("fits_printer"), "-")
        print(f"{r['part']:<20} {r['quantity']:>3} {r['material']:<8} {r['volume_mm3']:>12.1f} "
              f"{r['mass_g']:>8.1f} {fits:>5}")
    for name in report["skipped_oversize"]:
        size = next(r["size_mm"] for r in report["parts"] if r["part"] == name)
        print(f"NOT exported, larger than the build volume: {name} "
              f"({' x '.join(f'{s:.1f}' for s in size)} mm)")
    total = sum(report["files"].values())
    print(f"{len(report['files'])} files, {total / 1e6:.2f} MB")
    return 3 if report["skipped_oversize"] else 0
