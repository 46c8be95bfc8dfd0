"""Clearances between the solids of a design in their poses: coil to coil, board to board,
board to coil, standoff to coil (SI, m).

Each coil is convex solids in its pose (:mod:`.convex`): the winding, the core, the bobbin's
envelope (flange radius over the winding and both flanges) and its frame pocket (pocket radius
over the same length). A clearance is the signed distance of two solids (negative: they
overlap by that much), never a distance of centres. The rows for a pair of coils keep the form
of the thesis' grid rules: value = the two radii, limit = their spacing (closest distance of
the solids + the two radii), which for side-by-side parallel coils is the pitch.
"""

from __future__ import annotations

import functools
import itertools

import numpy as np

from ..design import Design
from ..design.layouts import Layout
from .geometry import Assembly, CoilType, coil_axes, pocket_solid, standoff_solid
from .convex import Box, Cylinder, lower_bound_m, signed_distance
from .rule import Rule, wall

LAYOUT_KEYS = {"grid": ("array.pitch_m",), "hex": ("array.pitch_m",),
               "ring": ("array.radius_m", "array.tilt_deg"),
               "free": ("array.positions_m", "array.axes")}
"""The layout keys that move coils apart, by layout kind."""


def layout_keys(design: Design) -> tuple[str, ...]:
    return LAYOUT_KEYS[design.array.kind]


def coil_solid(design: Design, t: CoilType, k: int, what: str) -> Cylinder | None:
    """Coil k's 'winding', 'core', 'envelope' (bobbin: flange radius, both flanges) or
    'pocket' as a cylinder in its pose, m (None: an air coil's core)."""
    position, axis = coil_axes(design)[k]
    half = t.coil.length_m / 2
    if what == "winding":
        return Cylinder(position, axis, half, t.coil.outer_radius_m)
    if what == "core":
        if t.core is None:
            return None
        c = np.asarray(position) + np.asarray(axis) * t.core.offset_m
        return Cylinder(tuple(c), axis, t.core.length_m / 2, t.core.radius_m)
    if what == "envelope":
        return Cylinder(position, axis, half + design.cad.flange_thickness_m,
                        t.flange_radius_m)
    return pocket_solid(design, t, k)


def _closest(pairs) -> tuple[float, object]:
    """(smallest signed distance, its pair label) over ``pairs`` of (label, solid_a, solid_b),
    skipping pairs whose bounding spheres are farther apart than the best so far."""
    best, which = np.inf, None
    items = sorted(pairs, key=lambda q: lower_bound_m(q[1], q[2]))
    for label, a, b in items:
        if lower_bound_m(a, b) >= best:
            break
        d = signed_distance(a, b)
        if d < best:
            best, which = d, label
    return float(best), which


def _coil_pairs(design: Design, asm: Assembly, parts: tuple[str, ...]):
    """(label (i, j), solid of i, solid of j) for every pair of coils and every combination
    of ``parts`` (a core with the other coil's ``parts[0]`` too)."""
    n = design.n_coils
    solids = [{p: coil_solid(design, asm.type_of_coil(k), k, p) for p in parts + ("core",)}
              for k in range(n)]
    for i, j in itertools.combinations(range(n), 2):
        names = [(p, p) for p in parts] + [("core", parts[0]), (parts[0], "core"),
                                          ("core", "core")]
        for pa, pb in names:
            a, b = solids[i][pa], solids[j][pb]
            if a is not None and b is not None:
                yield (i, j), a, b


def pair_rules(design: Design, asm: Assembly) -> list[Rule]:
    """No overlap of windings, of bobbin envelopes, a frame web between the pockets and, with
    a mount plate, a web between the board pockets: the worst pair of each."""
    if design.n_coils < 2:
        return []
    c = design.cad
    keys = layout_keys(design)
    out = []
    for name, part, radius, what, extra in (
            ("coils_overlap", "winding", lambda t: t.coil.outer_radius_m,
             "winding outer radii", ()),
            ("flanges_overlap", "envelope", lambda t: t.flange_radius_m,
             "bobbin flange radii", ("cad.flange_lip_m",))):
        sd, (i, j) = _closest(_coil_pairs(design, asm, (part,)))
        ti, tj = asm.type_of_coil(i), asm.type_of_coil(j)
        value = radius(ti) + radius(tj)
        limit = value + sd
        fix_keys = keys + tuple(dict.fromkeys((ti.key("coil.outer_radius_m"),
                                               tj.key("coil.outer_radius_m"))))
        out.append(Rule(name, value, limit, "m", "upper", fix_keys + extra,
                        f"{what} of coils {i} and {j} at their spacing ({part}s overlap above "
                        "it)", _spread_fix(design, keys, value - limit, value)
                        + f" or reduce {' / '.join(fix_keys[len(keys):] + extra)}"))
    sd, (i, j) = _closest(_coil_pairs(design, asm, ("pocket",)))
    ti, tj = asm.type_of_coil(i), asm.type_of_coil(j)
    radii = ti.pocket_radius_m + tj.pocket_radius_m
    out.append(wall("frame_web", f"frame web between the flange pockets of coils {i} and {j}",
                    sd, c.min_wall_m, keys + (ti.key("coil.outer_radius_m"), "cad.flange_lip_m",
                                              "cad.pocket_clearance_m"),
                    _spread_fix(design, keys, c.min_wall_m - sd, radii + c.min_wall_m)
                    + " or reduce coil.outer_radius_m / cad.flange_lip_m / "
                    "cad.pocket_clearance_m"))
    if asm.sensor_holder == "mount":
        boards = board_solids(design, pocket=True)[:design.n_coils]
        sd, (i, j) = _closest(((i, j), boards[i], boards[j]) for i, j in
                              itertools.combinations(range(len(boards)), 2))
        out.append(wall("sensor_board_web", "sensor mount web between board pockets", sd,
                        c.min_wall_m, keys[:1] + ("cad.board_width_m",),
                        f"use a smaller sensor board (cad.board_width_m) or increase "
                        f"{keys[0]}"))
    return out


