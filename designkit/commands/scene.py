"""``designkit scene compile OBJECT``: a compiled scene the runner loads with numpy alone.

OBJECT is plane, hemisphere, half-cylinder, wedge (thesis sizes) or an STL/PLY file (closed
mesh, millimetres unless --mesh-scale). Without --lambda the force constant (thesis eq. 4.3) is
computed with the exact allocator against the map (--map; --build-map builds the object's scene
map first) or, without a map, the design's coil array directly. The scene records the map's
design SHA-256; the runner's loader refuses the scene with another map.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from .. import fieldmap, render
from ..design import load_design
from ..errors import BadInputError
from ._common import add_progress_argument, check_output, show_progress


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", choices=["compile"], help="what to do")
    parser.add_argument("object", help="plane | hemisphere | half-cylinder | wedge | FILE.stl/ply")
    parser.add_argument("--map", type=Path, default=None,
                        help="force-current map (designkit map); default: the design's array")
    parser.add_argument("--build-map", type=Path, default=None,
                        help="build the scene map of the object (its region plus 5 mm; "
                             "designkit map --scene) into this .npz and compute lambda on it")
    parser.add_argument("--design", type=Path, default=None,
                        help="design TOML (without --map; default: the embedded thesis design)")
    parser.add_argument("--out", type=Path, default=Path("scene.npz"), help="output .npz")
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
    parser.add_argument("--mesh-spacing", type=float, default=2.0,
                        help="signed-distance grid spacing, mm (default 2)")
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
    obj = render.make_object(args.object, scale=args.mesh_scale,
                             spacing_m=args.mesh_spacing * 1e-3) \
        if Path(args.object).suffix.lower() in (".stl", ".ply") \
        else render.make_object(args.object)
    if args.build_map is not None:
        args.map = _build_scene_map(args, obj)
    if args.map is not None:
        fm = fieldmap.load(args.map)
        source = render.actuation_source(fm)
        u_default, t_default = fm.meta["max_current_a"], fm.meta["total_current_a"]
    else:
        design = load_design(args.design)
        source = render.ArrayActuation.from_design(design)
        u_default, t_default = design.drive.max_current_a, design.drive.total_current_a
    u = u_default if args.current_limit is None else args.current_limit
    tl = t_default if args.total_current is None else args.total_current
    extra = {"object": args.object, "unipolar": bool(args.unipolar), "rows": args.rows,
             "current_limit_a": u, "total_current_a": tl}
    if args.lam is None:
        fc = render.force_constant(obj, source, current_limit_a=u, total_current_a=tl,
                                   unipolar=args.unipolar, rows=args.rows, n_side=args.n_side,
                                   progress=show_progress(args))
        lam = fc.lam_n_per_m
        extra["lambda_limiting_point_m"] = fc.limiting_point_m.tolist()
        extra["lambda_points"] = int(len(fc.points_m))
        how = (f"computed (eq. 4.3, {len(fc.points_m)} surface points), limiting point "
               f"{[round(float(c) * 1e3, 1) for c in fc.limiting_point_m]} mm")
    else:
        if not args.lam >= 0:
            raise BadInputError("--lambda", ">= 0 N/m", args.lam)
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
