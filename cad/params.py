"""Frozen parameter dataclasses of every part, and the one SI (m) -> mm conversion.

:func:`from_design` (with the per-part helpers it calls) is the only place where the
design's metres become millimetres; every part function takes one of the dataclasses below
and nothing else. Values the thesis does not give (fits, wall thicknesses, board size, finger
diameter) are printing choices, stated in the field docs and overridable through
:func:`from_design`'s keyword arguments.

Frame: the design's array frame in mm, coil top faces at z = 0, z up, coil (0, 0) at the
array centre for an odd number of rows and columns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from designkit.design import Design
from designkit.errors import BadInputError
from designkit.rules import Assembly, CoilType, assembly

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
class GridParams:
    """Where the coils are: the design's rows x columns at its pitch, and the footprint."""

    rows: int
    columns: int
    pitch_mm: float
    centres_xy_mm: tuple[tuple[float, float], ...]
    """Coil axes, row-major as :meth:`Design.coil_centres_m`, mm."""
    footprint_x_mm: float
    footprint_y_mm: float
    fixing_inset_mm: float
    """Distance of the four corner fixing holes from the footprint edges, mm."""
    fixing_hole_radius_mm: float
    """M3 clearance hole, mm."""

    @property
    def fixing_xy_mm(self) -> tuple[tuple[float, float], ...]:
        hx = self.footprint_x_mm / 2 - self.fixing_inset_mm
        hy = self.footprint_y_mm / 2 - self.fixing_inset_mm
        return ((-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy))


@dataclass(frozen=True)
class FrameParams:
    """Upper frame plate (the lower one is its mirror image about the array mid-plane)."""

    grid: GridParams
    thickness_mm: float
    """Plate thickness; the plate's bottom face lies on the coil top plane z = 0, mm."""
    pocket_radius_mm: float
    """Flange seat from the underside: flange radius + fit clearance, mm."""
    pocket_depth_mm: float
    """= flange thickness, so the plate's underside rests on the winding's end plane, mm."""
    through_radius_mm: float
    """Hole above the pocket through which the core passes (= bobbin bore), mm."""
    mirror_z_mm: float
    """z of the array mid-plane about which the lower plate mirrors the upper one, mm."""


@dataclass(frozen=True)
class StandoffParams:
    """Spacer tube between the two frame plates, on an M3 rod at each corner."""

    outer_radius_mm: float
    hole_radius_mm: float
    length_mm: float
    """= winding length: the plates rest on the winding end planes, mm."""


@dataclass(frozen=True)
class SensorMountParams:
    """Board mount of the upper Hall-sensor array (the lower one mirrors it)."""

    grid: GridParams
    sensor_z_mm: float
    """Height of the sensing plane (board mid-plane) above the coil tops, mm."""
    board_size_mm: tuple[float, float]
    """Sensor breakout board, x by y, mm (assumed 12 x 12: a TSOP-6 TLV493D on a small PCB)."""
    board_thickness_mm: float
    pocket_clearance_mm: float
    floor_thickness_mm: float
    channel_width_mm: float
    """Cable channel per row, from the pockets to the +x edge, as deep as the pocket, mm."""
    leg_outer_radius_mm: float
    leg_bottom_z_mm: float
    """Top face of the upper frame plate, on which the mount's legs stand, mm."""
    mirror_z_mm: float

    @property
    def top_z_mm(self) -> float:
        return self.sensor_z_mm + self.board_thickness_mm / 2

    @property
    def bottom_z_mm(self) -> float:
        return self.top_z_mm - self.board_thickness_mm - self.floor_thickness_mm


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
    bobbin: BobbinParams
    core: CoreParams | None
    grid: GridParams
    frame: FrameParams
    standoff: StandoffParams
    sensor_mount: SensorMountParams
    magnet_holder: MagnetHolderParams
    printer: PrinterParams
    magnet_centre_mm: tuple[float, float, float]
    """Where the assembly puts the magnet: the design point above the array centre, mm."""
    design: Design
    """The design with every override applied: what the rule book checks."""


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
    bobbin, core_p = _bobbin_and_core(design, g.types[0])
    outline = np.asarray(g.upper.outline_m)
    grid = GridParams(rows=design.array.rows, columns=design.array.columns,
                      pitch_mm=design.array.pitch_m * mm,
                      centres_xy_mm=tuple((x * mm, y * mm) for x, y, _ in design.coil_centres_m()),
                      footprint_x_mm=float(np.ptp(outline[:, 0])) * mm,
                      footprint_y_mm=float(np.ptp(outline[:, 1])) * mm,
                      fixing_inset_mm=c.fixing_inset_m * mm,
                      fixing_hole_radius_mm=c.fixing_hole_radius_m * mm)
    length = bobbin.winding_length_mm
    mid = -length / 2
    frame = FrameParams(grid=grid, thickness_mm=c.plate_thickness_m * mm,
                        pocket_radius_mm=g.types[0].pocket_radius_m * mm,
                        pocket_depth_mm=c.flange_thickness_m * mm,
                        through_radius_mm=bobbin.bore_radius_mm, mirror_z_mm=mid)
    standoff = StandoffParams(outer_radius_mm=c.standoff_outer_radius_m * mm,
                              hole_radius_mm=c.fixing_hole_radius_m * mm, length_mm=length)
    sensors = SensorMountParams(
        grid=grid, sensor_z_mm=design.sensors.offset_m * mm,
        board_size_mm=(c.board_width_m * mm, c.board_width_m * mm),
        board_thickness_mm=c.board_thickness_m * mm,
        pocket_clearance_mm=c.board_clearance_m * mm, floor_thickness_mm=c.mount_floor_m * mm,
        channel_width_mm=c.channel_width_m * mm, leg_outer_radius_mm=c.standoff_outer_radius_m * mm,
        leg_bottom_z_mm=c.plate_thickness_m * mm, mirror_z_mm=mid)
    holder = MagnetHolderParams(
        magnet_radius_mm=design.magnet.radius_m * mm, magnet_length_mm=design.magnet.length_m * mm,
        press_fit_clearance_mm=c.press_fit_clearance_m * mm,
        finger_diameter_mm=c.finger_diameter_m * mm, ring_wall_mm=c.ring_wall_m * mm,
        ring_width_mm=c.ring_width_m * mm, boss_wall_mm=c.boss_wall_m * mm,
        floor_thickness_mm=c.holder_floor_m * mm)
    # The design point sits above coil (0, 0) of the optimization; in the array that is the
    # array centre (a coil axis for odd rows x columns).
    magnet_centre = (0.0, 0.0, design.optimize.height_m * mm)
    return CadParams(design_name=design.name, bobbin=bobbin, core=core_p, grid=grid, frame=frame,
                     standoff=standoff, sensor_mount=sensors, magnet_holder=holder,
                     printer=printer, magnet_centre_mm=magnet_centre, design=design)


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
