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
import tomllib
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from . import _validate as v
from .asbuilt import AsBuilt, asbuilt_from_dict
from .constants import MU0  # noqa: F401  (re-exported: designkit.design.MU0 is public)
from .errors import BadInputError, DesignRuleError



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
class ArraySpec:
    """Planar array of identical coils with parallel axes (+z), top faces at z = 0."""

    rows: int = 3
    columns: int = 3
    pitch_m: float = 0.050
    """Centre-to-centre spacing, m (assumed from the 150 mm x 150 mm footprint)."""


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


@dataclass(frozen=True)
class SensorSpec:
    """Two arrays of TLV493D-A1B6 Hall sensors, one at each coil centre."""

    offset_m: float = 0.014
    """Distance above the coil tops (upper array) and below the coil bottoms (lower array), m."""
    range_t: float = 0.130
    lsb_t: float = 0.098e-3


@dataclass(frozen=True)
class WorkspaceSpec:
    """Box in which the finger magnet moves, m, in the array frame."""

    z_min_m: float = 0.020
    """Lowest magnet-centre height above the coil tops, m. The magnet's centre cannot go lower:
    the upper Hall-sensor board sits ``sensors.offset_m`` (14 mm) above the coil tops and the
    magnet is 10 mm long, so its centre is >= 19 mm up plus the board's thickness
    (docs/optimize.md, "Workspace floor")."""
    z_max_m: float = 0.080
    half_width_m: float = 0.075
    """Half the side of the square footprint the box covers in x and y, m."""


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
class Design:
    """The whole device. Immutable; sweeps use :func:`dataclasses.replace`."""

    name: str = "thesis-default"
    magnet: MagnetSpec = field(default_factory=MagnetSpec)
    wire: WireSpec = field(default_factory=WireSpec)
    coil: CoilSpec = field(default_factory=CoilSpec)
    core: CoreSpec | None = field(default_factory=CoreSpec)
    array: ArraySpec = field(default_factory=ArraySpec)
    drive: DriveSpec = field(default_factory=DriveSpec)
    sensors: SensorSpec = field(default_factory=SensorSpec)
    workspace: WorkspaceSpec = field(default_factory=WorkspaceSpec)
    optimize: OptimizeSpec = field(default_factory=OptimizeSpec)
    render: RenderSpec = field(default_factory=RenderSpec)
    cad: CadSpec = field(default_factory=CadSpec)
    asbuilt: AsBuilt | None = None
    """The device as built (designkit.asbuilt); None: the nominal design."""

    def __post_init__(self):
        check_design(self)
        if self.asbuilt is not None:
            self.asbuilt.check(self.array.rows * self.array.columns, self.core is not None)

    # -- derived quantities -------------------------------------------------------------
    @property
    def design_point_m(self) -> tuple[float, float, float]:
        """Magnet centre at the design height above the top face of a single coil, m."""
        return (0.0, 0.0, self.optimize.height_m)

    def coil_centres_m(self) -> list[tuple[float, float, float]]:
        """Centres of the array's windings, row-major, m (top faces at z = 0)."""
        a = self.array
        zc = -self.coil.length_m / 2
        out = []
        for i in range(a.rows):
            for j in range(a.columns):
                x = (j - (a.columns - 1) / 2) * a.pitch_m
                y = ((a.rows - 1) / 2 - i) * a.pitch_m
                out.append((x, y, zc))
        return out

    def replace(self, **changes) -> "Design":
        """A copy with top-level or dotted-path changes: ``d.replace(**{"coil.turns": 1000})``."""
        return replace_path(self, changes)

    def to_dict(self) -> dict[str, Any]:
        out = dataclasses.asdict(self)
        if self.asbuilt is None:  # a nominal design keeps its hash
            del out["asbuilt"]
        return out

    def spec_hash(self) -> str:
        """SHA-256 of the canonical JSON of the physics spec (stable across runs and machines;
        the printing choices of ``cad`` change no field, so they are not part of it)."""
        spec = {k: val for k, val in self.to_dict().items() if k != "cad"}
        blob = json.dumps(spec, sort_keys=True, separators=(",", ":"), default=float)
        return hashlib.sha256(blob.encode()).hexdigest()