def _spread_fix(design: Design, keys, deficit_m: float, needed_m: float) -> str:
    """'increase array.pitch_m to >= X m' for a lattice (``needed_m``: the spacing that meets
    the rule for parallel coils), else 'move the coils apart by D (keys)'."""
    if design.array.kind in ("grid", "hex"):
        return f"increase array.pitch_m to >= {needed_m:.4g} m"
    return (f"move the coils apart by at least {max(deficit_m, 0.0) * 1e3:.3g} mm "
            f"({' / '.join(keys)})")


def board_solids(design: Design, pocket: bool = False) -> list[Box]:
    """Every sensor board as a box in its chip frame (side ``cad.board_width_m``, thickness
    ``cad.board_thickness_m``; ``pocket``: grown by the pocket clearance in its plane), m."""
    c = design.cad
    side = c.board_width_m / 2 + (c.board_clearance_m if pocket else 0.0)
    pos, rot = design.sensor_poses()
    return [Box(tuple(map(float, p)), tuple(map(tuple, r)), (side, side, c.board_thickness_m / 2))
            for p, r in zip(pos, rot)]


def board_rules(design: Design, asm: Assembly) -> list[Rule]:
    """Every sensor board clear of the other coils' bobbins and cores (of every coil for a
    free sensor layout); not needed with a mount plate above level coil tops."""
    if asm.sensor_holder == "mount":
        return []
    boards = board_solids(design)
    n = design.n_coils
    own = ([k % n for k in range(len(boards))] if design.sensors.layout != "free"
           else [-1] * len(boards))
    pairs = []
    for b, board in enumerate(boards):
        for k in range(n):
            if k == own[b]:
                continue
            for part in ("envelope", "core"):
                s = coil_solid(design, asm.type_of_coil(k), k, part)
                if s is not None:
                    pairs.append(((b, k), board, s))
    if not pairs:
        return []
    sd, (b, k) = _closest(pairs)
    keys = (("sensors.positions_m", "sensors.rotations") if design.sensors.layout == "free"
            else ("sensors.offset_m",)) + layout_keys(design)
    return [Rule("sensor_board_to_coils", sd, 0.0, "m", "lower", keys,
                 f"sensor board {b} clear of coil {k} (its bobbin and core)",
                 f"move sensor {b} or coil {k} apart ({' / '.join(keys)})")]


def standoff_rule(design: Design, asm: Assembly) -> Rule:
    """The nearest standoff to a coil's flange pocket is a wall away."""
    c = design.cad
    z_lo, z_hi = asm.standoff_z_m
    pairs = [((f, k), standoff_solid(design, p, z_lo, z_hi),
              pocket_solid(design, asm.type_of_coil(k), k))
             for f, p in enumerate(asm.fixing_xy_m) for k in range(design.n_coils)]
    sd, _ = _closest(pairs)
    keys = ("cad.fixing_inset_m", "cad.standoff_outer_radius_m") + layout_keys(design)[:1]
    spread = (f"increase {keys[-1]}" if design.array.kind in ("grid", "hex")
              else f"move the coils ({' / '.join(layout_keys(design))})")
    return wall("standoff_to_pocket", "standoff to the nearest flange pocket", sd, c.min_wall_m,
                keys, f"reduce cad.fixing_inset_m or cad.standoff_outer_radius_m, or {spread}")


@functools.lru_cache(maxsize=4096)
def lattice_gap_m(layout: Layout, radius_m: float, length_m: float, beyond_m: float) -> float:
    """Smallest signed distance between identical coil cylinders on ``layout``, m: radius
    ``radius_m`` along each axis from ``beyond_m`` above the top face to ``beyond_m`` below a
    winding of ``length_m`` (e.g. the frame pockets: the pocket radius and the flange
    thickness). A grid or hex lattice of upright coils: the pitch less two radii."""
    tops, axes = layout.top_centres_m(), layout.axes()
    if len(tops) < 2:
        return np.inf
    if layout.kind in ("grid", "hex"):
        return layout.pitch_m - 2 * radius_m
    half = length_m / 2 + beyond_m
    cyl = [Cylinder(tuple(t - a * length_m / 2), tuple(a), half, radius_m)
           for t, a in zip(tops, axes)]
    return _closest(((i, j), cyl[i], cyl[j])
                    for i, j in itertools.combinations(range(len(cyl)), 2))[0]
