"""build123d part functions: each takes one frozen parameter dataclass (mm) and returns a Part.

Nothing here writes files; export is :mod:`cad.export`. Parts that exist once per coil
(bobbin, flange, core, winding) are built in the frame of the coil at the array origin
(winding top face at z = 0, axis = z) and placed by :mod:`cad.assembly`; plates are built in
place in the array frame.
"""

from __future__ import annotations

import math
from typing import Literal

from build123d import Align, Box, Cylinder, Part, Pos, Rot

from designkit.errors import BadInputError

from .params import (BobbinParams, CoreParams, FrameParams, MagnetHolderParams,
                     SensorMountParams, StandoffParams)

_BOTTOM = (Align.CENTER, Align.CENTER, Align.MIN)
_EPS = 1.0
"""Overshoot of cutting tools beyond the faces they open, mm (avoids coplanar booleans)."""


def _cyl(radius: float, z0: float, z1: float, x: float = 0.0, y: float = 0.0) -> Part:
    """Cylinder on the z axis through (x, y) from z0 to z1, mm."""
    return Pos(x, y, z0) * Cylinder(radius, z1 - z0, align=_BOTTOM)


def _box(x0: float, x1: float, y0: float, y1: float, z0: float, z1: float) -> Part:
    return Pos(x0, y0, z0) * Box(x1 - x0, y1 - y0, z1 - z0, align=(Align.MIN,) * 3)


def _flange_ring(p: BobbinParams, inner_radius: float, z0: float) -> Part:
    """Annulus inner_radius..flange radius, thickness t, with the wire slot along +x."""
    t = p.flange_thickness_mm
    ring = _cyl(p.flange_radius_mm, z0, z0 + t) - _cyl(inner_radius, z0 - _EPS, z0 + t + _EPS)
    h = p.slot_width_mm / 2
    return ring - _box(0.0, p.flange_radius_mm + _EPS, -h, h, z0 - _EPS, z0 + t + _EPS)


def slot_area_mm2(inner_radius: float, outer_radius: float, slot_width: float) -> float:
    """Area removed from an annulus by a radial slot of the given width (closed form), mm^2.

    Integral over |y| < w/2 of sqrt(R^2 - y^2) - sqrt(a^2 - y^2), with
    int_{-h}^{h} sqrt(R^2 - y^2) dy = h sqrt(R^2 - h^2) + R^2 asin(h / R).
    """
    h = slot_width / 2

    def chord_integral(r: float) -> float:
        return h * math.sqrt(r * r - h * h) + r * r * math.asin(h / r)

    return chord_integral(outer_radius) - chord_integral(inner_radius)


def bobbin(p: BobbinParams) -> Part:
    """One-piece bobbin: printed tube (bore..winding inner radius) and two slotted flanges.

    Local frame: winding from z = -L to 0; flanges at [0, t] and [-L - t, -L].
    Only for ``p.mandrel == 'printed_tube'`` (a 'core' mandrel has no tube: use
    :func:`bobbin_flange`).
    """
    L, t = p.winding_length_mm, p.flange_thickness_mm
    tube = _cyl(p.winding_inner_radius_mm, -L - t, t) - _cyl(p.bore_radius_mm, -L - t - _EPS, t + _EPS)
    top = _flange_ring(p, p.winding_inner_radius_mm, 0.0)
    bottom = _flange_ring(p, p.winding_inner_radius_mm, -L - t)
    return Part(tube + top + bottom)


def bobbin_volume_mm3(p: BobbinParams) -> float:
    """Closed-form volume of :func:`bobbin`, mm^3."""
    L, t = p.winding_length_mm, p.flange_thickness_mm
    tube = math.pi * (p.winding_inner_radius_mm**2 - p.bore_radius_mm**2) * (L + 2 * t)
    ring = math.pi * (p.flange_radius_mm**2 - p.winding_inner_radius_mm**2) - slot_area_mm2(
        p.winding_inner_radius_mm, p.flange_radius_mm, p.slot_width_mm)
    return tube + 2 * t * ring


def bobbin_flange(p: BobbinParams) -> Part:
    """C-shaped end flange that slides on the core (mandrel 'core'); two per coil.

    Local frame: the top flange of the coil at the origin, z in [0, t]. The bottom one is
    the same part turned over (rotation of 180 degrees about x).
    """
    return Part(_flange_ring(p, p.bore_radius_mm, 0.0))


def bobbin_flange_volume_mm3(p: BobbinParams) -> float:
    """Closed-form volume of :func:`bobbin_flange`, mm^3."""
    return p.flange_thickness_mm * (
        math.pi * (p.flange_radius_mm**2 - p.bore_radius_mm**2)
        - slot_area_mm2(p.bore_radius_mm, p.flange_radius_mm, p.slot_width_mm))


def core(p: CoreParams) -> Part:
    """Steel core cylinder on the coil axis (machined part), array frame of coil (0, 0)."""
    return Part(_cyl(p.radius_mm, p.bottom_z_mm, p.top_z_mm))


def winding(p: BobbinParams) -> Part:
    """The copper winding as a solid annulus (reference for the assembly and the picture)."""
    L = p.winding_length_mm
    return Part(_cyl(p.winding_outer_radius_mm, -L, 0.0)
                - _cyl(p.winding_inner_radius_mm, -L - _EPS, _EPS))


