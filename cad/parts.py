"""build123d part functions: each takes one frozen parameter dataclass (mm) and returns a Part.

Nothing here writes files; export is :mod:`cad.export`. Parts that exist once per coil
(bobbin, flange, core, winding, sensor cap) are built in the frame of a coil end (its face at
z = 0, axis = z) and placed by :mod:`cad.assembly`; plates are built in place in the array
frame.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from build123d import (Align, Box, BuildPart, BuildSketch, Cylinder, Location, Part, Plane,
                       Polygon, Pos, Rot, extrude, mirror)

from designkit.errors import BadInputError

from .params import (BobbinParams, CoreParams, MagnetHolderParams, PlateParams,
                     SensorCapParams, SensorMountParams, StandoffParams, segment_outline)

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


def _prism(outline, z0: float, z1: float) -> Part:
    """Vertical prism over a counter-clockwise polygon (k, 2) mm from z0 to z1."""
    with BuildPart() as prism:
        with BuildSketch(Plane.XY.offset(z0)):
            Polygon(*[(float(x), float(y)) for x, y in outline], align=None)
        extrude(amount=z1 - z0)
    return prism.part


def _in_frame(part: Part, centre, rotation) -> Part:
    """``part`` built in a local frame, moved to ``centre`` (mm) with ``rotation`` (3 x 3,
    columns: the local axes in the array frame)."""
    r = np.asarray(rotation, dtype=float)
    plane = Plane(origin=tuple(map(float, centre)), x_dir=tuple(r[:, 0]), z_dir=tuple(r[:, 2]))
    return Location(plane) * part


def _seat_cuts(p: PlateParams) -> list[Part]:
    """The flange pocket (from beyond the coil to the flange's outer face) and the bore of every
    seat, along its axis; long enough to leave the plate whatever the tilt."""
    reach = 3.0 * (p.thickness_mm + max(s.pocket_radius_mm for s in p.seats)) + _EPS
    cuts = []
    for s in p.seats:
        cuts.append(_in_frame(_cyl(s.pocket_radius_mm, -reach, s.pocket_depth_mm),
                              s.centre_mm, s.rotation))
        cuts.append(_in_frame(_cyl(s.through_radius_mm, -reach, reach), s.centre_mm, s.rotation))
    return cuts


def frame_plate(p: PlateParams, segment: int | None = None) -> Part:
    """Frame plate holding every coil end by its flange, in place in the array frame.

    A prism over the outline from z0 to z1 with, for each seat, a flange pocket from the coil
    side (a seat's depth along its axis) and a bore beyond it, and a vertical fixing hole at
    each standoff. The upper plate is printed turned over and the lower one as it stands, so
    the pockets open upwards and a tilted bore overhangs by its coil's tilt.
    ``segment``: the piece of a plate printed in segments (:attr:`PlateParams.segments`).
    """
    outline = np.asarray(p.outline_mm, dtype=float)
    if segment is not None:
        outline = segment_outline(outline, p.centre_xy_mm, p.segments[segment])
    plate = _prism(outline, p.z0_mm, p.z1_mm)
    cuts = _seat_cuts(p)
    cuts += [_cyl(p.fixing_hole_radius_mm, p.z0_mm - _EPS, p.z1_mm + _EPS, x, y)
             for x, y in p.fixing_xy_mm]
    return Part(plate - Part(children=cuts))


def standoff(p: StandoffParams) -> Part:
    """Spacer tube between the plates (on an M3 rod), local frame z in [-length, 0]."""
    return Part(_cyl(p.outer_radius_mm, -p.length_mm, 0.0)
                - _cyl(p.hole_radius_mm, -p.length_mm - _EPS, _EPS))


def standoff_volume_mm3(p: StandoffParams) -> float:
    return math.pi * (p.outer_radius_mm**2 - p.hole_radius_mm**2) * p.length_mm


def sensor_mount(p: SensorMountParams, side: Literal["upper", "lower"] = "upper",
                 segment: int | None = None) -> Part:
    """Board mount of one Hall-sensor array of level boards, in place in the array frame.

    Upper: a plate over the frame's outline whose top face is at sensor_z + board/2, a board
    pocket centred on each coil axis (the board's mid-plane is the sensing plane), a cable
    channel from each pocket to the +x edge, and legs standing on the upper frame plate at the
    fixing holes (the M3 rods pass through them). Lower: its mirror image about the array's
    mid-plane. ``segment``: the piece of a mount printed in segments (:attr:`segments`).
    """
    if side not in ("upper", "lower"):
        raise BadInputError("side", "'upper' or 'lower'", side)
    top, bottom = p.top_z_mm, p.bottom_z_mm
    body = _prism(p.outline_mm, bottom, top)
    legs = [_cyl(p.leg_outer_radius_mm, p.leg_bottom_z_mm, bottom + _EPS, x, y)
            for x, y in p.fixing_xy_mm] if bottom > p.leg_bottom_z_mm else []
    if legs:
        body = body + Part(children=legs)
    floor = top - p.board_thickness_mm
    bx = p.board_size_mm[0] / 2 + p.pocket_clearance_mm
    by = p.board_size_mm[1] / 2 + p.pocket_clearance_mm
    edge = max(x for x, _ in p.outline_mm)
    w = p.channel_width_mm / 2
    cuts = [_box(x - bx, x + bx, y - by, y + by, floor, top + _EPS) for x, y in p.board_xy_mm]
    cuts += [_box(x, edge + _EPS, y - w, y + w, floor, top + _EPS) for x, y in p.board_xy_mm]
    cuts += [_cyl(p.fixing_hole_radius_mm, p.leg_bottom_z_mm - _EPS, top + _EPS, x, y)
             for x, y in p.fixing_xy_mm]
    mount = Part(body - Part(children=cuts))
    if segment is not None:  # the wedge of the segment, legs and channels included
        piece = segment_outline(p.outline_mm, p.centre_xy_mm, p.segments[segment])
        mount = Part(mount & _prism(piece, p.leg_bottom_z_mm - _EPS, top + _EPS))
    if side == "upper":
        return mount
    return Part(mirror(mount, Plane.XY.offset(p.mirror_z_mm)))


def sensor_cap(p: SensorCapParams) -> Part:
    """A sensor board's cap on a coil end, local frame: z from 0 (the face it rests on) to the
    board's outer face at ``height_mm``; the board pocket there and a cable channel along +x to
    the rim. Printed standing on its base; pressed into the frame plate's bore."""
    h = p.height_mm
    bx = p.board_size_mm[0] / 2 + p.pocket_clearance_mm
    by = p.board_size_mm[1] / 2 + p.pocket_clearance_mm
    floor = h - p.board_thickness_mm
    w = p.channel_width_mm / 2
    cuts = [_box(-bx, bx, -by, by, floor, h + _EPS),
            _box(0.0, p.radius_mm + _EPS, -w, w, floor, h + _EPS)]
    return Part(_cyl(p.radius_mm, 0.0, h) - Part(children=cuts))


def sensor_cap_volume_mm3(p: SensorCapParams) -> float:
    """Closed-form volume of :func:`sensor_cap`: the cylinder less the board pocket and the
    channel's part beyond the pocket (a rectangle cut by the rim circle), mm^3."""
    bx = p.board_size_mm[0] / 2 + p.pocket_clearance_mm
    by = p.board_size_mm[1] / 2 + p.pocket_clearance_mm
    r, w = p.radius_mm, p.channel_width_mm / 2

    def area_x_from(x0):  # area of {x >= x0, |y| <= w} inside the circle of radius r
        def f(y):
            return y * math.sqrt(r * r - y * y) / 2 + r * r * math.asin(y / r) / 2
        return 2 * (f(w) - x0 * w)

    removed = 4 * bx * by + area_x_from(bx)
    return p.board_thickness_mm * (-removed) + math.pi * r * r * p.height_mm


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
