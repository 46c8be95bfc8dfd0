"""``designkit map``: the map file (v2) the controller runs on.

Samples the coupled array model of a design over its workspace box -- A(p), the magnet's bias
force F0(p), the magnet-induced core field at the Hall sensors, the coils' field at the sensors,
the saturation correction -- and writes one ``.npz`` file atomically (format:
:mod:`firmware_io.mapfile`; built by :mod:`designkit.fieldmap`). With ``--scene`` only the
region the scene's objects can push in, plus a margin (:func:`designkit.fieldmap.scene_region`).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from firmware_io.scene import Scene

from .. import fieldmap
from ..design import load_design
from .common import (add_design_argument, add_progress_argument, check_output, parse_length,
                     show_progress)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_design_argument(parser)
    parser.add_argument("--spacing", default=None, metavar="LENGTH",
                        help="x, y step of the grid over magnet positions that carries the "
                             "bias force beyond the per-core tables (default 10mm, or 5mm when "
                             "some core's axis is not along the magnet's moment; a number is "
                             "mm)")
    parser.add_argument("--scene", type=Path, default=None,
                        help="compiled scene (designkit scene compile): map only the region its "
                             "objects can push in, plus --scene-margin (the runner fails safe "
                             "outside it)")
    parser.add_argument("--scene-margin", default="5mm", metavar="LENGTH",
                        help="margin around the scene's objects (default 5mm; a number is mm)")
    parser.add_argument("--out", type=Path, default=Path("fieldmap.npz"),
                        help="output file, .npz (default ./fieldmap.npz)")
    add_progress_argument(parser)


def scene_args(path: Path, design, margin_m: float) -> dict:
    """:func:`fieldmap.build` arguments of the scene map for the scene file ``path``
    (compiled for ``design``: a scene of another design is refused like the runner does)."""
    sc = Scene.load(path, design.spec_hash())
    return fieldmap.scene_build_args(design, sc.objects, fieldmap.scene_band_m(sc), margin_m,
                                     {"scene": Path(path).name,
                                      "objects": [o.kind for o in sc.objects],
                                      "rows": sc.meta.get("rows", "force")})


def run(args: argparse.Namespace) -> int:
    # everything that can be refused is refused before the (long) computation
    out = fieldmap.check_output(args.out)
    check_output(out, folder=False)  # a folder that cannot be written: refused in < 1 s
    spacing = (None if args.spacing is None else
               parse_length(args.spacing, "--spacing", valid_m=(0.5e-3, 0.1)))
    margin = parse_length(args.scene_margin, "--scene-margin", valid_m=(0.0, 0.1))
    design = load_design(args.design)
    extra = {} if args.scene is None else scene_args(args.scene, design, margin)
    t0 = time.perf_counter()
    data = fieldmap.build(design, spacing=spacing, progress=show_progress(args), **extra)
    path = fieldmap.write(out, data)
    meta = data["meta"]
    err = meta["errors"]
    print(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB) for design {meta['design_name']!r}: "
          f"{meta['n_coils']} coils, A in {sum(lay['nx'] * lay['ny'] for lay in meta['a_layers'])}"
          f" harmonic cells, "
          f"{time.perf_counter() - t0:.1f} s; "
          f"largest error at {err['n_points']} random points (of each row's max |A|): "
          f"{max(err['actuation_max_rel_per_row'].values()):.1e}")
    return 0
