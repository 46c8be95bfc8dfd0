"""The design spec: one frozen, SI-unit description of the whole device.

Every product (field, force, optimized coil, printed parts, FEM mesh, force-current map,
plots, currents on the wire) is derived from one :class:`Design`, so they can never disagree.
A design is loaded from TOML (:func:`load_design`) or taken from :func:`default_design`, the
thesis' device (the EHI thesis this toolkit reproduces, sections 2.2-3.2). Values the thesis does not give
are marked ``assumed`` in the field docs below.

Frame: the coil top faces lie in the plane z = 0 and z points up, towards the user's hand.
Polarity (see :class:`MagnetSpec`): positive current = counter-clockwise seen from above = coil
field up; the magnet's moment points down by default, so positive current repels it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import numbers
from dataclasses import dataclass, field, fields
from typing import Any, Mapping

import numpy as np

from ..constants import MU0  # noqa: F401  (re-exported: designkit.design.MU0 is public)
from ..errors import BadInputError, DesignRuleError
from ..geometry.pose import Pose
from ..support import validate as v
from .asbuilt import AsBuilt
from .layouts import GridLayout, HexLayout, Layout, check_layout, pose_on_axis
from .workspace import Workspace



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


@dataclass(frozen=True)
class Design:
    """The whole device. Immutable; sweeps use :func:`dataclasses.replace`."""

    name: str = "thesis-default"
    magnet: MagnetSpec = field(default_factory=MagnetSpec)
    wire: WireSpec = field(default_factory=WireSpec)
    coil: CoilSpec = field(default_factory=CoilSpec)
    core: CoreSpec | None = field(default_factory=CoreSpec)
    array: Layout = field(default_factory=GridLayout)
    """Where the coils sit (:mod:`designkit.design.layouts`): grid, hex, ring or free."""
    drive: DriveSpec = field(default_factory=DriveSpec)
    sensors: SensorSpec = field(default_factory=SensorSpec)
    workspace: WorkspaceSpec = field(default_factory=WorkspaceSpec)
    optimize: OptimizeSpec = field(default_factory=OptimizeSpec)
    render: RenderSpec = field(default_factory=RenderSpec)
    cad: CadSpec = field(default_factory=CadSpec)
    asbuilt: AsBuilt | None = None
    """The device as built (designkit.design.asbuilt); None: the nominal design."""
    groups: tuple[CoilGroup, ...] = ()
    """Coils whose winding or core differ from ``coil`` / ``core`` (none: all alike)."""
    other_magnets: tuple[MagnetSpec, ...] = ()
    """Magnets beyond ``magnet`` (several fingers: ``[[magnets]]`` in a design file, the first
    of which is ``magnet``); :attr:`magnets` lists them all."""

    def __post_init__(self):
        check_design(self)
        if self.asbuilt is not None:
            self.asbuilt.check(self.n_coils, self.core is not None)

    # -- derived quantities -------------------------------------------------------------
    @property
    def design_point_m(self) -> tuple[float, float, float]:
        """Magnet centre at the design height above the top face of a single coil, m."""
        return (0.0, 0.0, self.optimize.height_m)

    @property
    def magnets(self) -> tuple[MagnetSpec, ...]:
        """Every finger magnet, ``magnet`` first."""
        return (self.magnet,) + self.other_magnets

    @property
    def n_coils(self) -> int:
        """Number of coils of the layout."""
        return len(self.array.top_centres_m())

    def coil_spec(self, k: int) -> CoilSpec:
        """The winding of coil k (its group's, else ``coil``)."""
        for g in self.groups:
            if k in g.coils:
                return g.coil
        return self.coil

    def core_spec(self, k: int) -> CoreSpec | None:
        """The core of coil k (its group's, else ``core``; None: an air coil)."""
        for g in self.groups:
            if k in g.coils:
                return g.core
        return self.core

    def coil_poses(self) -> list[Pose]:
        """Each coil's pose: its winding centre (``length_m / 2`` below its top face along its
        axis), its local +z the layout's axis (the identity rotation for an upright coil), m."""
        tops, axes = self.array.top_centres_m(), self.array.axes()
        return [pose_on_axis(top - axis * self.coil_spec(k).length_m / 2, axis)
                for k, (top, axis) in enumerate(zip(tops, axes))]

    def coil_centres_m(self) -> list[tuple[float, float, float]]:
        """Centres of the windings, m, in the layout's coil order."""
        return [p.position for p in self.coil_poses()]

    def workspace_region(self) -> Workspace:
        """The region the magnet moves in (:class:`designkit.design.workspace.Workspace`)."""
        ws = self.workspace
        if ws.shape == "box":
            return Workspace.box(ws.half_width_m, ws.z_min_m, ws.z_max_m)
        if ws.shape == "disc":
            return Workspace.disc(ws.radius_m, ws.z_min_m, ws.z_max_m)
        return Workspace.from_polygon(self.array.footprint_m(), ws.z_min_m, ws.z_max_m)

    def sensor_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """Sensor positions (n_sensors, 3) m and frames (n_sensors, 3, 3) (columns: each chip's
        x, y, z axes in the array frame), in :class:`SensorSpec`'s order."""
        s = self.sensors
        if s.layout == "free":
            pos = np.array(s.positions_m, dtype=float).reshape(-1, 3)
            rot = (np.array(s.rotations, dtype=float).reshape(-1, 3, 3) if s.rotations
                   else np.tile(np.eye(3), (len(pos), 1, 1)))
            return pos, rot
        poses = self.coil_poses()
        up, down, frames = [], [], []
        for k, p in enumerate(poses):
            axis = p.matrix[:, 2]
            reach = self.coil_spec(k).length_m / 2 + s.offset_m
            up.append(np.asarray(p.position) + reach * axis)
            down.append(np.asarray(p.position) - reach * axis)
            frames.append(p.matrix)
        return np.array(up + down), np.array(frames + frames)

    def replace(self, **changes) -> "Design":
        """A copy with top-level or dotted-path changes: ``d.replace(**{"coil.turns": 1000})``."""
        return replace_path(self, changes)

    def to_dict(self) -> dict[str, Any]:
        """The spec as nested dicts (``array`` with its ``layout``; ``groups`` and ``asbuilt``
        only when present, so that a design without them keeps its hash)."""
        out = dataclasses.asdict(self)
        out["array"] = {"layout": self.array.kind, **out["array"]}
        if self.asbuilt is None:
            del out["asbuilt"]
        if not self.groups:
            del out["groups"]
        if not self.other_magnets:
            del out["other_magnets"]
        return out

    def spec_hash(self) -> str:
        """SHA-256 of the canonical JSON of the physics spec (stable across runs and machines;
        the printing choices of ``cad`` change no field, so they are not part of it)."""
        spec = {k: val for k, val in self.to_dict().items() if k != "cad"}
        blob = json.dumps(spec, sort_keys=True, separators=(",", ":"), default=float)
        return hashlib.sha256(blob.encode()).hexdigest()


SECTIONS: dict[str, type] = {
    "magnet": MagnetSpec, "wire": WireSpec, "coil": CoilSpec, "core": CoreSpec,
    "array": GridLayout, "drive": DriveSpec, "sensors": SensorSpec,
    "workspace": WorkspaceSpec, "optimize": OptimizeSpec, "render": RenderSpec,
    "cad": CadSpec,
}
"""The tables of a design file and their classes (``array``: the grid's; the ``layout`` key
chooses another, :data:`designkit.design.layouts.LAYOUTS`)."""


def default_design() -> Design:
    """The thesis device with the assumptions stated in the field docs."""
    return Design()


def replace_path(design: Design, changes: Mapping[str, Any]) -> Design:
    """Apply ``{"section.field": value}`` (or top-level ``{"name": ...}``) changes."""
    top: dict[str, Any] = {}
    per_section: dict[str, dict[str, Any]] = {}
    for key, value in changes.items():
        if "." in key:
            sec, _, name = key.partition(".")
            if sec not in SECTIONS:
                raise BadInputError("parameter", f"one of {sorted(SECTIONS)} before the dot", key)
            current = getattr(design, sec)
            allowed = {f.name for f in fields(SECTIONS[sec] if current is None else current)}
            if name not in allowed:
                raise BadInputError("parameter", f"a field of [{sec}]: {sorted(allowed)}", key)
            per_section.setdefault(sec, {})[name] = value
        else:
            top[key] = value
    for sec, vals in per_section.items():
        current = getattr(design, sec)
        if current is None:
            current = SECTIONS[sec]()
        if sec == "workspace":
            vals = implied_shape(vals)
        top[sec] = dataclasses.replace(current, **vals)
    return dataclasses.replace(design, **top)


def _check_type(name: str, value: Any, default: Any) -> None:
    """The value has the type of the field's default: a string where text is expected, a whole
    number for counts, a number (not text, not true/false) for quantities."""
    if isinstance(default, str):
        if not isinstance(value, str):
            raise BadInputError(name, "a string (in TOML: quoted)", value)
    elif isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise BadInputError(name, "a whole number", value)
    elif isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise BadInputError(name, "a number (in TOML: unquoted)", value)


MAX_LENGTH_M = 1.0
"""Largest length (key ending in ``_m``) a design may give, m; radii at most half of it. A
larger value is almost always millimetres written where metres are expected."""


def _check_metres(name: str, value: Any) -> None:
    """Refuse a length that reads as millimetres (``coil.inner_radius_m = 12``), with the hint."""
    if (not name.endswith("_m") or name.endswith("_per_m") or isinstance(value, bool)
            or not isinstance(value, numbers.Real)):
        return
    limit = MAX_LENGTH_M / 2 if "radius" in name else MAX_LENGTH_M
    if abs(value) > limit:
        raise BadInputError(name, f"a length in metres, at most {limit:g} m", value,
                            f"Millimetres where metres are expected? {value:g} mm is "
                            f"{value / 1000:g} m: design files are in SI units.")


def _magnetization_hint(value: float) -> str:
    if 0.0 < value < 10.0:
        return (f"Br in tesla? M = Br / mu0: {value:g} T is {value / MU0:.4g} A/m (an N52 "
                f"magnet: Br ~1.45 T, M ~1.16e6 A/m).")
    return ""


def _permeability_hint(value: float) -> str:
    if 0.0 < value < 1.0:
        return (f"The absolute permeability in H/m? mu_r = mu / mu0: {value:g} H/m is "
                f"mu_r {value / MU0:.4g}.")
    return ""


def _tesla_hint(value: float) -> str:
    return f"Millitesla? {value:g} mT is {value * 1e-3:g} T." if value > 0 else ""


PHYSICAL_RANGES: dict[str, tuple[float, float, str, Any]] = {
    "magnetization_a_per_m": (1e4, 2e6, "A/m", _magnetization_hint),
    "relative_permeability": (1.0, 1e6, "", _permeability_hint),
    "saturation_t": (0.1, 3.0, "T", _tesla_hint),
    "range_t": (1e-4, 10.0, "T", _tesla_hint),
    "lsb_t": (1e-9, 1e-2, "T", _tesla_hint),
}
"""Closed ranges of the magnetic keys (low, high, unit, the hint for a value outside): a
permanent magnet's M lies between a weak rubber magnet's 1e4 A/m and 2e6 A/m (no magnet
reaches Br = 2.5 T); a core's mu_r between air's 1 and 1e6 (supermalloy); a B-H knee
between 0.1 and 3 T; a Hall sensor's range and resolution in tesla."""


def _check_physical(name: str, key: str, value: float) -> None:
    """``value`` of the magnetic key ``key`` in :data:`PHYSICAL_RANGES`, else BadInputError
    naming ``name``, the range and the value, with the unit hint."""
    lo, hi, unit, hint = PHYSICAL_RANGES[key]
    if not (math.isfinite(value) and lo <= value <= hi):
        raise BadInputError(name, f"in [{lo:g}, {hi:g}] {unit}".rstrip(), value, hint(value))


FINITE_FIELDS = ("offset_m", "reference_temperature_c", "operating_temperature_c",
                 "core_clearance_m", "press_fit_clearance_m")
"""Fields that may take any finite value (offsets, temperatures, clearances)."""


def field_rule(key: str, default: Any) -> tuple:
    """How a table's field ``key`` (with this default) is checked, one of: ('vector',) the
    moment's direction, ('list',) a sensor layout's list, ('choice', choices), ('name',) a
    non-empty free text, ('count',),
    ('finite',), ('nonnegative',), ('range', lo, hi, unit) (:data:`PHYSICAL_RANGES`),
    ('positive',). Lengths (``*_m``) are also capped by :data:`MAX_LENGTH_M`. The one rule
    book of :func:`check_design` and of the design-file reference (docs/design_file.md)."""
    if key == "direction":
        return ("vector",)
    if key in ("positions_m", "rotations"):
        return ("list",)
    if key in CHOICES:
        return ("choice", CHOICES[key])
    if isinstance(default, str):
        return ("name",)
    if key == "turns":
        return ("count",)
    if key in FINITE_FIELDS:
        return ("finite",)
    if key == "z_min_m":
        return ("nonnegative",)
    if key in PHYSICAL_RANGES:
        return ("range",) + PHYSICAL_RANGES[key][:3]
    return ("positive",)


def _check_section(sec: str, obj: Any) -> None:
    """Type and range checks of one table's fields, each named ``sec.field``
    (:func:`field_rule`)."""
    for f in fields(obj):
        val = getattr(obj, f.name)
        name = f"{sec}.{f.name}"
        kind = field_rule(f.name, f.default)[0]
        if kind == "vector":
            if not (isinstance(val, tuple) and len(val) == 3
                    and all(isinstance(c, float) and math.isfinite(c) for c in val)
                    and any(c != 0.0 for c in val)):
                raise BadInputError(name, "3 finite numbers, not all 0 (the moment's "
                                    "direction; default [0, 0, -1])", val)
            continue
        if kind == "list":
            continue  # the sensor layout's lists: _check_sensors
        _check_type(name, val, f.default)
        _check_metres(name, val)
        if kind == "choice":
            if val not in CHOICES[f.name]:
                raise BadInputError(name, " or ".join(repr(c) for c in CHOICES[f.name]), val)
        elif kind == "name":
            if not val.strip():
                raise BadInputError(name, "a non-empty name", val)
        elif kind == "count":
            v.positive_int(name, val)
        elif kind == "finite":
            v.finite(name, val)
        elif kind == "nonnegative":
            v.nonnegative(name, val)
        elif kind == "range":
            _check_physical(name, f.name, val)
        else:
            v.positive(name, val, "")


CHOICES = {"bh": ("linear", "steel1010"), "packing": ("layered", "orthocyclic"),
           "mandrel": ("auto", "printed_tube", "core"), "layout": SENSOR_LAYOUTS,
           "shape": WORKSPACE_SHAPES}
"""The fields that name a choice, and their choices."""


def _check_winding(where: str, c: CoilSpec, core: CoreSpec | None) -> None:
    if c.outer_radius_m <= c.inner_radius_m:
        raise BadInputError(f"{where}coil.outer_radius_m",
                            f"> {where}coil.inner_radius_m ({c.inner_radius_m} m)",
                            c.outer_radius_m)
    if core is not None and core.radius_m > c.inner_radius_m:
        raise BadInputError(f"{where}core.radius_m",
                            f"<= {where}coil.inner_radius_m ({c.inner_radius_m} m)",
                            core.radius_m, "The core must fit in the bore.")


def _check_groups(d: Design) -> None:
    seen: dict[int, int] = {}
    n = d.n_coils
    for g, group in enumerate(d.groups):
        where = f"groups[{g}]."
        if not group.coils:
            raise BadInputError(f"{where}coils", "a non-empty list of coil indices", [])
        for k in group.coils:
            if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < n:
                raise BadInputError(f"{where}coils", f"coil indices in [0, {n - 1}] (the "
                                    f"layout has {n} coils)", k)
            if k in seen:
                raise BadInputError(f"{where}coils", f"indices not in another group (coil {k}"
                                    f" is in groups[{seen[k]}])", k)
            seen[k] = g
        _check_section(f"{where}coil", group.coil)
        if group.core is not None:
            _check_section(f"{where}core", group.core)
        _check_winding(where, group.coil, group.core)


def _check_sensors(d: Design) -> None:
    s = d.sensors
    if s.layout != "free":
        for key in ("positions_m", "rotations"):
            if getattr(s, key):
                raise BadInputError(f"sensors.{key}", "given only with sensors.layout = 'free'",
                                    f"layout {s.layout!r}")
        return
    pos = np.asarray(s.positions_m, dtype=float) if s.positions_m else np.zeros((0, 3))
    if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) == 0 or not np.all(np.isfinite(pos)):
        raise BadInputError("sensors.positions_m", "a non-empty list of [x, y, z] in m",
                            s.positions_m)
    if s.rotations:
        rot = np.asarray(s.rotations, dtype=float)
        if rot.shape != (len(pos), 3, 3) or not np.all(np.isfinite(rot)):
            raise BadInputError("sensors.rotations", f"{len(pos)} 3x3 matrices (one a sensor)",
                                f"shape {rot.shape}")
        for k, r in enumerate(rot):
            if not (np.allclose(r.T @ r, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0):
                raise BadInputError(f"sensors.rotations[{k}]", "a proper rotation (columns: "
                                    "the chip's x, y, z axes, orthonormal, right-handed)",
                                    r.tolist())


def _check_magnets(d: Design) -> None:
    names: dict[str, int] = {}
    for k, magnet in enumerate(d.magnets):
        if not isinstance(magnet, MagnetSpec):
            raise BadInputError(f"magnets[{k}]", "a MagnetSpec", type(magnet).__name__)
        if k:
            _check_section(f"magnets[{k}]", magnet)
        if not magnet.name.strip():
            raise BadInputError(f"magnets[{k}].name", "a non-empty string", magnet.name)
        if magnet.name in names:
            raise BadInputError(f"magnets[{k}].name", "a name no other magnet has (magnets["
                                f"{names[magnet.name]}] is {magnet.name!r})", magnet.name)
        names[magnet.name] = k
    most = d.n_coils // 3
    if len(d.magnets) > max(most, 1):
        raise BadInputError(
            "magnets", f"at most {max(most, 1)} magnet(s) for {d.n_coils} coils", len(d.magnets),
            "Each magnet's force has 3 components to control: n magnets need at least 3 n "
            "independent coil currents.")


def check_design(d: Design) -> None:
    """Type and range checks of every field; raises BadInputError naming the dotted parameter."""
    _check_type("name", d.name, "")
    if not d.name.strip():
        raise BadInputError("name", "a non-empty string", d.name)
    check_layout(d.array)
    for sec in SECTIONS:
        obj = getattr(d, sec)
        if obj is not None and sec != "array":
            _check_section(sec, obj)
    _check_winding("", d.coil, d.core)
    if d.drive.driver_max_voltage_v <= d.drive.driver_min_voltage_v:
        raise BadInputError("drive.driver_max_voltage_v",
                            f"> drive.driver_min_voltage_v ({d.drive.driver_min_voltage_v} V)",
                            d.drive.driver_max_voltage_v)
    if d.workspace.z_max_m <= d.workspace.z_min_m:
        raise BadInputError("workspace.z_max_m", f"> workspace.z_min_m ({d.workspace.z_min_m} m)",
                            d.workspace.z_max_m)
    _check_groups(d)
    _check_sensors(d)
    _check_magnets(d)
    if isinstance(d.array, (GridLayout, HexLayout)) and d.n_coils > 1:
        widest = max(2 * d.coil_spec(k).outer_radius_m for k in range(d.n_coils))
        if widest > d.array.pitch_m:
            raise DesignRuleError(
                f"Coils overlap: 2 x coil.outer_radius_m = {widest:.4g} m exceeds "
                f"array.pitch_m = {d.array.pitch_m:.4g} m; neighbouring coils (e.g. 0 and 1) "
                "intersect.")
