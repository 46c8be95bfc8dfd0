"""``designkit scene compile OBJECT``: a compiled scene the runner loads with numpy alone.

OBJECT is plane, hemisphere, half-cylinder, wedge (thesis sizes) or an STL/PLY file (closed
mesh, millimetres unless --mesh-scale). Without --lambda the force constant (thesis eq. 4.3) is
computed with the exact allocator against the map (--map; --build-map builds the object's scene
map first) or, without a map, the design's coil array directly, over the surface points where
any force is renderable (where the magnet's pull on the cores cannot be cancelled, no lambda is,
and those points are counted, as ``designkit run --simulate`` does). The scene records the map's
design SHA-256; the runner's loader refuses the scene with another map.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .. import fieldmap, render
from ..design import load_design
from ..errors import BadInputError
from ..support import validate as v
from .common import (add_design_argument, add_progress_argument, check_output, parse_length,
                     parse_lengths, show_progress)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", choices=["compile"], help="what to do")
    parser.add_argument("object", help="plane | hemisphere | half-cylinder | wedge | FILE.stl/ply")
    parser.add_argument("--map", type=Path, default=None,
                        help="force-current map (designkit map); default: the design's array")
    parser.add_argument("--build-map", type=Path, default=None,
                        help="build the scene map of the object (its region plus 5 mm; "
                             "designkit map --scene) into this .npz and compute lambda on it")
    add_design_argument(parser, "; with --map it must be the map's design")
    parser.add_argument("--out", type=Path, default=Path("scene.npz"),
                        help="output .npz (default ./scene.npz)")
    parser.add_argument("--lambda", dest="lam", type=float, default=None,
                        help="force constant in N/m (default: computed, eq. 4.3)")
    parser.add_argument("--unipolar", action="store_true",
                        help="0 <= I <= u as in the thesis (default: bipolar |I| <= u)")
    parser.add_argument("--rows", choices=["force", "fz"], default="force",
                        help="required force: 3-D lambda h n (default) or the thesis' Fz only")
    parser.add_argument("--current-limit", type=float, default=None,
                        help="per-coil limit, A (default: the map's / design's)")
    parser.add_argument("--total-current", type=float, default=None,
                        help="budget on sum |I|, A (default: the map's / design's)")
    parser.add_argument("--law", choices=["constraint", "penetration"], default="constraint",
                        help="constraint: lambda h n (thesis); penetration: proxy wall")
    parser.add_argument("--stiffness", type=float, default=200.0,
                        help="penetration stiffness, N/m (clamped by the passivity bound)")
    parser.add_argument("--loop-period", type=float, default=5.0,
                        help="control loop period for the passivity bound, ms (default 5)")
    parser.add_argument("--n-side", type=int, default=61,
                        help="surface points per side for lambda (default 61: 3721 points)")
    parser.add_argument("--mesh-scale", type=float, default=1e-3,
                        help="mesh file units to m (default 1e-3: mm)")
    parser.add_argument("--mesh-spacing", default="2mm", metavar="LENGTH",
                        help="signed-distance grid spacing (default 2mm; a number is mm)")
    parser.add_argument("--mesh-at", default="0,0,0", metavar="X,Y,Z",
                        help="where the mesh's bounding-box bottom centre goes above the coil "
                             "tops' centre (default 0,0,0; a number is mm, or 10mm, 1cm, "
                             "0.01m)")
    add_progress_argument(parser)


def _build_scene_map(args: argparse.Namespace, obj) -> Path:
    """Write the scene map of ``obj`` to ``--build-map`` (the design's box cut to where the
    object can push, plus 5 mm; :func:`designkit.fieldmap.scene_build_args`)."""
    if args.map is not None:
        raise BadInputError("--build-map", "without --map (one map source)", str(args.build_map))
    out = fieldmap.check_output(args.build_map)
    design = load_design(args.design)
    kw = fieldmap.scene_build_args(design, [obj], 0.0, region={"objects": [obj.kind],
                                                               "rows": args.rows})
    fieldmap.write(out, fieldmap.build(design, progress=show_progress(args), **kw))
    return out


def run(args: argparse.Namespace) -> int:
    check_output(args.out, folder=False)
    if args.build_map is not None:
        check_output(fieldmap.check_output(args.build_map), folder=False, param="--build-map")
    _check_numbers(args)
    obj = _object(args)
    if args.build_map is not None:
        args.map = _build_scene_map(args, obj)
    if args.map is not None:
        fm = fieldmap.load(args.map)
        source = render.actuation_source(fm)
        u_default, t_default = fm.meta["max_current_a"], fm.meta["total_current_a"]
        if args.design is not None:
            _same_design(args.design, args.map, source.design_sha256)
    else:
        design = load_design(args.design)
        source = render.ArrayActuation.from_design(design)
        u_default, t_default = design.drive.max_current_a, design.drive.total_current_a
    _check_inside(obj, source, args)
    u = u_default if args.current_limit is None else args.current_limit
    tl = t_default if args.total_current is None else args.total_current
    extra = {"object": args.object, "unipolar": bool(args.unipolar), "rows": args.rows,
             "current_limit_a": u, "total_current_a": tl}
    if args.lam is None:
        fc = render.force_constant(obj, source, current_limit_a=u, total_current_a=tl,
                                   unipolar=args.unipolar, rows=args.rows, n_side=args.n_side,
                                   progress=show_progress(args))
        lam = fc.lam_where_renderable()
        if args.law == "constraint":  # lambda h n with lambda 0 renders nothing
            _check_renderable(args, fc)
        limit = fc.limiting_point_where_renderable()
        extra["lambda_limiting_point_m"] = limit.tolist()
        extra["lambda_points"] = int(len(fc.points_m))
        extra["lambda_unrenderable_points"] = fc.unrenderable_points
        how = (f"computed (eq. 4.3, {len(fc.points_m)} surface points), limiting point "
               f"{_mm(limit)} mm" + (f"; {fc.unrenderable_points} points where the cores' "
                                     "pull cannot be cancelled left out"
                                     if fc.unrenderable_points else ""))
    else:
        lam, how = args.lam, "given"
    if args.law == "constraint":
        law = render.ConstraintLaw(lam)
    else:
        law = render.PenetrationLaw(stiffness_n_per_m=args.stiffness,
                                    loop_period_s=args.loop_period * 1e-3)
    path = render.compile_scene(obj, args.out, lam_n_per_m=lam, law=law,
                                map_design_sha256=source.design_sha256, extra_meta=extra)
    print(f"wrote {path}: {args.object}, lambda = {lam:.4g} N/m ({how}), law {args.law}"
          + (f" (K = {law.effective_stiffness_n_per_m:.3g} N/m, limited by "
             f"{law.bound()[1]})" if args.law == "penetration" else "")
          + f", map design {source.design_sha256[:12]}...")
    return 0


def _check_numbers(args) -> None:
    """The numeric options, named as on the command line, before any work."""
    if args.lam is not None:
        v.nonnegative("--lambda", args.lam, "N/m")
    for name, value, unit in (("--current-limit", args.current_limit, "A"),
                              ("--total-current", args.total_current, "A")):
        if value is not None:
            v.nonnegative(name, value, unit)
    v.positive("--stiffness", args.stiffness, "N/m")
    v.in_range("--loop-period", args.loop_period, 0.1, 100.0, "ms")
    v.in_range("--n-side", args.n_side, 3, 401)
    v.in_range("--mesh-scale", args.mesh_scale, 1e-6, 1e3)
    parse_length(args.mesh_spacing, "--mesh-spacing", valid_m=(1e-4, 0.05))


def _mm(p) -> list:
    return [round(float(c) * 1e3, 1) for c in p]


def _object(args):
    """The virtual object: a named one, or a mesh file scaled and placed by the options."""
    if Path(args.object).suffix.lower() not in (".stl", ".ply"):
        return render.make_object(args.object)
    at = parse_lengths(args.mesh_at, "--mesh-at", 3, valid_m=(-1.0, 1.0))
    spacing = parse_length(args.mesh_spacing, "--mesh-spacing", valid_m=(1e-4, 0.05))
    return render.make_object(args.object, scale=args.mesh_scale, spacing_m=spacing,
                              position_m=at)


def _same_design(design_arg, map_path, map_sha: str) -> None:
    """--design next to --map: refused unless it is the map's design (it would be ignored)."""
    sha = load_design(design_arg).spec_hash()
    if sha != map_sha:
        raise BadInputError("--design", f"the design of --map {map_path} (SHA-256 "
                            f"{map_sha[:12]}...) or no --design", f"{design_arg} (SHA-256 "
                            f"{sha[:12]}...)", "The scene uses the map's design; drop --design "
                            "or build the map for this design with `designkit map`.")