def _turn_over(part: Part, mid_z: float) -> Part:
    """Rotate 180 degrees about the x axis through z = mid_z (upper part -> lower part)."""
    return Pos(0, 0, mid_z) * Rot(180, 0, 0) * Pos(0, 0, -mid_z) * part


def frame_plate(p: FrameParams, side: Literal["upper", "lower"] = "upper") -> Part:
    """Frame plate holding every bobbin by its flange, with four corner fixing holes.

    The upper plate spans z in [0, thickness]: a flange seat (pocket) from the underside at
    each coil, a through hole for the core above it. The lower plate is the same plate
    turned over about the array mid-plane (rows are symmetric in y, so it is also its
    mirror image).
    """
    if side not in ("upper", "lower"):
        raise BadInputError("side", "'upper' or 'lower'", side)
    g, T = p.grid, p.thickness_mm
    plate = _box(-g.footprint_x_mm / 2, g.footprint_x_mm / 2, -g.footprint_y_mm / 2,
                 g.footprint_y_mm / 2, 0.0, T)
    cuts = []
    for x, y in g.centres_xy_mm:
        cuts.append(_cyl(p.pocket_radius_mm, -_EPS, p.pocket_depth_mm, x, y))
        cuts.append(_cyl(p.through_radius_mm, -_EPS, T + _EPS, x, y))
    for x, y in g.fixing_xy_mm:
        cuts.append(_cyl(g.fixing_hole_radius_mm, -_EPS, T + _EPS, x, y))
    plate = Part(plate - Part(children=cuts))
    return plate if side == "upper" else _turn_over(plate, p.mirror_z_mm)


def standoff(p: StandoffParams) -> Part:
    """Spacer tube between the plates (on an M3 rod), local frame z in [-length, 0]."""
    return Part(_cyl(p.outer_radius_mm, -p.length_mm, 0.0)
                - _cyl(p.hole_radius_mm, -p.length_mm - _EPS, _EPS))


def standoff_volume_mm3(p: StandoffParams) -> float:
    return math.pi * (p.outer_radius_mm**2 - p.hole_radius_mm**2) * p.length_mm


def sensor_mount(p: SensorMountParams, side: Literal["upper", "lower"] = "upper") -> Part:
    """Board mount of one Hall-sensor array, in place in the array frame.

    Upper: a plate whose top face is at sensor_z + board/2, a board pocket centred on each
    coil axis (the board's mid-plane is the sensing plane), one cable channel per row
    running to the +x edge, and four legs standing on the upper frame plate at the fixing
    holes (the M3 rods pass through them). Lower: the same part turned over.
    """
    if side not in ("upper", "lower"):
        raise BadInputError("side", "'upper' or 'lower'", side)
    g = p.grid
    top, bottom = p.top_z_mm, p.bottom_z_mm
    hx, hy = g.footprint_x_mm / 2, g.footprint_y_mm / 2
    body = _box(-hx, hx, -hy, hy, bottom, top)
    legs = [_cyl(p.leg_outer_radius_mm, p.leg_bottom_z_mm, bottom + _EPS, x, y)
            for x, y in g.fixing_xy_mm] if bottom > p.leg_bottom_z_mm else []
    if legs:
        body = body + Part(children=legs)
    floor = top - p.board_thickness_mm
    bx = p.board_size_mm[0] / 2 + p.pocket_clearance_mm
    by = p.board_size_mm[1] / 2 + p.pocket_clearance_mm
    cuts = [_box(x - bx, x + bx, y - by, y + by, floor, top + _EPS) for x, y in g.centres_xy_mm]
    w = p.channel_width_mm / 2
    for y in sorted({round(c[1], 9) for c in g.centres_xy_mm}):
        x_first = min(c[0] for c in g.centres_xy_mm if round(c[1], 9) == y)
        cuts.append(_box(x_first, hx + _EPS, y - w, y + w, floor, top + _EPS))
    cuts += [_cyl(g.fixing_hole_radius_mm, p.leg_bottom_z_mm - _EPS, top + _EPS, x, y)
             for x, y in g.fixing_xy_mm]
    mount = Part(body - Part(children=cuts))
    return mount if side == "upper" else _turn_over(mount, p.mirror_z_mm)


def magnet_holder(p: MagnetHolderParams) -> Part:
    """Finger ring (axis x) with a boss below it holding the magnet in a press-fit pocket.

    Local frame: finger axis = x axis; the pocket opens at the boss' bottom face,
    z = magnet_centre_z - length/2, and ends floor_thickness below the finger.
    """
    ri = p.finger_diameter_mm / 2
    ro = ri + p.ring_wall_mm
    half_w = p.ring_width_mm / 2
    ring = Rot(0, 90, 0) * Cylinder(ro, p.ring_width_mm)
    pocket_top = -(ri + p.floor_thickness_mm)
    boss_bottom = pocket_top - p.pocket_depth_mm
    boss = _cyl(p.boss_radius_mm, boss_bottom, 0.0)
    finger = Rot(0, 90, 0) * Cylinder(ri, 2 * (half_w + _EPS))
    pocket = _cyl(p.pocket_radius_mm, boss_bottom - _EPS, pocket_top)
    return Part(ring + boss - finger - pocket)


def magnet(p: MagnetHolderParams) -> Part:
    """The N52 magnet itself (bought part), in the holder's local frame."""
    zc = p.magnet_centre_z_mm
    return Part(_cyl(p.magnet_radius_mm, zc - p.magnet_length_mm / 2, zc + p.magnet_length_mm / 2))
