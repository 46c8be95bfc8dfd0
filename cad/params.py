"""Frozen parameter dataclasses of every part, and the one SI (m) -> mm conversion.

:func:`from_design` (with the per-part helpers it calls) is the only place where the
design's metres become millimetres; every part function takes one of the dataclasses below
and nothing else. Values the thesis does not give (fits, wall thicknesses, board size, finger
diameter) are printing choices, stated in the field docs and overridable through
:func:`from_design`'s keyword arguments.

Frame: the design's array frame in mm (z up; the top faces of an upright array at z = 0).
Parts that exist once per coil (bobbin, core, winding, caps) are parameters of its coil type
(:class:`CoilTypeParts`) and are placed in each coil's frame.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from designkit.design import Design, pose_on_axis
from designkit.errors import BadInputError
from designkit.rules import Assembly, CoilType, Plate, assembly, clip_polygon


MM_PER_M = 1000.0
"""The one unit factor of cad/: millimetres per metre."""

Mandrel = Literal["auto", "printed_tube", "core"]


@dataclass(frozen=True)
class PrinterParams:
    """The FDM printer and the tessellation used for exported meshes."""

    build_volume_mm: tuple[float, float, float] = (230.0, 190.0, 200.0)
    """Usable build volume x, y, z, mm (Ultimaker-class default)."""
    tolerance_mm: float = 0.02
    """Linear deflection of the tessellation (max chord-to-surface distance), mm."""
    angular_tolerance_rad: float = 0.2
    flow_mm3_per_s: float = 4.0
    """Print-time proxy: volumetric rate of a 0.4 mm nozzle at 0.2 mm layers and 50 mm/s,
    mm^3/s, applied to the solid volume (100 % infill: an upper bound on time)."""
    density_g_cm3: tuple[tuple[str, float], ...] = (
        ("PLA", 1.24), ("steel", 7.85), ("copper", 8.96), ("NdFeB", 7.5))
    """Density of each part material, g/cm^3 (copper: the winding as solid copper, an upper
    bound; NdFeB: sintered N52 datasheet value)."""


def fit_in_build_volume(size_mm: tuple[float, float, float],
                        build_mm: tuple[float, float, float]) -> tuple[int, int, int] | None:
    """An axis order that fits the part's box in the build volume, or None.

    Parts may be laid down in any of the 6 axis-aligned orientations; rotations about z
    by other angles are not tried (conservative).

    Returns
    -------
    tuple of int or None
        ``order`` such that ``size_mm[order[k]] <= build_mm[k]`` for k = 0, 1, 2.
    """
    for order in itertools.permutations(range(3)):
        if all(size_mm[order[k]] <= build_mm[k] for k in range(3)):
            return order
    return None


@dataclass(frozen=True)
class BobbinParams:
    """Bobbin of one winding; local frame = array frame of the coil at (0, 0).

    The winding occupies ``winding_inner_radius_mm <= r <= winding_outer_radius_mm`` and
    ``-winding_length_mm <= z <= 0``; the flanges sit just outside it.
    """

    bore_radius_mm: float
    """Radius of the hole the core slides through: core radius + clearance, mm."""
    winding_inner_radius_mm: float
    winding_outer_radius_mm: float
    winding_length_mm: float
    flange_thickness_mm: float
    flange_radius_mm: float
    """Winding outer radius + a lip that keeps the outer layer on the bobbin, mm."""
    slot_width_mm: float
    """Width of the radial wire-exit slot through each flange, mm."""
    mandrel: Literal["printed_tube", "core"]
    """'printed_tube': a printed tube between bore and winding carries the winding (one part
    with both flanges). 'core': the winding is wound on the (insulated) core itself, as the
    design's core radius = winding inner radius implies; the bobbin is then two identical
    C-shaped end flanges (part ``bobbin_flange``) that slide onto the core."""

    @property
    def tube_wall_mm(self) -> float:
        """Radial wall of the printed tube (negative: the core leaves no room), mm."""
        return self.winding_inner_radius_mm - self.bore_radius_mm


@dataclass(frozen=True)
class CoreParams:
    """Low-carbon steel core, a plain cylinder (machined, not printed)."""

    radius_mm: float
    length_mm: float
    centre_z_mm: float
    """Axial position of the core centre in the array frame, mm."""

    @property
    def top_z_mm(self) -> float:
        return self.centre_z_mm + self.length_mm / 2

    @property
    def bottom_z_mm(self) -> float:
        return self.centre_z_mm - self.length_mm / 2


@dataclass(frozen=True)
class SeatParams:
    """A coil end held by a frame plate: its face centre (mm) and its frame (columns: local
    x, y, z in the array frame; local z = the outward axis), with the pocket and bore."""

    coil: int
    centre_mm: tuple[float, float, float]
    rotation: tuple[tuple[float, float, float], ...]
    pocket_radius_mm: float
    """Flange seat: flange radius + fit clearance, mm."""
    pocket_depth_mm: float
    """= flange thickness, from the face outwards, mm."""
    through_radius_mm: float
    """Hole beyond the pocket through which the core passes (= bobbin bore), mm."""


@dataclass(frozen=True)
class PlateParams:
    """A frame plate: a vertical prism over ``outline_mm`` (counter-clockwise) from ``z0_mm`` to
    ``z1_mm``, a pocket and bore along each seat's axis, a vertical hole at each fixing. A
    plate larger than the printer is printed in ``segments``: wedges about ``centre_xy_mm``
    between consecutive fixings (the standoffs' rods clamp the seams)."""

    side: Literal["upper", "lower"]
    outline_mm: tuple[tuple[float, float], ...]
    z0_mm: float
    z1_mm: float
    seats: tuple[SeatParams, ...]
    fixing_xy_mm: tuple[tuple[float, float], ...]
    fixing_hole_radius_mm: float
    segments: tuple[tuple[float, float], ...] = ()
    """Angle ranges (rad) of the printed pieces about ``centre_xy_mm``; empty: one piece."""
    centre_xy_mm: tuple[float, float] = (0.0, 0.0)
    segments_identical: bool = False
    """Every segment is the first one turned about ``centre_xy_mm`` (one part, printed n
    times)."""

    @property
    def thickness_mm(self) -> float:
        return self.z1_mm - self.z0_mm


@dataclass(frozen=True)
class StandoffParams:
    """Spacer tube between the two frame plates, on an M3 rod at each fixing."""

    outer_radius_mm: float
    hole_radius_mm: float
    length_mm: float
    """From the lower plate's top face to the upper plate's bottom face, mm."""


@dataclass(frozen=True)
class SensorMountParams:
    """Board mount of the upper Hall-sensor array of level, upright boards (the lower one is
    its mirror image about ``mirror_z_mm``)."""

    outline_mm: tuple[tuple[float, float], ...]
    board_xy_mm: tuple[tuple[float, float], ...]
    """Board centres (the coil axes), mm."""
    sensor_z_mm: float
    """Height of the sensing plane (board mid-plane), mm."""
    board_size_mm: tuple[float, float]
    """Sensor breakout board, x by y, mm (assumed 12 x 12: a TSOP-6 TLV493D on a small PCB)."""
    board_thickness_mm: float
    pocket_clearance_mm: float
    floor_thickness_mm: float
    channel_width_mm: float
    """Cable channel from each pocket to the +x edge, as deep as the pocket, mm."""
    leg_outer_radius_mm: float
    leg_bottom_z_mm: float
    """Top face of the upper frame plate, on which the mount's legs stand, mm."""
    fixing_xy_mm: tuple[tuple[float, float], ...]
    fixing_hole_radius_mm: float
    mirror_z_mm: float
    segments: tuple[tuple[float, float], ...] = ()
    """As :attr:`PlateParams.segments`: a mount larger than the printer is printed in wedges."""
    centre_xy_mm: tuple[float, float] = (0.0, 0.0)
    segments_identical: bool = False

    @property
    def top_z_mm(self) -> float:
        return self.sensor_z_mm + self.board_thickness_mm / 2

    @property
    def bottom_z_mm(self) -> float:
        return self.top_z_mm - self.board_thickness_mm - self.floor_thickness_mm


@dataclass(frozen=True)
class SensorCapParams:
    """A sensor board's cap on one coil end, in the end's frame: from z = 0 (resting on the core
    end or the bobbin) to ``height_mm`` outwards along the axis, pressed into the frame plate's
    bore; the board pocket at its outer face, a cable channel to its rim along local +x."""

    radius_mm: float
    """The bore's radius less the press-fit clearance, mm."""
    height_mm: float
    board_size_mm: tuple[float, float]
    board_thickness_mm: float
    pocket_clearance_mm: float
    channel_width_mm: float


@dataclass(frozen=True)
class CoilTypeParts:
    """The parts of one coil type (coils sharing a winding and core), mm."""

    suffix: str
    """Appended to its part names: '' for a single type, '_t1', '_t2', ... otherwise."""
    coils: tuple[int, ...]
    bobbin: BobbinParams
    core: CoreParams | None
    cap_upper: SensorCapParams | None
    cap_lower: SensorCapParams | None
    reach_upper_mm: float
    """Where the upper cap rests: the core top or the top flange above the winding, mm."""
    reach_lower_mm: float


@dataclass(frozen=True)
class MagnetHolderParams:
    """Finger-splint magnet holder: a ring around the finger with a boss holding the magnet.

    Local frame: finger (ring) axis along x through the origin; magnet axis along z,
    pocket opening downwards (towards the coils) below the finger.
    """

    magnet_radius_mm: float
    magnet_length_mm: float
    press_fit_clearance_mm: float
    """Radial pocket oversize, mm. FDM holes print ~0.1 mm undersize, so a nominal +0.05
    gives a press fit (assumed; tune per printer)."""
    finger_diameter_mm: float
    """Inner diameter of the ring (assumed 18 mm: an adult index fingertip)."""
    ring_wall_mm: float
    ring_width_mm: float
    boss_wall_mm: float
    floor_thickness_mm: float
    """Plastic between the magnet's top face and the finger, mm."""

    @property
    def pocket_radius_mm(self) -> float:
        return self.magnet_radius_mm + self.press_fit_clearance_mm

    @property
    def pocket_depth_mm(self) -> float:
        return self.magnet_length_mm

    @property
    def boss_radius_mm(self) -> float:
        return self.pocket_radius_mm + self.boss_wall_mm

    @property
    def magnet_centre_z_mm(self) -> float:
        """z of the magnet's centre in the holder's local frame, mm."""
        return -(self.finger_diameter_mm / 2 + self.floor_thickness_mm + self.magnet_length_mm / 2)


@dataclass(frozen=True)
class CadParams:
    """Everything cad/ builds, derived from one design (mm)."""

    design_name: str
    types: tuple[CoilTypeParts, ...]
    coil_type: tuple[int, ...]
    """Each coil's index into ``types``."""
    coil_frames: tuple[tuple[tuple[float, float, float], tuple], ...]
    """Each coil's top-face centre (mm) and frame (3 x 3, columns local x, y, z = axis)."""
    upper: PlateParams
    lower: PlateParams
    standoff: StandoffParams
    standoff_top_z_mm: float
    """The upper plate's bottom face, where each standoff ends, mm."""
    sensor_holder: Literal["mount", "caps", "none"]
    sensor_mount: SensorMountParams | None
    magnet_holder: MagnetHolderParams
    printer: PrinterParams
    magnet_centre_mm: tuple[float, float, float]
    """Where the assembly puts the magnet: the design point, mm."""
    design: Design
    """The design with every override applied: what the rule book checks."""

    @property
    def bobbin(self) -> BobbinParams:
        """The first coil type's bobbin (the only one of a design without groups)."""
        return self.types[0].bobbin

    @property
    def core(self) -> CoreParams | None:
        return self.types[0].core

    @property
    def fixing_xy_mm(self) -> tuple[tuple[float, float], ...]:
        return self.upper.fixing_xy_mm


_OVERRIDES_MM = ("min_wall", "core_clearance", "air_core_tube_wall", "flange_thickness",
                 "flange_lip", "pocket_clearance", "plate_thickness", "fixing_inset",
                 "fixing_hole_radius", "standoff_outer_radius", "board_width", "board_thickness",
                 "board_clearance", "mount_floor", "channel_width", "press_fit_clearance",
                 "finger_diameter", "ring_wall", "ring_width", "boss_wall", "holder_floor")
"""Keyword arguments ``<name>_mm`` of :func:`from_design`: the design's ``cad.<name>_m`` in mm."""


def with_overrides(design: Design, mandrel: str | None = None, **overrides_mm) -> Design:
    """The design with ``cad`` keys replaced by printing choices given in mm (None: keep)."""
    changes = {} if mandrel is None else {"cad.mandrel": mandrel}
    for key, value in overrides_mm.items():
        name = key.removesuffix("_mm")
        if not key.endswith("_mm") or name not in _OVERRIDES_MM:
            raise BadInputError("cad option", f"one of {[n + '_mm' for n in _OVERRIDES_MM]}", key)
        if value is not None:
            if not math.isfinite(float(value)):
                raise BadInputError(key, "a finite number (mm)", value)
            changes[f"cad.{name}_m"] = float(value) / MM_PER_M
    return design.replace(**changes) if changes else design


def from_design(design: Design, *, mandrel: Mandrel | None = None,
                printer: PrinterParams | None = None, **overrides_mm) -> CadParams:
    """Convert a design (SI, m) into the parameters of every part (mm).

    This (with the rule book's :func:`designkit.rules.layout`) is the only code in cad/ that
    reads metres. ``mandrel`` and ``<name>_mm`` keyword arguments override the design's
    ``cad`` keys (:func:`with_overrides`); they are not range-checked here beyond being finite
    numbers, because :func:`cad.rules.check_rules` reports every violated rule with the fix.

    Parameters
    ----------
    design : Design
        The device; its coil, core, array, sensors, magnet, cad and optimize.height_m are used.
    mandrel : {'auto', 'printed_tube', 'core'}, optional
        What carries the winding (default: ``cad.mandrel``). 'auto' prints a tube when the
        radial room between the core (plus clearance) and the winding's inner radius is at
        least the printer's minimum wall, else winds on the core (see
        :attr:`BobbinParams.mandrel`).

    Returns
    -------
    CadParams
    """
    if mandrel is not None and mandrel not in ("auto", "printed_tube", "core"):
        raise BadInputError("mandrel", "one of 'auto', 'printed_tube', 'core'", mandrel)
    if mandrel == "core" and design.core is None:
        raise BadInputError("mandrel", "'auto' or 'printed_tube' for a design without a core",
                            mandrel, "An air-core coil needs a printed tube to wind on.")
    design = with_overrides(design, mandrel, **overrides_mm)
    printer = printer or PrinterParams()
    g = assembly(design)
    c, mm = design.cad, MM_PER_M
    types = tuple(_type_parts(design, g, t) for t in g.types)
    frames = tuple((tuple(float(q) * mm for q in s.centre_m), _frame(s.axis))
                   for s in g.upper.seats)
    upper, lower = (_plate(design, g, plate, printer) for plate in (g.upper, g.lower))
    z_lo, z_hi = g.standoff_z_m
    standoff = StandoffParams(outer_radius_mm=c.standoff_outer_radius_m * mm,
                              hole_radius_mm=c.fixing_hole_radius_m * mm,
                              length_mm=(z_hi - z_lo) * mm)
    mount = _mount(design, g, printer) if g.sensor_holder == "mount" else None
    holder = MagnetHolderParams(
        magnet_radius_mm=design.magnet.radius_m * mm, magnet_length_mm=design.magnet.length_m * mm,
        press_fit_clearance_mm=c.press_fit_clearance_m * mm,
        finger_diameter_mm=c.finger_diameter_m * mm, ring_wall_mm=c.ring_wall_m * mm,
        ring_width_mm=c.ring_width_m * mm, boss_wall_mm=c.boss_wall_m * mm,
        floor_thickness_mm=c.holder_floor_m * mm)
    magnet_centre = tuple(float(q) * mm for q in design.design_point_m)
    return CadParams(design_name=design.name, types=types, coil_type=g.type_of,
                     coil_frames=frames, upper=upper, lower=lower, standoff=standoff,
                     standoff_top_z_mm=z_hi * mm, sensor_holder=g.sensor_holder,
                     sensor_mount=mount, magnet_holder=holder, printer=printer,
                     magnet_centre_mm=magnet_centre, design=design)


def _frame(axis) -> tuple:
    """The frame (3 x 3 nested tuples) whose local z is ``axis``: the identity when upright
    (:func:`designkit.design.pose_on_axis`)."""
    return tuple(map(tuple, pose_on_axis((0.0, 0.0, 0.0), axis).matrix))


def _type_parts(design: Design, g: Assembly, t: CoilType) -> CoilTypeParts:
    """The bobbin, core and sensor caps of one coil type, mm."""
    mm, c = MM_PER_M, design.cad
    bobbin, core_p = _bobbin_and_core(design, t)
    caps = [None, None]
    if g.sensor_holder == "caps":
        top = design.sensors.offset_m + c.board_thickness_m / 2
        caps = [SensorCapParams(radius_mm=(t.bore_radius_m - c.press_fit_clearance_m) * mm,
                                height_mm=(top - reach[0]) * mm,
                                board_size_mm=(c.board_width_m * mm, c.board_width_m * mm),
                                board_thickness_mm=c.board_thickness_m * mm,
                                pocket_clearance_mm=c.board_clearance_m * mm,
                                channel_width_mm=c.channel_width_m * mm)
                for reach in (t.reach_upper_m, t.reach_lower_m)]
    return CoilTypeParts(suffix="" if len(g.types) == 1 else f"_t{t.index + 1}", coils=t.coils,
                         bobbin=bobbin, core=core_p, cap_upper=caps[0], cap_lower=caps[1],
                         reach_upper_mm=t.reach_upper_m[0] * mm,
                         reach_lower_mm=t.reach_lower_m[0] * mm)


def _plate(design: Design, g: Assembly, plate: Plate, printer: PrinterParams) -> PlateParams:
    """A frame plate in mm, split into segments when it fits the printer in no orientation."""
    mm, c = MM_PER_M, design.cad
    seats = tuple(SeatParams(
        coil=s.coil, centre_mm=tuple(float(q) * mm for q in s.centre_m), rotation=_frame(s.axis),
        pocket_radius_mm=g.type_of_coil(s.coil).pocket_radius_m * mm,
        pocket_depth_mm=c.flange_thickness_m * mm,
        through_radius_mm=g.type_of_coil(s.coil).bore_radius_m * mm) for s in plate.seats)
    outline = np.asarray(plate.outline_m) * mm
    fixings = tuple((x * mm, y * mm) for x, y in g.fixing_xy_m)
    poses = [tuple(s.centre_mm) + tuple(np.asarray(s.rotation)[:, 2]) for s in seats]
    segments, centre, identical = _segmentation(outline, (plate.z1_m - plate.z0_m) * mm,
                                                fixings, poses, printer)
    return PlateParams(side=plate.side, outline_mm=tuple(map(tuple, outline)),
                       z0_mm=plate.z0_m * mm, z1_mm=plate.z1_m * mm, seats=seats,
                       fixing_xy_mm=fixings, fixing_hole_radius_mm=c.fixing_hole_radius_m * mm,
                       segments=segments, centre_xy_mm=centre, segments_identical=identical)


def _segmentation(outline: np.ndarray, thickness_mm: float, fixings, poses,
                  printer: PrinterParams) -> tuple[tuple, tuple[float, float], bool]:
    """(segments, centre, identical) of a plate over ``outline`` (k, 2) mm: no segments when it
    fits the printer, else wedges about its centre between consecutive ``fixings`` when each
    of them fits (identical: each is the first turned, with the plate's ``poses``: rows of
    position and axis, mm)."""
    size = (float(np.ptp(outline[:, 0])), float(np.ptp(outline[:, 1])), thickness_mm)
    centre = tuple(float(q) for q in outline.mean(axis=0))
    segments: tuple = ()
    if fit_in_build_volume(size, printer.build_volume_mm) is None and len(fixings) >= 3:
        ang = sorted(math.atan2(y - centre[1], x - centre[0]) for x, y in fixings)
        pieces = tuple((a, b if b > a else b + 2 * math.pi)
                       for a, b in zip(ang, ang[1:] + ang[:1]))
        if all(fit_in_build_volume(_segment_size(outline, centre, a, thickness_mm),
                                   printer.build_volume_mm) is not None for a in pieces):
            segments = pieces
    identical = bool(segments) and all(
        _turned_onto_itself(outline, poses, fixings, centre, a - segments[0][0])
        for a, _ in segments)
    return segments, centre, identical


def segment_outline(outline, centre_xy, angles) -> np.ndarray:
    """The part of a plate's outline (k, 2) mm in the wedge of ``angles`` (rad, < pi) about
    ``centre_xy``: a printed segment of the plate."""
    o = np.asarray(outline, dtype=float)
    a0, a1 = angles
    r = 2.0 * float(np.max(np.linalg.norm(o - centre_xy, axis=1))) / math.cos((a1 - a0) / 2)
    cx, cy = centre_xy
    wedge = np.array([(cx, cy), (cx + r * math.cos(a0), cy + r * math.sin(a0)),
                      (cx + r * math.cos(a1), cy + r * math.sin(a1))])
    return clip_polygon(o, wedge)


def _segment_size(outline, centre_xy, angles, thickness_mm: float):
    piece = segment_outline(outline, centre_xy, angles)
    return (float(np.ptp(piece[:, 0])), float(np.ptp(piece[:, 1])), thickness_mm)


def turn_about(centre_xy, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """(rotation (3, 3), offset (3,) mm) of a turn by ``angle`` (rad) about the vertical axis
    through ``centre_xy`` (mm): p -> R p + offset."""
    c, s = math.cos(angle), math.sin(angle)
    r = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    centre = np.r_[np.asarray(centre_xy, dtype=float), 0.0]
    return r, centre - r @ centre


def _turned_onto_itself(outline, poses, fixings, centre, angle: float) -> bool:
    """Whether a turn by ``angle`` about ``centre`` maps the plate's outline, poses (rows of
    position and axis) and fixings onto themselves (to 1e-6 mm)."""
    r, off = turn_about(centre, angle)

    def key(rows):
        return set(map(tuple, np.round(np.asarray(rows, dtype=float), 6) + 0.0))

    def turned(rows):
        rows = np.asarray(rows, dtype=float)
        return rows @ r[:rows.shape[1], :rows.shape[1]].T + off[:rows.shape[1]]

    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    poses_t = np.c_[poses[:, :3] @ r.T + off, poses[:, 3:] @ r.T]
    return (key(turned(outline)) == key(outline) and key(turned(fixings)) == key(fixings)
            and key(poses_t) == key(poses))


def _mount(design: Design, g: Assembly, printer: PrinterParams) -> SensorMountParams:
    """The sensor mount plate of level, upright boards, mm (in segments like a frame plate
    when it is larger than the printer)."""
    mm, c = MM_PER_M, design.cad
    top = max(s.centre_m[2] for s in g.upper.seats)
    bottom = max(s.centre_m[2] for s in g.lower.seats)
    outline = np.asarray(g.upper.outline_m) * mm
    boards = tuple((s.centre_m[0] * mm, s.centre_m[1] * mm) for s in g.upper.seats)
    fixings = tuple((x * mm, y * mm) for x, y in g.fixing_xy_m)
    thickness = (c.board_thickness_m + c.mount_floor_m) * mm
    segments, centre, identical = _segmentation(outline, thickness, fixings,
                                                [(x, y, 0.0, 0.0, 0.0, 1.0) for x, y in boards],
                                                printer)
    return SensorMountParams(
        outline_mm=tuple(map(tuple, outline)), board_xy_mm=boards,
        sensor_z_mm=(top + design.sensors.offset_m) * mm,
        board_size_mm=(c.board_width_m * mm, c.board_width_m * mm),
        board_thickness_mm=c.board_thickness_m * mm,
        pocket_clearance_mm=c.board_clearance_m * mm, floor_thickness_mm=c.mount_floor_m * mm,
        channel_width_mm=c.channel_width_m * mm, leg_outer_radius_mm=c.standoff_outer_radius_m * mm,
        leg_bottom_z_mm=g.upper.z1_m * mm, fixing_xy_mm=fixings,
        fixing_hole_radius_mm=c.fixing_hole_radius_m * mm, mirror_z_mm=(top + bottom) / 2 * mm,
        segments=segments, centre_xy_mm=centre, segments_identical=identical)


def _bobbin_and_core(design: Design, g: CoilType) -> tuple[BobbinParams, CoreParams | None]:
    """The bobbin (with the rule book's mandrel) and the core, mm, from the design."""
    mm = MM_PER_M
    coil, core = g.coil, g.core
    length = coil.length_m * mm
    core_p = None
    if core is not None:
        core_p = CoreParams(radius_mm=core.radius_m * mm, length_mm=core.length_m * mm,
                            centre_z_mm=-length / 2 + core.offset_m * mm)
    bobbin = BobbinParams(
        bore_radius_mm=g.bore_radius_m * mm, winding_inner_radius_mm=coil.inner_radius_m * mm,
        winding_outer_radius_mm=coil.outer_radius_m * mm, winding_length_mm=length,
        flange_thickness_mm=design.cad.flange_thickness_m * mm,
        flange_radius_mm=g.flange_radius_m * mm,
        # two wire diameters side by side (lead in and out) plus a printing allowance
        slot_width_mm=2 * design.wire.insulated_diameter_m * mm + 0.4,
        mandrel=g.mandrel,
    )
    return bobbin, core_p
