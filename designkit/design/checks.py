"""The range checks of a design: every field of every table, the layout, the groups, the
sensors and the magnets; :func:`check_design` raises BadInputError naming the dotted key, its
value and the valid range (with a unit hint where a value reads as the wrong unit)."""

from __future__ import annotations

import math
import numbers
from dataclasses import fields
from typing import Any

import numpy as np

from firmware_io.hw.sensors import MAX_SENSORS

from ..constants import MU0
from ..errors import BadInputError, DesignRuleError
from ..support import validate as v
from .layouts import GridLayout, HexLayout, check_layout
from .tables import SECTIONS, SENSOR_LAYOUTS, WORKSPACE_SHAPES, CoilSpec, CoreSpec, MagnetSpec

DesignLike = Any
"""A :class:`designkit.design.Design` (not imported here: the design imports its checks)."""


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


def _check_groups(d: DesignLike) -> None:
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


def _check_sensors(d: DesignLike) -> None:
    s = d.sensors
    if s.layout != "free":
        for key in ("positions_m", "rotations"):
            if getattr(s, key):
                raise BadInputError(f"sensors.{key}", "given only with sensors.layout = 'free'",
                                    f"layout {s.layout!r}")
        if 2 * d.n_coils > MAX_SENSORS:
            raise BadInputError(
                "sensors.layout", f"'free' with at most {MAX_SENSORS} sensors, or 'coils' with "
                f"at most {MAX_SENSORS // 2} coils (one sensor above and one below each)",
                f"'coils' on {d.n_coils} coils ({2 * d.n_coils} sensors)",
                f"The sensor bus addresses {MAX_SENSORS}: TCA9548A muxes 0x71..0x77, 8 "
                "channels each.")
        return
    pos = np.asarray(s.positions_m, dtype=float) if s.positions_m else np.zeros((0, 3))
    if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) == 0 or not np.all(np.isfinite(pos)):
        raise BadInputError("sensors.positions_m", "a non-empty list of [x, y, z] in m",
                            s.positions_m)
    if len(pos) > MAX_SENSORS:
        raise BadInputError("sensors.positions_m", f"at most {MAX_SENSORS} sensors (the sensor "
                            "bus: TCA9548A muxes 0x71..0x77, 8 channels each)",
                            f"{len(pos)} sensors")
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


def _check_magnets(d: DesignLike) -> None:
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


def check_design(d: DesignLike) -> None:
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
