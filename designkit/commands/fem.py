"""``designkit fem``: GetDP cross-check of the design's coil and core.

Writes to --out: model.msh (+ model.vtu, model.xdmf), model.pro, getdp.log, fem_results.json
(FEM lines, energy, inductance and the relative errors of designkit's models) and
fem_vs_designkit.png.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..design import load_design
from ..errors import BadInputError
from ..fem.compare import air_inductance, comparison_table, plot_comparison
from ..fem.runner import solve
from ..model.coil import Coil
from ..support.atomic import write_json_atomic
from .common import add_design_argument, check_output, staged_folder


def add_arguments(parser) -> None:
    """The options of ``designkit fem``."""
    add_design_argument(parser)
    mat = parser.add_mutually_exclusive_group()
    mat.add_argument("--mu-r", type=float, default=None,
                     help="linear core relative permeability (default: the design's)")
    mat.add_argument("--bh", choices=["steel1010"], default=None,
                     help="nonlinear core with this B-H curve (FEMM '1010 Steel')")
    parser.add_argument("--current", type=float, default=None,
                        help="coil current, A (default: the design's drive.max_current_a)")
    parser.add_argument("--level", type=int, default=1,
                        help="mesh refinement level 0..6 (default 1)")
    parser.add_argument("--out", default="fem_out",
                        help="output folder, relative to the working folder (default ./fem_out)")


def run(args) -> int:
    """Solve the design's coil with GetDP, compare designkit's models, write --out."""
    out = check_output(args.out, folder=True)
    design = load_design(args.design)
    coil = Coil.from_design(design)
    if coil.core is not None:
        if args.bh is not None:
            coil = dataclasses.replace(coil, core=dataclasses.replace(coil.core, bh=args.bh))
        elif args.mu_r is not None:
            coil = dataclasses.replace(coil, core=dataclasses.replace(
                coil.core, relative_permeability=float(args.mu_r)))
    current = design.drive.max_current_a if args.current is None else args.current
    if not current > 0:
        raise BadInputError("--current", "> 0 A", current)
    if not 0 <= args.level <= 6:
        raise BadInputError("--level", "an integer 0..6", args.level)
    # staged (absolute: GetDP runs inside it): a failure or Ctrl-C leaves no partial folder
    with staged_folder(out) as stage:
        res, summary = _solve_and_write(design, coil, current, args.level, stage)
    _print_summary(res, summary, out)
    return 0


def _solve_and_write(design, coil, current: float, level: int, stage):
    """Solve, compare and write fem_results.json and fem_vs_designkit.png into ``stage``."""
    res = solve(coil, current, level=level, out_dir=stage, export=True)
    heights = np.array([0.014, 0.02, 0.03, 0.04, 0.06, 0.08, 0.10])
    table = comparison_table(coil, res, heights)
    l_air = air_inductance(coil)
    extra = 0.0
    if coil.core is not None:
        extra = coil.core.extra_inductance(coil, current if coil.core.bh != "linear" else None)
    summary = {
        "design": design.name,
        "design_hash": design.spec_hash(),
        "core": None if coil.core is None else dataclasses.asdict(coil.core),
        "model_inductance_h": l_air + extra,
        "air_inductance_quadrature_h": l_air,
        "comparison": table,
        "heights_m": heights.tolist(),
    }
    data = res.to_dict()
    data["files"] = {k: Path(v).name for k, v in data["files"].items()}  # names in --out
    write_json_atomic(stage / "fem_results.json", {**data, **summary})
    plot_comparison(coil, res, stage / "fem_vs_designkit.png")
    return res, summary


def _print_summary(res, summary: dict, out) -> None:
    """The stdout lines: inductance and the axis comparison, and where it was written."""
    heights = np.asarray(summary["heights_m"])
    table = summary["comparison"]
    key = "winding" if summary["core"] is None else "surface-current"
    lfem = res.inductance_linkage
    print(f"designkit fem: {res.mesh_stats['nodes']} nodes, GetDP {res.solve_seconds:.1f} s; "
          f"L_FEM = {lfem * 1e3:.4g} mH, designkit {summary['model_inductance_h'] * 1e3:.4g} mH "
          f"({(summary['model_inductance_h'] / lfem - 1) * 100:+.2f} %)")
    ax = table["axis"]
    for i, h in enumerate(heights):
        print(f"  {h * 1e3:5.0f} mm: FEM Bz {ax['fem_bz_t'][i] * 1e3:9.4f} mT "
              f"dBz/dz {ax['fem_dbz_dz_t_per_m'][i]:9.4f} T/m | {key} "
              f"{ax[key + '_bz_rel_err'][i] * 100:+.3f} % {ax[key + '_dbz_dz_rel_err'][i] * 100:+.3f} %")
    print(f"  wrote {out}")