def _check_inside(obj, source, args) -> None:
    """Refuse an object none of whose surface lies in the map's box, saying where each is."""
    pts, _ = obj.surface_points(min(args.n_side, 61))
    lo, hi = (np.asarray(b, float) for b in source.bounds)
    if len(pts) and np.any(np.all((pts >= lo - 1e-12) & (pts <= hi + 1e-12), axis=1)):
        return
    span = ("no upward-facing surface" if not len(pts) else
            "surface x {:.0f}..{:.0f}, y {:.0f}..{:.0f}, z {:.0f}..{:.0f} mm".format(
                *np.ravel(np.c_[pts.min(0), pts.max(0)] * 1e3)))
    box = "x {:.0f}..{:.0f}, y {:.0f}..{:.0f}, z {:.0f}..{:.0f} mm".format(
        *np.ravel(np.c_[lo, hi] * 1e3))
    mesh = Path(args.object).suffix.lower() in (".stl", ".ply")
    raise BadInputError("OBJECT", f"an object with its top surface inside the map's box ({box})",
                        f"{args.object} ({span})",
                        "Place the mesh with --mesh-at X,Y,Z (mm, its bottom centre) and size "
                        "it with --mesh-scale (file units to m)." if mesh else "")


def _check_renderable(args, fc) -> None:
    """lambda = 0: the drive cannot render the object at all; say where and what to change."""
    if fc.lam_where_renderable() > 0:
        return
    drive = "unipolar drive (0 <= I <= u)" if args.unipolar else "bipolar drive (|I| <= u)"
    raise BadInputError("OBJECT", f"an object the {drive} can render (lambda > 0 N/m)",
                        f"{args.object}: lambda = 0 N/m, limited at {_mm(fc.limiting_point_m)} "
                        f"mm", "Drop --unipolar, use --rows fz, or give --lambda N/m to "
                        "compile it anyway." if args.unipolar else
                        "Use --rows fz or give --lambda N/m to compile it anyway.")
