"""``designkit fem``: GetDP cross-check of the design's coil and core, or of its whole array.

Axisymmetric (default): one coil alone (``--coil``, its own winding and core) against the
single-coil models; writes to --out: model.msh (+ model.vtu, model.xdmf), model.pro, getdp.log,
fem_results.json (FEM lines, energy, inductance and the relative errors of designkit's models)
and fem_vs_designkit.png. An array couples its cores and is not axisymmetric: the command says
so and names ``--3d``.

``--3d``: the design's whole array (any layout, tilted coils included; every core in its pose,
coil ``--coil`` at 1 A) in the 3-D GetDP model against the coupled A(p) over the workspace
(:mod:`designkit.fem.array_check`); writes fem3d_results.json and GetDP's files to --out.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..design import load_design
from ..errors import BadInputError
from ..fem.array_check import check_array, workspace_points
from ..fem.compare import air_inductance, comparison_table, plot_comparison
from ..fem.runner import solve
from ..model.array import CoilArray
from ..model.coil import Coil
from ..support.atomic import write_json_atomic
from ..support.validate import in_range
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
    parser.add_argument("--level", type=int, default=None,
                        help="mesh refinement level: 0..6 (default 1) axisymmetric, -2..2 "
                             "(default 0) with --3d")
    parser.add_argument("--3d", dest="three_d", action="store_true",
                        help="the whole array in 3-D (any layout): coil --coil at 1 A against "
                             "the coupled model over the workspace")
    parser.add_argument("--coil", type=int, default=None,
                        help="the coil modelled (axisymmetric) or energized (--3d) (default: "
                             "the coil nearest the design point)")
    parser.add_argument("--out", default="fem_out",
                        help="output folder, relative to the working folder (default ./fem_out)")


def _chosen_coil(design, k) -> int:
    """``--coil`` checked, or the coil whose axis passes nearest the design point."""
    n = design.n_coils
    if k is None:
        tops = design.array.top_centres_m()
        return int(np.argmin(np.hypot(tops[:, 0], tops[:, 1])))
    if not (isinstance(k, int) and 0 <= k < n):
        raise BadInputError("--coil", f"a coil index in [0, {n - 1}]", k)
    return k


def run(args) -> int:
    """Solve the design's coil (or, with --3d, its array) with GetDP, compare designkit's
    models, write --out."""
    out = check_output(args.out, folder=True)
    design = load_design(args.design)
    k = _chosen_coil(design, args.coil)
    if args.three_d:
        return _run_3d(args, design, k, out)
    coil = Coil.of_design(design, k)
    if design.n_coils > 1:
        print(f"designkit fem: axisymmetric check of coil {k} alone (its winding and core); "
              f"the design's {design.n_coils} coils ({design.array.describe()}) couple their "
              "cores and are not axisymmetric: designkit fem --3d compares the whole array")
    if coil.core is not None:
        if args.bh is not None:
            coil = dataclasses.replace(coil, core=dataclasses.replace(coil.core, bh=args.bh))
        elif args.mu_r is not None:
            coil = dataclasses.replace(coil, core=dataclasses.replace(
                coil.core, relative_permeability=float(args.mu_r)))
    current = design.drive.max_current_a if args.current is None else args.current
    if not current > 0:
        raise BadInputError("--current", "> 0 A", current)
    level = 1 if args.level is None else args.level
    if not 0 <= level <= 6:
        raise BadInputError("--level", "an integer 0..6", level)
    # staged (absolute: GetDP runs inside it): a failure or Ctrl-C leaves no partial folder
    with staged_folder(out) as stage:
        res, summary = _solve_and_write(design, coil, current, level, stage)
    _print_summary(res, summary, out)
    return 0


def _run_3d(args, design, k: int, out) -> int:
    """``--3d``: the coupled array against the 3-D FEM, written to ``out``."""
    if args.bh is not None:
        raise BadInputError("--bh", "not given with --3d (the 3-D model's cores are linear)",
                            args.bh)
    if args.current is not None:
        raise BadInputError("--current", "not given with --3d (linear cores: the column of A "
                            "is per ampere)", args.current)
    level = 0 if args.level is None else args.level
    if not -2 <= level <= 2:
        raise BadInputError("--level", "an integer -2..2 with --3d", level)
    array = CoilArray.from_design(design)
    if args.mu_r is not None:  # every core, its group's too
        mu = in_range("--mu-r", args.mu_r, 1.0, 1e6)
        array = CoilArray(tuple(c if c.core is None else c.replace(
            core=dataclasses.replace(c.core, relative_permeability=mu)) for c in array.coils))
    if not any(c.core is not None for c in array.coils):
        raise BadInputError("--design", "a design with iron cores for --3d (air coils are "
                            "exact superposition: nothing to compare)", design.name)
    pts = workspace_points(design)
    with staged_folder(out) as stage:
        res = check_array(array, pts, k, level, out_dir=stage)
        write_json_atomic(stage / "fem3d_results.json", {
            "design": design.name, "design_hash": design.spec_hash(),
            "layout": design.array.describe(), "coil": k, "level": level, **res.to_dict()})
    worst = max(res.coupled_error.values())
    print(f"designkit fem --3d: {design.array.describe()}, coil {k} at 1 A, "
          f"{res.tetrahedra} tetrahedra ({res.symmetry} model), {res.seconds:.0f} s; "
          f"largest error of the coupled model per row of A (of each row's max over "
          f"{len(pts)} points, 20-80 mm) {worst * 100:.2f} % (uncoupled "
          f"{max(res.uncoupled_error.values()) * 100:.1f} %)")
    for row, e in res.coupled_error.items():
        print(f"  {row:7s} {e * 100:6.2f} %  (uncoupled {res.uncoupled_error[row] * 100:6.1f} %)")
    print(f"  wrote {out}")
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
