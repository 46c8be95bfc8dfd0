"""The printed assembly's geometry derived from a design (SI, m): what cad builds, what the rule
book checks (cad/params.py converts it to millimetres).

Coil types: the coils that share a winding and core (the design's ``[coil]`` / ``[core]``, and
each ``[[groups]]`` entry) share one bobbin, core and sensor cap. Seats: each coil's top face is
held by the upper frame plate, its bottom face by the lower one; a seat is the face centre and
the outward axis. A plate is a vertical prism over a convex outline whose flange pockets and
bores follow each seat's axis, thick enough that ``cad.plate_thickness_m`` of plate lies above
every pocket along its coil's axis (a tilted coil needs a thicker plate). Plates are printed
with their pockets facing up, so a tilted bore overhangs by the coil's tilt
(:data:`MAX_OVERHANG_DEG`). Standoffs stand vertically between the plates at the corners of
the upper plate's outline inset by ``cad.fixing_inset_m``, or at its edge midpoints where a
corner would meet a coil. Sensor holders: a mount plate per side when every board lies flat at
one height (upright coils in one plane), else a cap per coil end pressed into the plate's bore
('caps'); none for a free sensor layout.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..design import CoilSpec, CoreSpec, Design
from ..design.layouts import grown_hull
from .convex import Cylinder, signed_distance

TOLERANCE_M = 1e-9
MAX_OVERHANG_DEG = 45.0
"""Steepest overhang an FDM printer makes without support, degrees from vertical: the largest
coil tilt the frame plates (printed pockets up, bores along the coil axes) accept."""
FIXING_SIDES = 16
"""Sides of the polygon about a standoff that the lower plate's outline takes in."""
UPRIGHT_TOLERANCE = 1e-12
"""Largest |axis - z| of an upright coil."""


@dataclass(frozen=True)
class CoilType:
    """Coils sharing a winding and core, and the parts derived from them (m)."""

    index: int
    coils: tuple[int, ...]
    where: str
    """Prefix of its design keys: '' (``coil.*``, ``core.*``) or 'groups[g].'."""
    coil: CoilSpec
    core: CoreSpec | None
    mandrel: str
    """'printed_tube' or 'core' (``cad.mandrel`` with 'auto' resolved)."""
    bore_radius_m: float
    flange_radius_m: float
    pocket_radius_m: float
    reach_upper_m: tuple[float, str]
    """How far the coil stack rises above the winding's top plane, m, and what reaches."""
    reach_lower_m: tuple[float, str]

    def key(self, name: str) -> str:
        """The design key of this type's ``coil.*`` / ``core.*`` field."""
        return self.where + name


@dataclass(frozen=True)
class Seat:
    """A coil end held by a frame plate: the face centre (m) and the outward unit axis."""

    coil: int
    centre_m: tuple[float, float, float]
    axis: tuple[float, float, float]

    @property
    def tilt_deg(self) -> float:
        """Angle between the outward axis and the vertical, degrees (0: upright)."""
        return math.degrees(math.acos(min(1.0, abs(self.axis[2]))))


@dataclass(frozen=True)
class Plate:
    """A frame plate: a vertical prism over ``outline_m`` (k, 2), counter-clockwise, from
    ``z0_m`` to ``z1_m``, with a seat for each coil end it holds."""

    side: str
    outline_m: tuple[tuple[float, float], ...]
    z0_m: float
    z1_m: float
    seats: tuple[Seat, ...]

    @property
    def thickness_m(self) -> float:
        return self.z1_m - self.z0_m


