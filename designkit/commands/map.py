"""``designkit map``: the force-current map file the controller runs on.

Computes A(p) (thesis eq. 2.13) over the workspace box of a design and writes one ``.npz``
file atomically (format: :mod:`designkit.fieldmap`).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from ..design import load_design
from ._common import add_progress_argument, show_progress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--design", type=Path, default=None,
                        help="design TOML file (default: the embedded thesis design)")
    parser.add_argument("--spacing", type=float, default=2.0,
                        help="grid spacing in mm (default 2)")
    parser.add_argument("--out", type=Path, default=Path("fieldmap.npz"),
                        help="output file (default ./fieldmap.npz)")
    parser.add_argument("--fine-slab", type=float, default=4.0,
                        help="height in mm of a grid at half the spacing over the bottom of the "
                             "box, where an iron core's rim makes the field vary fastest "
                             "(default 4; 0: none)")
    add_progress_argument(parser)


def run(args: argparse.Namespace) -> int:
    from .. import fieldmap

    design = load_design(args.design)
    t0 = time.perf_counter()
    data = fieldmap.build(design, spacing=args.spacing * 1e-3, fine_slab=args.fine_slab * 1e-3,
                          progress=show_progress(args))
    path = fieldmap.write(args.out, data)
    g = data["meta"]["grid"]
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB): grid {g['shape']} at "
          f"{[round(s * 1e3, 4) for s in g['spacing_m']]} mm"
          + (f" + bottom slab {data['meta']['fine_grid']['shape']}" if data["meta"]["fine_grid"]
             else "")
          + "".join(f" + (rho, z) table {t['shape'][:2]} for coils {t['coils']}"
                    for t in data["meta"]["rz_tables"])
          + f", {data['meta']['n_coils']} coils, "
          f"{time.perf_counter() - t0:.1f} s")
    return 0
