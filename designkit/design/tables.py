"""The tables of a design file, one frozen dataclass each (SI): the magnet, wire, winding, core,
drive, sensors, workspace, optimization, rendering and printing choices, and the coil groups.

Values the thesis does not give are marked ``assumed`` in the field docs. Frame: the coil top
faces of an upright array lie in the plane z = 0 and z points up, towards the user's hand.
Polarity (see :class:`MagnetSpec`): positive current = counter-clockwise seen from above = coil
field up; the magnet's moment points down by default, so positive current repels it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

from .layouts import GridLayout


@dataclass(frozen=True)
class MagnetSpec:
    """The fingertip permanent magnet (thesis: N52 cylinder, 10 mm x 10 mm, axial M).

    Polarity, defined here once for all of designkit and the map file: a positive coil current
    circulates counter-clockwise about +z seen from above (:meth:`designkit.Coil.field`), so
    the coil's field above its top face points up (+z, its north pole up). The magnet's moment
    points along ``direction``, by default -z (its north pole faces the coils): like poles face
    each other, and positive current repels the magnet, i.e. pushes the finger up, as the
    thesis' unipolar drive does (F_z = m . dB/dz = -|m| dBz/dz > 0 above a coil).
    """

    name: str = "finger"
    """What the runner, logs and summaries call this magnet (unique among a design's magnets)."""
    radius_m: float = 0.005
    length_m: float = 0.010
    magnetization_a_per_m: float = 1.1579e6
    """Axial magnetization M, A/m (thesis section 2.2)."""
    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    """Direction of the magnetic moment (south -> north) in the array frame, normalized on use.
    Default (0, 0, -1): north pole down, so positive coil current means repulsion."""

    def __post_init__(self):
        d = tuple(float(c) for c in self.direction) if isinstance(
            self.direction, (list, tuple)) else self.direction
        object.__setattr__(self, "direction", d)

    @property
    def moment_vector_a_m2(self) -> tuple[float, float, float]:
        """The moment m = M V * direction / |direction|, A m^2, shape (3,). Use this, never a
        hard-coded (0, 0, |m|)."""
        d = self.direction
        n = math.sqrt(sum(c * c for c in d))
        return tuple(self.moment_a_m2 * c / n for c in d)

    @property
    def volume_m3(self) -> float:
        return math.pi * self.radius_m**2 * self.length_m

    @property
    def moment_a_m2(self) -> float:
        """Dipole moment |m| = M V, A m^2 (~0.909 for the thesis magnet)."""
        return self.magnetization_a_per_m * self.volume_m3


@dataclass(frozen=True)
class WireSpec:
    """Magnet wire. The thesis gives 0.7 mm; we take it as the bare copper diameter."""

    diameter_m: float = 0.7e-3
    """Bare copper diameter, m."""
    insulated_diameter_m: float = 0.7e-3
    """Outer diameter over the enamel, m (assumed equal to the bare diameter, which is what
    1429 turns in the thesis' 7 mm x 100 mm section implies: 10 layers x 143 turns)."""
    resistivity_ohm_m: float = 1.7241e-8
    """Annealed copper at the reference temperature (IEC 60028), ohm m."""
    temperature_coefficient_per_k: float = 0.00393
    reference_temperature_c: float = 20.0
    operating_temperature_c: float = 20.0
    """Winding temperature at which R is evaluated, deg C (assumed)."""
    packing: str = "layered"
    """'layered' (square, turns = layers x turns per layer) or 'orthocyclic'."""


@dataclass(frozen=True)
class CoilSpec:
    """Thick multilayer winding (thesis: 24/38 mm inner/outer diameter, 100 mm, 1429 turns)."""

    inner_radius_m: float = 0.012
    outer_radius_m: float = 0.019
    length_m: float = 0.100
    turns: int = 1429


@dataclass(frozen=True)
class CoreSpec:
    """Soft-iron core (thesis: low-carbon steel, 110 mm long)."""

    radius_m: float = 0.012
    """Core radius, m (assumed: fills the 24 mm bore)."""
    length_m: float = 0.110
    relative_permeability: float = 1000.0
    """Linear relative permeability (assumed; the thesis does not state it)."""
    offset_m: float = 0.0
    """Axial offset of the core centre from the winding centre, m (assumed 0: the core
    protrudes 5 mm beyond each end of the 100 mm winding)."""
    saturation_t: float = 1.5
    """Flux density at the knee of the B-H curve of low-carbon steel, T: a linear core model
    warns above it (``Core.knee_t``)."""
    bh: str = "linear"
    """Core material law: 'linear' (relative_permeability; keeps fields linear in the currents,
    which the actuation matrix and the controller assume) or 'steel1010' (nonlinear B-H curve,
    see designkit.cores)."""


@dataclass(frozen=True)
class DriveSpec:
    supply_voltage_v: float = 36.0
    max_current_a: float = 6.0
    """Per-coil current limit used by the map and the controller, A."""
    total_current_a: float = 54.0
    """Budget for the sum of |I| over all coils, A (assumed: 9 x 6 A)."""
    driver: str = "Cytron MD10C"
    """The coil driver's name; its ratings are the ``driver_*`` keys (defaults: the MD10C's)."""
    driver_min_voltage_v: float = 5.0
    """Lowest motor supply the driver is rated for, V (MD10C: 5 V)."""
    driver_max_voltage_v: float = 30.0
    """Highest motor supply the driver is rated for, V (MD10C datasheet: 30 V; the thesis' 36 V
    exceeds it)."""
    driver_continuous_current_a: float = 13.0
    """The driver's continuous output current, A (MD10C: 13 A)."""
    driver_max_pwm_frequency_hz: float = 20e3
    """Highest PWM input frequency the driver follows, Hz (MD10C: 20 kHz)."""
    pwm_frequency_hz: float = 1526.0
    """PWM frequency of the drivers, Hz (datasheet: the PCA9685's maximum); sets the current
    ripple (``electrical.pwm_ripple``)."""


SENSOR_LAYOUTS = ("coils", "free")
"""Sensor layouts: 'coils' (one sensor on each coil's axis above its top face and one below its
bottom face) or 'free' (``positions_m`` and ``rotations``)."""


@dataclass(frozen=True)
class SensorSpec:
    """The 3-axis Hall sensors (TLV493D-A1B6): where they sit and what they read.

    ``layout = 'coils'`` (default, the thesis): an upper array, one sensor ``offset_m`` above
    each coil's top face on its axis, in coil order, then a lower array, ``offset_m`` below each
    bottom face; each chip's frame is its coil's. ``layout = 'free'``: one sensor at each of
    ``positions_m`` (m, array frame), its frame ``rotations[k]`` (3 x 3, columns = the chip's
    x, y, z axes in the array frame; empty: every chip aligned with the array frame).
    """

    layout: str = "coils"
    offset_m: float = 0.014
    """Distance above the coil tops (upper array) and below the coil bottoms (lower array), m."""
    range_t: float = 0.130
    lsb_t: float = 0.098e-3
    positions_m: tuple[tuple[float, float, float], ...] = ()
    rotations: tuple[tuple[tuple[float, float, float], ...], ...] = ()


WORKSPACE_SHAPES = ("layout", "box", "disc")
"""Workspace outlines: 'layout' (the layout's own footprint, :mod:`.layouts`), 'box' (the square
of ``half_width_m`` about the array's axis) or 'disc' (``radius_m``)."""


def implied_shape(values: Mapping[str, Any]) -> dict[str, Any]:
    """Workspace keys with the shape their size implies: ``half_width_m`` without ``shape``
    means the box, ``radius_m`` the disc (a design that gives a size means that outline)."""
    out = dict(values)
    if "shape" not in out:
        if "half_width_m" in out:
            out["shape"] = "box"
        elif "radius_m" in out:
            out["shape"] = "disc"
    return out


@dataclass(frozen=True)
class WorkspaceSpec:
    """The region the finger magnet moves in (:class:`designkit.design.workspace.Workspace`):
    an outline in x, y from ``shape`` and heights ``z_min_m`` to ``z_max_m`` above the coil
    tops, m, array frame."""

    z_min_m: float = 0.020
    """Lowest magnet-centre height above the coil tops, m. The magnet's centre cannot go lower:
    the upper Hall-sensor board sits ``sensors.offset_m`` (14 mm) above the coil tops and the
    magnet is 10 mm long, so its centre is >= 19 mm up plus the board's thickness
    (docs/optimize.md, "Workspace floor")."""
    z_max_m: float = 0.080
    shape: str = "layout"
    half_width_m: float = 0.075
    """Half the side of the square outline of ``shape = 'box'``, m."""
    radius_m: float = 0.075
    """Radius of the outline of ``shape = 'disc'``, m."""


@dataclass(frozen=True)
class OptimizeSpec:
    """The coil-design problem of thesis eq. 2.14."""

    height_m: float = 0.030
    """Design point: magnet centre above the coil top face, m."""
    max_resistance_ohm: float = 6.0
    max_settling_time_s: float = 0.100
    """Bound on 5 L/R, s."""
    max_outer_radius_m: float = 0.025
    """Rmax (assumed: half the 50 mm pitch)."""
    max_length_m: float = 0.100
    """Lmax (assumed: the thesis' result sits on it)."""
    min_inner_radius_m: float = 0.005


@dataclass(frozen=True)
class RenderSpec:
    stiffness_n_per_m: float = 6.0
    """Force constant lambda of thesis eq. 4.3, N/m."""
    threshold_n: float = 0.8e-3
    """Human force-detection threshold, N."""


@dataclass(frozen=True)
class CadSpec:
    """Printing choices of the parts (cad/), m: the keys that fix a buildability rule
    (:mod:`designkit.rules`; rationale in docs/rules.md). Defaults: an FDM printer with a
    0.4 mm nozzle and a 12 mm x 1.6 mm Hall-sensor breakout board (assumed)."""

    mandrel: str = "auto"
    """What carries the winding: 'printed_tube', 'core' (wound on the insulated core) or
    'auto' (a tube when the core leaves room for one)."""
    min_wall_m: float = 0.8e-3
    """Thinnest wall the printer makes reliably (two 0.4 mm perimeters), m."""
    core_clearance_m: float = 0.15e-3
    air_core_tube_wall_m: float = 1.2e-3
    flange_thickness_m: float = 2.0e-3
    flange_lip_m: float = 1.5e-3
    """Bobbin flange radius - winding outer radius, m."""
    pocket_clearance_m: float = 0.3e-3
    """Frame-plate flange seat radius - flange radius, m."""
    plate_thickness_m: float = 6.0e-3
    fixing_inset_m: float = 5.2e-3
    """Distance of the corner fixing holes from the footprint edges, m."""
    fixing_hole_radius_m: float = 1.7e-3
    standoff_outer_radius_m: float = 4.0e-3
    board_width_m: float = 12e-3
    """Side of the square Hall-sensor board, m."""
    board_thickness_m: float = 1.6e-3
    """Sensor board thickness, m; its mid-plane is the sensing plane (sensors.offset_m)."""
    board_clearance_m: float = 0.2e-3
    mount_floor_m: float = 2.0e-3
    channel_width_m: float = 4.0e-3
    press_fit_clearance_m: float = 0.05e-3
    """Radial oversize of the magnet pocket, m (FDM holes print undersize: a press fit)."""
    finger_diameter_m: float = 18e-3
    ring_wall_m: float = 2.5e-3
    ring_width_m: float = 14e-3
    boss_wall_m: float = 1.6e-3
    holder_floor_m: float = 1.2e-3


@dataclass(frozen=True)
class CoilGroup:
    """Coils of a layout (indices in the layout's order) with a winding and core of their own;
    in a design file ``[[groups]]`` with ``coils = [...]`` and partial ``coil`` / ``core``
    tables whose missing keys take the design's ``[coil]`` / ``[core]`` values."""

    coils: tuple[int, ...]
    coil: CoilSpec
    core: CoreSpec | None


SECTIONS: dict[str, type] = {
    "magnet": MagnetSpec, "wire": WireSpec, "coil": CoilSpec, "core": CoreSpec,
    "array": GridLayout, "drive": DriveSpec, "sensors": SensorSpec,
    "workspace": WorkspaceSpec, "optimize": OptimizeSpec, "render": RenderSpec,
    "cad": CadSpec,
}
"""The tables of a design file and their classes (``array``: the grid's; the ``layout`` key
chooses another, :data:`designkit.design.layouts.LAYOUTS`)."""