_SECTIONS = {
    "magnet": MagnetSpec, "wire": WireSpec, "coil": CoilSpec, "core": CoreSpec,
    "array": ArraySpec, "drive": DriveSpec, "sensors": SensorSpec,
    "workspace": WorkspaceSpec, "optimize": OptimizeSpec, "render": RenderSpec,
    "cad": CadSpec,
}


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
            if sec not in _SECTIONS:
                raise BadInputError("parameter", f"one of {sorted(_SECTIONS)} before the dot", key)
            allowed = {f.name for f in fields(_SECTIONS[sec])}
            if name not in allowed:
                raise BadInputError("parameter", f"a field of [{sec}]: {sorted(allowed)}", key)
            per_section.setdefault(sec, {})[name] = value
        else:
            top[key] = value
    for sec, vals in per_section.items():
        current = getattr(design, sec)
        if current is None:
            current = _SECTIONS[sec]()
        top[sec] = dataclasses.replace(current, **vals)
    return dataclasses.replace(design, **top)


def design_from_dict(data: Mapping[str, Any], *, source: str = "design") -> Design:
    """Build a Design from a nested mapping (the TOML layout); unknown keys are errors."""
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key == "name":
            kwargs["name"] = value  # type-checked in check_design: 5 is not silently "5"
        elif key == "asbuilt":
            kwargs["asbuilt"] = asbuilt_from_dict(value, source)
        elif key in _SECTIONS:
            if key == "core" and (value is False or value == {} and False):
                kwargs["core"] = None
                continue
            if not isinstance(value, Mapping):
                raise BadInputError(f"{source}: [{key}]", "a table", value)
            if key == "core" and value.get("enabled", True) is False:
                kwargs["core"] = None
                continue
            cls = _SECTIONS[key]
            allowed = {f.name for f in fields(cls)}
            unknown = set(value) - allowed - ({"enabled"} if key == "core" else set())
            if unknown:
                raise BadInputError(f"{source}: [{key}] key", f"one of {sorted(allowed)}",
                                    sorted(unknown)[0])
            kwargs[key] = cls(**{k: val for k, val in value.items() if k != "enabled"})
        else:
            raise BadInputError(f"{source}: top-level key",
                                f"'name' or one of the tables {sorted(_SECTIONS)}", key)
    return Design(**kwargs)


NAMED_DESIGNS: dict[str, str | None] = {"thesis": None, "thesis-default": None,
                                          "optimized": "optimized.toml"}
"""Designs loadable by name (``--design optimized``): None = the embedded thesis default;
otherwise a TOML file shipped in ``designkit/data`` (``optimized``: the device of
``designkit optimize`` meeting every constraint, see designkit.optimize)."""


def named_design(name: str) -> Design:
    """A shipped design by name (:data:`NAMED_DESIGNS`)."""
    if name not in NAMED_DESIGNS:
        raise BadInputError("design", f"a TOML path or one of the names {sorted(NAMED_DESIGNS)}",
                            name)
    fname = NAMED_DESIGNS[name]
    if fname is None:
        return default_design()
    text = resources.files("designkit").joinpath("data", fname).read_text()
    return design_from_dict(tomllib.loads(text), source=f"designkit/data/{fname}")


def load_design(path: str | Path | None) -> Design:
    """Load a TOML design file, or a shipped design by name; ``None`` gives
    :func:`default_design`.

    Names (:data:`NAMED_DESIGNS`) are used only when no file of that name exists. Missing
    tables and keys take the default design's values.
    """
    if path is None:
        return default_design()
    p = Path(path)
    if not p.is_file() and str(path) in NAMED_DESIGNS:
        return named_design(str(path))
    if not p.is_file():
        raise BadInputError("design", "a path to an existing TOML file or one of the names "
                            f"{sorted(NAMED_DESIGNS)}", str(p))
    try:
        data = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise BadInputError("design", f"valid TOML ({exc})", str(p)) from None
    return design_from_dict(data, source=str(p))