@dataclass(frozen=True)
class Assembly:
    """The assembly of a design (see the module docstring), m."""

    types: tuple[CoilType, ...]
    type_of: tuple[int, ...]
    """Each coil's type index."""
    upper: Plate
    lower: Plate
    fixing_xy_m: tuple[tuple[float, float], ...]
    """Standoff axes (vertical) in x, y, m."""
    sensor_holder: str
    """'mount' (a plate per side), 'caps' (one per coil end) or 'none' (free sensors)."""
    sensor_mount_bottom_m: float
    """Underside of the upper sensor mount above the coil tops, m ('mount')."""

    @property
    def standoff_z_m(self) -> tuple[float, float]:
        """Standoff ends: the lower plate's top face and the upper plate's bottom face, m."""
        return (self.lower.z1_m, self.upper.z0_m)

    def type_of_coil(self, k: int) -> CoilType:
        return self.types[self.type_of[k]]

    @property
    def max_tilt_deg(self) -> float:
        return max(s.tilt_deg for s in self.upper.seats + self.lower.seats)


def board_top_m(design: Design) -> float:
    """Top face of an upper Hall-sensor board above its coil's top face, along the axis, m."""
    return design.sensors.offset_m + design.cad.board_thickness_m / 2


def pitch_clearance_m(design: Design) -> float:
    """Smallest spacing - 2 x winding outer radius that leaves a frame web of the minimum
    wall between the flange pockets of neighbouring parallel coils, m."""
    c = design.cad
    return c.min_wall_m + 2 * (c.flange_lip_m + c.pocket_clearance_m)


def max_core_protrusion_m(design: Design) -> float:
    """Highest core top above the winding's top plane under the upper sensor mount, m."""
    c = design.cad
    return design.sensors.offset_m - c.board_thickness_m / 2 - c.mount_floor_m


def _mandrel(design: Design, coil: CoilSpec, core: CoreSpec | None, bore: float) -> str:
    c = design.cad
    if core is None:
        return "printed_tube"
    if c.mandrel == "auto":
        room = coil.inner_radius_m - bore
        return "printed_tube" if room >= c.min_wall_m - TOLERANCE_M else "core"
    return c.mandrel


def _coil_type(design: Design, index: int, coils, where: str, coil: CoilSpec,
               core: CoreSpec | None) -> CoilType:
    c = design.cad
    bore = (coil.inner_radius_m - c.air_core_tube_wall_m if core is None
            else core.radius_m + c.core_clearance_m)
    flange = coil.outer_radius_m + c.flange_lip_m
    up = (c.flange_thickness_m, "top bobbin flange")
    down = (c.flange_thickness_m, "bottom bobbin flange")
    if core is not None:
        top = core.offset_m + core.length_m / 2 - coil.length_m / 2
        bottom = -core.offset_m + core.length_m / 2 - coil.length_m / 2
        up = max(up, (top, "core top"))
        down = max(down, (bottom, "core bottom"))
    return CoilType(index, tuple(coils), where, coil, core, _mandrel(design, coil, core, bore),
                    bore, flange, flange + c.pocket_clearance_m, up, down)


def coil_types(design: Design) -> tuple[tuple[CoilType, ...], tuple[int, ...]]:
    """The coil types in order (the design's own first when any coil uses it, then each
    group), and each coil's type index."""
    grouped = {k: g for g, grp in enumerate(design.groups) for k in grp.coils}
    types, type_of = [], [0] * design.n_coils
    plain = [k for k in range(design.n_coils) if k not in grouped]
    if plain:
        types.append(_coil_type(design, 0, plain, "", design.coil, design.core))
    for g, grp in enumerate(design.groups):
        types.append(_coil_type(design, len(types), grp.coils, f"groups[{g}].", grp.coil,
                                grp.core))
    for t in types:
        for k in t.coils:
            type_of[k] = t.index
    return tuple(types), tuple(type_of)


@functools.lru_cache(maxsize=256)
def coil_axes(design: Design) -> tuple[tuple[tuple[float, float, float],
                                                tuple[float, float, float]], ...]:
    """Each coil's winding centre (m) and unit axis, from :meth:`Design.coil_poses` (once per
    design: the rules read them many times)."""
    return tuple((tuple(map(float, p.position)), tuple(map(float, p.matrix[:, 2])))
                 for p in design.coil_poses())


