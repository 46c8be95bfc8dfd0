"""``designkit viz KIND``: one off-screen pyvista figure of a design, written as a PNG.

KIND is one of ``scene`` (coil array, magnet, workspace; a numbered top view), ``fieldlines``
(streamlines of B), ``slice-B`` / ``slice-F`` (|B| / |F| on a vertical and a horizontal section
through the design point), ``forcemap`` (force arrows at the design point's height) and
``isosurface`` (Fz = +/-0.8 mN). Renders without a display. ``--vtk DIR`` also writes the
figures' data for ParaView.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .. import viz
from ..design import load_design
from ..errors import BadInputError
from .common import (add_currents_arguments, add_design_argument, check_current_limit,
                     check_output, parse_currents, staged_folder)


def parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise BadInputError("--size", "WIDTHxHEIGHT in pixels, e.g. 1024x768", text) from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise BadInputError("--size", "WIDTHxHEIGHT, each 16..8192 pixels", text)
    return w, h


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("kind", choices=viz.KINDS, help="which figure")
    add_design_argument(parser)
    add_currents_arguments(parser, "per-coil currents in A, comma-separated, in the layout's "
                                   "coil order (default: the coil nearest the design point at "
                                   "drive.max_current_a, others 0)")
    parser.add_argument("--out", type=Path, default=None,
                        help="PNG file (default: ./designkit-viz-KIND.png)")
    parser.add_argument("--size", default=None,
                        help="image size WIDTHxHEIGHT in pixels, each 16..8192 (default 1024x768; "
                             "the two-panel scene and slices 1280x640 and 1500x640)")
    parser.add_argument("--quality", choices=("quick", "full"), default="full",
                        help="grid resolution (quick: coarse grids, a few seconds)")
    parser.add_argument("--vtk", type=Path, default=None,
                        help="also write the VTK files for ParaView into this folder")


def run(args: argparse.Namespace) -> int:
    out = check_output(args.out or Path(f"designkit-viz-{args.kind}.png"), folder=False)
    if out.suffix.lower() != ".png":
        raise BadInputError("--out", "a file name ending in .png", str(out))
    if args.vtk is not None:
        check_output(args.vtk, folder=True, param="--vtk")
    design = load_design(args.design)
    currents = viz.resolve_currents(design, parse_currents(args.currents))
    check_current_limit(design, currents, allow=args.allow_over_limit)
    size = None if args.size is None else parse_size(args.size)
    if args.vtk is None:
        _png(args, design, currents, size, out)
        return 0
    # staged: a failure or Ctrl-C leaves neither a partial VTK folder nor the PNG
    with staged_folder(args.vtk, param="--vtk") as stage:
        files = viz.export_vtk(design, stage, currents, quality=args.quality)
        _png(args, design, currents, size, out)
    print(f"wrote {len(files)} VTK files to {args.vtk}")
    return 0


def _png(args, design, currents, size, out) -> None:
    plotter = viz.render(args.kind, design, currents, quality=args.quality, window_size=size)
    try:
        viz.save_png(plotter, out)
    finally:
        plotter.close()
    print(f"wrote {out}")