def design_to_toml(design: Design) -> str:
    """Serialize a design as TOML (round-trips through :func:`load_design`)."""
    lines = [f'name = "{design.name}"', ""]
    for sec in _SECTIONS:
        obj = getattr(design, sec)
        lines.append(f"[{sec}]")
        if obj is None:
            lines.append("enabled = false")
        else:
            for f in fields(obj):
                val = getattr(obj, f.name)
                lines.append(f"{f.name} = {json.dumps(val)}")
        lines.append("")
    if design.asbuilt is not None:
        lines.append(design.asbuilt.to_toml())
    return "\n".join(lines)


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


def check_design(d: Design) -> None:
    """Type and range checks of every field; raises BadInputError naming the dotted parameter."""
    _check_type("name", d.name, "")
    if not d.name.strip():
        raise BadInputError("name", "a non-empty string", d.name)
    for sec in _SECTIONS:
        obj = getattr(d, sec)
        if obj is None:
            continue
        for f in fields(obj):
            val = getattr(obj, f.name)
            name = f"{sec}.{f.name}"
            if f.name == "direction":
                if not (isinstance(val, tuple) and len(val) == 3
                        and all(isinstance(c, float) and math.isfinite(c) for c in val)
                        and any(c != 0.0 for c in val)):
                    raise BadInputError(name, "3 finite numbers, not all 0 (the moment's "
                                        "direction; default [0, 0, -1])", val)
                continue
            _check_type(name, val, f.default)
            _check_metres(name, val)
            if f.name == "bh":
                if val not in ("linear", "steel1010"):
                    raise BadInputError(name, "'linear' or 'steel1010'", val)
            elif f.name == "packing":
                if val not in ("layered", "orthocyclic"):
                    raise BadInputError(name, "'layered' or 'orthocyclic'", val)
            elif f.name == "mandrel":
                if val not in ("auto", "printed_tube", "core"):
                    raise BadInputError(name, "'auto', 'printed_tube' or 'core'", val)
            elif f.name == "driver":
                if not val.strip():
                    raise BadInputError(name, "a non-empty name", val)
            elif f.name in ("turns", "rows", "columns"):
                v.positive_int(name, val)
            elif f.name in ("offset_m", "reference_temperature_c", "operating_temperature_c",
                            "core_clearance_m", "press_fit_clearance_m"):
                v.finite(name, val)
            elif f.name == "z_min_m":
                v.nonnegative(name, val)
            else:
                v.positive(name, val, "")
    c = d.coil
    if c.outer_radius_m <= c.inner_radius_m:
        raise BadInputError("coil.outer_radius_m", f"> coil.inner_radius_m ({c.inner_radius_m} m)",
                            c.outer_radius_m)
    if d.core is not None and d.core.radius_m > c.inner_radius_m:
        raise BadInputError("core.radius_m", f"<= coil.inner_radius_m ({c.inner_radius_m} m)",
                            d.core.radius_m, "The core must fit in the bore.")
    if d.drive.driver_max_voltage_v <= d.drive.driver_min_voltage_v:
        raise BadInputError("drive.driver_max_voltage_v",
                            f"> drive.driver_min_voltage_v ({d.drive.driver_min_voltage_v} V)",
                            d.drive.driver_max_voltage_v)
    if d.workspace.z_max_m <= d.workspace.z_min_m:
        raise BadInputError("workspace.z_max_m", f"> workspace.z_min_m ({d.workspace.z_min_m} m)",
                            d.workspace.z_max_m)
    if d.array.rows * d.array.columns > 1 and 2 * c.outer_radius_m > d.array.pitch_m:
        raise DesignRuleError(
            f"Coils overlap: 2 x coil.outer_radius_m = {2 * c.outer_radius_m:.4g} m exceeds "
            f"array.pitch_m = {d.array.pitch_m:.4g} m; neighbouring coils (e.g. 0 and 1) intersect."
        )
