"""``designkit report``: the main job on a design (default: the thesis device).

Writes ``OUT/report.json`` with the default coil's field, gradient and the force and torque on
the finger magnet at the design point, and prints a summary table.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .. import __version__
from .._io import write_json_atomic
from ..coil import Coil
from ..design import load_design


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--design", type=Path, default=None,
                        help="design TOML file (default: the embedded thesis design)")
    parser.add_argument("--out", type=Path, default=Path("designkit-report"),
                        help="output folder (default: ./designkit-report)")
    parser.add_argument("--current", type=float, default=None,
                        help="coil current in A (default: the design's per-coil limit)")


def design_point_summary(design, current_a: float) -> dict:
    """Field, gradient, force and torque of the design's coil at its design point (SI)."""
    coil = Coil.from_design(design)
    p = np.array(design.design_point_m)
    b, g = coil.field(p, current_a, gradient=True)
    m = np.array([0.0, 0.0, design.magnet.moment_a_m2])
    force = g.T @ m  # F = grad(m . B) = G^T m
    torque = np.cross(m, b)
    return {
        "current_a": current_a,
        "point_m": p.tolist(),
        "magnet_moment_a_m2": m.tolist(),
        "flux_density_t": b.tolist(),
        "gradient_t_per_m": g.tolist(),
        "force_n": force.tolist(),
        "torque_n_m": torque.tolist(),
        "core_model": None if coil.core is None else coil.core.model,
    }


def run(args: argparse.Namespace) -> int:
    design = load_design(args.design)
    current = design.drive.max_current_a if args.current is None else float(args.current)
    summary = design_point_summary(design, current)
    report = {
        "designkit_version": __version__,
        "design_name": design.name,
        "design_hash": design.spec_hash(),
        "design": design.to_dict(),
        "design_point": summary,
    }
    out = Path(args.out)
    write_json_atomic(out / "report.json", report)
    b = summary["flux_density_t"]
    f = summary["force_n"]
    print(f"designkit {__version__} - design '{design.name}' ({design.spec_hash()[:12]})")
    print(f"coil: Ri/Ro/L = {design.coil.inner_radius_m * 1e3:.1f}/{design.coil.outer_radius_m * 1e3:.1f}"
          f"/{design.coil.length_m * 1e3:.1f} mm, {design.coil.turns} turns, core: "
          f"{summary['core_model'] or 'none'}")
    print(f"design point: {design.optimize.height_m * 1e3:.1f} mm above the coil top, I = {current:g} A")
    print(f"  B     = ({b[0] * 1e3:+.4f}, {b[1] * 1e3:+.4f}, {b[2] * 1e3:+.4f}) mT")
    print(f"  dBz/dz = {summary['gradient_t_per_m'][2][2]:+.5f} T/m")
    print(f"  F     = ({f[0] * 1e3:+.3f}, {f[1] * 1e3:+.3f}, {f[2] * 1e3:+.3f}) mN on m = "
          f"{design.magnet.moment_a_m2:.4f} A m^2")
    print(f"wrote {out / 'report.json'}")
    return 0