def seats(design: Design) -> tuple[tuple[Seat, ...], tuple[Seat, ...]]:
    """(top seats, bottom seats), one per coil: face centre and outward axis."""
    top, bottom = [], []
    for k, (centre, axis) in enumerate(coil_axes(design)):
        axis = np.asarray(axis)
        half = design.coil_spec(k).length_m / 2
        c = np.asarray(centre)
        top.append(Seat(k, tuple(map(float, c + half * axis)), tuple(map(float, axis))))
        bottom.append(Seat(k, tuple(map(float, c - half * axis)), tuple(map(float, -axis))))
    return tuple(top), tuple(bottom)


def clip_polygon(subject: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """The intersection of two convex counter-clockwise polygons (k, 2) m (Sutherland-Hodgman);
    (0, 2) when they do not meet."""
    out = np.asarray(subject, dtype=float)
    c = np.asarray(clip, dtype=float)
    for a, b in zip(c, np.roll(c, -1, axis=0)):
        if len(out) == 0:
            break
        e = b - a
        side = e[0] * (out[:, 1] - a[1]) - e[1] * (out[:, 0] - a[0])  # >= 0: inside
        new = []
        for k in range(len(out)):
            p, q, sp, sq = out[k], out[(k + 1) % len(out)], side[k], side[(k + 1) % len(out)]
            if sp >= 0:
                new.append(p)
            if (sp >= 0) != (sq >= 0):
                new.append(p + (q - p) * (sp / (sp - sq)))
        out = np.array(new).reshape(-1, 2)
    return out


def _interior_sines(hull: np.ndarray) -> np.ndarray:
    """sin(alpha / 2) of each interior angle alpha of a counter-clockwise polygon (k, 2)."""
    if len(hull) < 3:
        return np.full(max(len(hull), 1), math.sqrt(0.5))
    prev, nxt = np.roll(hull, 1, axis=0) - hull, np.roll(hull, -1, axis=0) - hull
    cos = np.einsum("ij,ij->i", prev, nxt) / (np.linalg.norm(prev, axis=1)
                                               * np.linalg.norm(nxt, axis=1))
    return np.sqrt(np.clip((1.0 - cos) / 2.0, 0.0, 1.0))


def _edge_margin_m(design: Design, types, type_of, seat_list) -> float:
    """How far a plate reaches beyond its seat centres, m: a wall beyond every pocket (its
    ellipse where a tilted bore meets the plate face) and room for a corner standoff one
    wall from the corner pocket (``sin(alpha / 2)`` of the corner's interior angle)."""
    c = design.cad
    pocket = max(t.pocket_radius_m for t in types)
    ellipse = max(types[type_of[s.coil]].pocket_radius_m / max(abs(s.axis[2]), 1e-6)
                  for s in seat_list)
    xy = np.array([s.centre_m[:2] for s in seat_list])
    hull = grown_hull(xy, 0.0) if len(np.unique(np.round(xy, 12), axis=0)) >= 3 else xy
    corner = float(np.max(_interior_sines(np.asarray(hull))))
    reach = (pocket + c.min_wall_m + c.standoff_outer_radius_m) * corner + c.fixing_inset_m
    return max(ellipse + c.min_wall_m, reach)


def _plate(design: Design, side: str, types, type_of, seat_list, extra_xy) -> Plate:
    """The frame plate holding ``seat_list``: its outline (the layout's footprint, the seats
    grown by the edge margin, ``extra_xy`` points) and its z range."""
    c = design.cad
    e = _edge_margin_m(design, types, type_of, seat_list)
    xy = np.array([s.centre_m[:2] for s in seat_list])
    pts = [design.array.footprint_m(), grown_hull(xy, e)] + (
        [np.asarray(extra_xy)] if len(extra_xy) else [])
    outline = grown_hull(np.vstack(pts), 0.0)
    # the plate's material along each axis: plate_thickness_m beyond the face, at the pocket's
    # rim where the tilt lifts it most
    ends = []
    for s in seat_list:
        a = np.asarray(s.axis)
        rim = types[type_of[s.coil]].pocket_radius_m * math.sqrt(max(0.0, 1.0 - a[2] ** 2))
        ends.append(s.centre_m[2] + c.plate_thickness_m * a[2] + math.copysign(rim, a[2]))
    faces = [s.centre_m[2] for s in seat_list]
    if side == "upper":
        z0, z1 = min(faces), max(ends)
    else:
        z0, z1 = min(ends), max(faces)
    return Plate(side, tuple(map(tuple, outline)), z0, z1, tuple(seat_list))


def pocket_solid(design: Design, t: CoilType, k: int) -> Cylinder:
    """Coil k's flange pocket as a cylinder over its whole bobbin (winding + both flanges), m."""
    centre, axis = coil_axes(design)[k]
    half = t.coil.length_m / 2 + design.cad.flange_thickness_m
    return Cylinder(centre, axis, half, t.pocket_radius_m)


def standoff_solid(design: Design, xy, z_lo: float, z_hi: float) -> Cylinder:
    """A standoff at ``xy`` between the plates (vertical cylinder), m."""
    return Cylinder((float(xy[0]), float(xy[1]), 0.5 * (z_lo + z_hi)), (0.0, 0.0, 1.0),
                    0.5 * abs(z_hi - z_lo), design.cad.standoff_outer_radius_m)


def _fixings(design: Design, types, type_of, outline, z_lo: float, z_hi: float):
    """Standoff positions: the inset outline's corners when each clears every coil's pocket
    by a wall, else the clear ones of its corners and edge midpoints (>= 3), m."""
    c = design.cad
    inset = grown_hull(np.asarray(outline), -c.fixing_inset_m)
    pockets = [pocket_solid(design, types[type_of[k]], k) for k in range(design.n_coils)]

    def clear(p):
        s = standoff_solid(design, p, z_lo, z_hi)
        return all(signed_distance(s, q) >= c.min_wall_m - TOLERANCE_M for q in pockets)

    corners = [tuple(map(float, p)) for p in inset]
    if all(clear(p) for p in corners):
        return tuple(corners)
    mids = [tuple(map(float, 0.5 * (a + b))) for a, b in zip(inset, np.roll(inset, -1, axis=0))]
    ok = [p for p in corners + mids if clear(p)]
    return tuple(ok) if len(ok) >= 3 else tuple(corners)


def _sensor_holder(design: Design) -> str:
    if design.sensors.layout == "free":
        return "none"
    top, bottom = seats(design)
    upright = all(abs(s.axis[2]) >= 1.0 - UPRIGHT_TOLERANCE for s in top)
    level = (np.ptp([s.centre_m[2] for s in top]) <= TOLERANCE_M
             and np.ptp([s.centre_m[2] for s in bottom]) <= TOLERANCE_M)
    return "mount" if upright and level else "caps"


@functools.lru_cache(maxsize=64)
def assembly(design: Design) -> Assembly:
    """The derived geometry of the printed assembly (see :class:`Assembly`), m."""
    types, type_of = coil_types(design)
    top, bottom = seats(design)
    upper = _plate(design, "upper", types, type_of, top, [])
    lower_z1 = max(s.centre_m[2] for s in bottom)
    fixings = _fixings(design, types, type_of, upper.outline_m, lower_z1, upper.z0_m)
    # the lower plate holds the standoffs as far inside its edge as the upper one does: a
    # polygon inscribed in the circle of the inset about each (within any corner it sits in)
    ang = 2 * math.pi * np.arange(FIXING_SIDES) / FIXING_SIDES
    ring = design.cad.fixing_inset_m * np.c_[np.cos(ang), np.sin(ang)]
    grown = [np.asarray(p) + ring for p in fixings]
    lower = _plate(design, "lower", types, type_of, bottom, np.vstack(grown) if grown else [])
    c = design.cad
    return Assembly(types, type_of, upper, lower, fixings, _sensor_holder(design),
                    board_top_m(design) - c.board_thickness_m - c.mount_floor_m)
