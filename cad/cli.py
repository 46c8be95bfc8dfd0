"""``designkit cad``: printable parts (STL/STEP/3MF), assembly STEP + PNG, parts list.

Thin: parse, load the design, convert once (:func:`cad.params.from_design`), export, print
a short table. Design-rule errors are raised before anything is written.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from designkit.commands.common import (add_design_argument, add_progress_argument, check_output,
                                       parse_length, parse_lengths, show_progress)
from designkit.design import load_design

from . import export
from .params import PrinterParams, from_design


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
    parser.add_argument("--build-volume", default="230,190,200", metavar="X,Y,Z",
                        help="printer build volume (default 230,190,200; a number is mm, or "
                             "23cm, 0.23m)")
    parser.add_argument("--min-wall", default=None, metavar="LENGTH",
                        help="thinnest printable wall (a number is mm; default: the design's "
                             "cad.min_wall_m, 0.8 mm unless set)")
    parser.add_argument("--tolerance", default="0.02mm", metavar="LENGTH",
                        help="tessellation linear deflection (default 0.02mm; a number is mm)")
    parser.add_argument("--finger-diameter", default=None, metavar="LENGTH",
                        help="inner diameter of the finger ring (a number is mm; default: the "
                             "design's cad.finger_diameter_m, 18 mm unless set)")
    parser.add_argument("--press-fit", default=None, metavar="LENGTH",
                        help="radial clearance of the magnet pocket (a number is mm; default: "
                             "the design's cad.press_fit_clearance_m, 0.05 mm unless set)")
    parser.add_argument("--oversize", choices=["error", "skip"], default="error",
                        help="a part larger than the build volume: fail (default) or skip it")
    parser.add_argument("--picture", choices=["png", "none"], default="png",
                        help="assembly.png picture (default png)")
    add_progress_argument(parser)


def _mm(name: str, value, valid_m: tuple[float, float]):
    """An optional length option (the command line's units) in mm, None when not given."""
    return None if value is None else 1e3 * parse_length(value, name, valid_m=valid_m)


def run(args: argparse.Namespace) -> int:
    """Export the design's parts to --out and print the parts table; 3 when parts were skipped."""
    check_output(args.out, folder=True)
    formats = export.parse_formats(args.format)
    volume = parse_lengths(args.build_volume.lower().replace("x", ","), "--build-volume", 3,
                           valid_m=(1e-3, 10.0))
    printer = dataclasses.replace(
        PrinterParams(), build_volume_mm=tuple(1e3 * q for q in volume),
        tolerance_mm=_mm("--tolerance", args.tolerance, (1e-7, 1e-3)))
    min_wall = _mm("--min-wall", args.min_wall, (1e-5, 0.05))
    finger = _mm("--finger-diameter", args.finger_diameter, (1e-3, 0.1))
    press_fit = _mm("--press-fit", args.press_fit, (-1e-3, 1e-3))
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
