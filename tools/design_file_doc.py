"""Generate docs/design_file.md, the reference of every key a design file may hold, from the
design package itself: the dataclasses (keys, types, defaults), their field docstrings (what
each key is) and the rule the checks apply (:func:`designkit.design.checks.field_rule`: the valid
range), so the reference cannot drift from the code. tests/test_design_file_doc.py fails when
the committed file differs from what this prints, or when a key of the spec is missing.

Usage: ``python tools/design_file_doc.py`` (rewrites docs/design_file.md) or ``--check``
(exit 1 when the committed file is stale).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from designkit.design import asbuilt, checks, layouts, tables  # noqa: E402

TARGET = ROOT / "docs" / "design_file.md"

UNITS = (("_a_per_m", "A/m"), ("_n_per_m", "N/m"), ("_ohm_m", "ohm m"), ("_per_k", "1/K"),
         ("_ohm", "ohm"), ("_hz", "Hz"), ("_deg", "deg"), ("_rad", "rad"), ("_m", "m"),
         ("_a", "A"), ("_v", "V"), ("_t", "T"), ("_s", "s"), ("_n", "N"), ("_c", "deg C"))
"""Key suffix -> unit (every quantity's key names its unit)."""

NOTES = {
    "magnet.radius_m": "Radius of the cylindrical finger magnet.",
    "magnet.length_m": "Length of the magnet along its moment.",
    "wire.temperature_coefficient_per_k": "Temperature coefficient of the copper's "
                                          "resistivity (IEC 60028).",
    "wire.reference_temperature_c": "Temperature of ``resistivity_ohm_m``.",
    "coil.inner_radius_m": "Inner radius of the winding (the bore).",
    "coil.outer_radius_m": "Outer radius of the winding.",
    "coil.length_m": "Axial length of the winding.",
    "coil.turns": "Turns of the winding (at most what its section holds: rule 'turns').",
    "core.length_m": "Core length (thesis: 110 mm on the 100 mm winding).",
    "drive.supply_voltage_v": "Supply of the coil drivers (thesis: 36 V; rule "
                              "'design_supply_voltage_v' against the driver's rating).",
    "drive.driver_continuous_current_a": "Continuous current rating of the driver (MD10C).",
    "sensors.range_t": "Measuring range of the Hall sensors, +- (TLV493D: 130 mT).",
    "sensors.lsb_t": "Resolution of one count (TLV493D: 0.098 mT).",
    "workspace.z_max_m": "Highest magnet-centre height above the coil tops.",
    "workspace.shape": "The outline in x, y (see above).",
    "sensors.layout": "Where the sensors are: on the coil axes, or free.",
    "sensors.positions_m": "Each sensor's position [x, y, z] (layout \"free\").",
    "sensors.rotations": "Each sensor's frame, 3 x 3 (layout \"free\").",
    "optimize.min_inner_radius_m": "Smallest winding inner radius the optimizers search.",
    "optimize.max_resistance_ohm": "Largest winding resistance (thesis eq. 2.14; the device "
                                   "optimizer applies it hot, at 100 C).",
    "cad.core_clearance_m": "Radial gap between the core and a printed bore.",
    "cad.air_core_tube_wall_m": "Wall of the printed tube an air winding is wound on.",
    "cad.flange_thickness_m": "Thickness of the bobbin's flanges.",
    "cad.plate_thickness_m": "Thickness of the frame plate.",
    "cad.fixing_hole_radius_m": "Radius of the frame's corner fixing holes.",
    "cad.standoff_outer_radius_m": "Outer radius of the sensor-board standoffs.",
    "cad.board_clearance_m": "Gap around the sensor board in its mount.",
    "cad.mount_floor_m": "Floor thickness of the sensor mount.",
    "cad.channel_width_m": "Width of the wire channels of the sensor mount.",
    "cad.finger_diameter_m": "Inner diameter of the finger ring of the magnet holder.",
    "cad.ring_wall_m": "Wall of the finger ring.",
    "cad.ring_width_m": "Width of the finger ring.",
    "cad.boss_wall_m": "Wall of the magnet holder's boss around the magnet.",
    "cad.holder_floor_m": "Floor under the magnet in its holder.",
    "array.rows": "Rows of the grid.",
    "array.columns": "Columns of the grid.",
    "array.rings": "Rings around the centre coil.",
    "array.count": "Coils on the ring.",
    "array.positions_m": "Each coil's top-face centre [x, y, z].",
    "array.axes": "Each coil's axis [ax, ay, az], a unit vector (empty: every axis +z; a "
                  "vector that is not unit is refused with the unit vector it may mean).",
    "asbuilt.coils.dx_m": "Offset of the winding centre along x.",
    "asbuilt.coils.dy_m": "Offset of the winding centre along y.",
    "asbuilt.coils.dz_m": "Offset of the winding centre along z.",
    "asbuilt.coils.tilt_x_rad": "Tilt about the array's x axis through the winding centre.",
    "asbuilt.coils.tilt_y_rad": "Tilt about the array's y axis through the winding centre.",
    "asbuilt.coils.turns": "Turns as wound (absent: the nominal count).",
    "asbuilt.coils.core_relative_permeability": "The core's mu_r as built (absent: nominal).",
    "asbuilt.coils.core_offset_m": "The core's axial offset from its nominal place.",
}
"""What a key is, for fields without a docstring in the code (a docstring there wins)."""

SECTION_NOTES = {
    "drive": "The coil drivers and their supply (thesis: Cytron MD10C boards, 36 V, 6 A per "
             "coil; PCA9685 PWM).",
    "render": "Rendering (thesis chapter 4).",
}
"""What a table is, for classes without a docstring in the code."""

LAYOUT_RULES = {
    "grid": {"rows": "a whole number >= 1", "columns": "a whole number >= 1",
             "pitch_m": "> 0"},
    "hex": {"rings": "a whole number >= 0", "pitch_m": "> 0"},
    "ring": {"count": "a whole number >= 1", "radius_m": "> 0", "tilt_deg": "[0, 90)"},
    "free": {"positions_m": "at least one [x, y, z], finite",
             "axes": "one unit vector per coil, or none",
             "footprint_margin_m": ">= 0"},
}
"""The ranges :func:`designkit.design.layouts.check_layout` applies (tests probe each)."""


def field_docs(module) -> dict:
    """{class name: {field: docstring}} from the attribute docstrings of ``module``'s source."""
    out: dict = {}
    for node in ast.walk(ast.parse(inspect.getsource(module))):
        if isinstance(node, ast.ClassDef):
            docs = {}
            body = node.body
            for a, b in zip(body, body[1:]):
                if (isinstance(a, ast.AnnAssign) and isinstance(a.target, ast.Name)
                        and isinstance(b, ast.Expr) and isinstance(b.value, ast.Constant)
                        and isinstance(b.value.value, str)):
                    docs[a.target.id] = " ".join(b.value.value.split())
            out[node.name] = docs
    return out


def unit_of(key: str) -> str:
    for suffix, unit in UNITS:
        if key.endswith(suffix):
            return unit
    return ""


def _default(f: dataclasses.Field):
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return None


class Shown(str):
    """A default shown as written (not a TOML value)."""


def _toml(value) -> str:
    if isinstance(value, Shown):
        return str(value)
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if value is None:
        return "(absent)"
    return f"{value:g}" if isinstance(value, float) else str(value)


def spec_valid(key: str, default) -> str:
    """The valid range of a spec field, from :func:`designkit.design.checks.field_rule`."""
    rule = checks.field_rule(key, default)
    kind = rule[0]
    if kind == "vector":
        return "3 finite numbers, not all 0 (normalized on use)"
    if kind == "list":
        return "lists, with layout = \"free\" only"
    if kind == "choice":
        return " or ".join(f'"{c}"' for c in rule[1])
    if kind == "count":
        return "a whole number >= 1"
    if kind == "name":
        return "a non-empty string"
    if kind == "range":
        return f"[{rule[1]:g}, {rule[2]:g}] {rule[3]}".rstrip()
    text = {"finite": "any finite number", "nonnegative": ">= 0", "positive": "> 0"}[kind]
    if unit_of(key) == "m":
        cap = checks.MAX_LENGTH_M / 2 if "radius" in key else checks.MAX_LENGTH_M
        text += f", at most {cap:g} m in size"
    return text


def md(text: str) -> str:
    """A docstring's reST as Markdown in a table cell: ``x`` and :role:`x` as `x`, bars
    escaped, whitespace folded."""
    text = re.sub(r":\w+:`~?([^`]+)`", r"`\1`", " ".join(text.split()))
    return text.replace("``", "`").replace("|", "\\|")


def _row(key: str, unit: str, default, valid: str, what: str) -> str:
    return f"| `{key}` | {unit or '-'} | {_toml(default)} | {valid} | {md(what)} |"


def class_doc(cls) -> str:
    """The class docstring (dataclasses make one from the signature when none is written:
    that one is left out)."""
    doc = cls.__doc__ or ""
    return "" if doc.startswith(cls.__name__ + "(") else md(doc)


HEADER = "| key | unit | default | valid | what |\n| --- | --- | --- | --- | --- |"


def section_table(sec: str, cls, docs: dict) -> str:
    rows = []
    for f in dataclasses.fields(cls):
        what = docs.get(cls.__name__, {}).get(f.name) or NOTES.get(f"{sec}.{f.name}", "")
        rows.append(_row(f.name, unit_of(f.name), _default(f), spec_valid(f.name, _default(f)),
                         what))
    return HEADER + "\n" + "\n".join(rows)


def layout_tables(docs: dict) -> str:
    parts = []
    for kind, cls in layouts.LAYOUTS.items():
        defaults = {("axes" if f.name == "axis_vectors" else f.name): _default(f)
                    for f in dataclasses.fields(cls)}
        rows = []
        for key in layouts.LAYOUT_KEYS[kind]:
            what = (docs.get(cls.__name__, {}).get("axis_vectors" if key == "axes" else key)
                    or NOTES.get(f"array.{key}", ""))
            rows.append(_row(key, unit_of(key), defaults[key], LAYOUT_RULES[kind][key], what))
        doc = class_doc(cls)
        parts.append(f"`layout = \"{kind}\"`{' (the default)' if kind == 'grid' else ''}: "
                     f"{doc}\n\n{HEADER}\n" + "\n".join(rows))
    return "\n\n".join(parts)


def asbuilt_tables(docs: dict) -> str:
    tol = [_row(f.name, unit_of(f.name) or "-", _default(f), "> 0",
                docs.get("BuildTolerances", {}).get(f.name, ""))
           for f in dataclasses.fields(asbuilt.BuildTolerances)]
    valid = {"turns": "a whole number >= 1, or absent",
             "core_relative_permeability": "> 0, or absent (cores only)",
             "core_offset_m": "any finite number (cores only)"}
    coil = [_row(f.name, unit_of(f.name), _default(f), valid.get(
        f.name, "any finite number" + ("; tilt_x, tilt_y together at most 0.2 rad"
                                        if "tilt" in f.name else "")),
        NOTES.get(f"asbuilt.coils.{f.name}", ""))
            for f in dataclasses.fields(asbuilt.CoilDeviation)]
    return ("`notes` (a string): where the numbers come from.\n\n"
            "`[asbuilt.tolerances]`: " + class_doc(asbuilt.BuildTolerances)
            + "\n\n" + HEADER + "\n" + "\n".join(tol) + "\n\n"
            "`[[asbuilt.coils]]`: none, or one table per coil in the layout's order. "
            + class_doc(asbuilt.CoilDeviation) + "\n\n" + HEADER + "\n"
            + "\n".join(coil))


INTRO = '''# Design files: every table and key

<!-- Generated by `python tools/design_file_doc.py` from designkit/design (the dataclasses,
their field docs and the checks); do not edit by hand: tests/test_design_file_doc.py fails when
this file and the generator disagree. -->

A design file is TOML: the tables below, each optional. A missing table or key takes the
default shown (the thesis device, `designkit.design.default_design()`); a key that is not
listed here is refused, naming it; a value outside its range is refused in one line naming
the key, its valid range and the value received. Every quantity is in SI units and its key
ends in its unit (`_m` metres, `_a` amperes, `_t` tesla, ...). A length above 1 m (a radius
above 0.5 m) is refused as millimetres written where metres are expected. Coordinates are in
the array frame: the coil top faces in the plane z = 0, z up towards the hand.

`designkit check --design FILE.toml` lists every design rule with its value, limit and the
keys that fix it ([rules.md](rules.md)); `design.toml` in a report folder is a complete
example, and `designkit optimize` writes one for its optimum. On the command line lengths
take units (`40mm`, `0.04m`; a bare number is millimetres, except in a key named `..._m`,
which is metres): [testing.md](testing.md) lists the conventions every command shares.

```toml
name = "my-device"

[array]
layout = "hex"
rings = 1
pitch_m = 0.044

[coil]
turns = 900

[[groups]]          # coil 0 (the centre) without a core
coils = [0]
[groups.core]
enabled = false

[workspace]
shape = "disc"
radius_m = 0.05
```

## Top level

| key | unit | default | valid | what |
| --- | --- | --- | --- | --- |
| `name` | - | "thesis-default" | a non-empty string | The design's name (titles, reports, the map's meta). |
'''


def render() -> str:
    docs = {**field_docs(tables), **field_docs(layouts), **field_docs(asbuilt)}
    out = [INTRO]
    for sec, cls in tables.SECTIONS.items():
        title = f"## [{sec}]"
        doc = class_doc(cls) or SECTION_NOTES.get(sec, "")
        if sec == "array":
            out.append(f"{title}\n\nWhere the coils sit; `layout` chooses how, and only its "
                       f"own keys may follow (another layout's key is refused, naming its "
                       f"layout).\n\n{layout_tables(docs)}\n")
            continue
        if sec == "core":
            doc += (" `enabled = false` (the only other key) makes every coil an air coil.")
        if sec == "sensors":
            doc += (' `positions_m` (at least one [x, y, z]) and `rotations` (one proper '
                    'rotation per sensor, or none) are refused with `layout = "coils"`.')
        if sec == "workspace":
            doc += (' `shape = "layout"` uses the layout\'s footprint, `"box"` the square of '
                    '`half_width_m`, `"disc"` the circle of `radius_m`; a file that gives '
                    '`half_width_m` without `shape` means `"box"`. `z_max_m` > `z_min_m`.')
        out.append(f"{title}\n\n{doc}\n\n{section_table(sec, cls, docs)}\n")
    out.append(
        "## [[groups]]\n\nCoils whose winding or core differ from `[coil]` / `[core]`; any "
        "number of groups, each coil in at most one.\n\n" + HEADER + "\n"
        + _row("coils", "", Shown("(required)"), "coil indices in [0, n_coils - 1], each in one group "
               "at most", "The coils of the group (the layout's order, from 0).") + "\n"
        + _row("coil", "", Shown("[coil]"), "a table of [coil] keys",
               "The group's winding: the keys given replace the design's `[coil]` values.")
        + "\n"
        + _row("core", "", Shown("[core]"), "a table of [core] keys, or `enabled = false`",
               "The group's core over the design's `[core]`; `enabled = false`: air coils.")
        + "\n")
    out.append(
        "## [[magnets]]\n\nSeveral finger magnets (one on each finger): an array of tables "
        "with the keys of `[magnet]`, the first of which is `[magnet]` (give one form, not "
        "both). Each `name` differs from the others'; at most one magnet for each three coils "
        "(each magnet's force has three components for the coil currents to control).\n")
    out.append("## [asbuilt]\n\nThe device as built (written by `designkit calibrate`, read "
               "by `designkit run --simulate --as-built`; [calibration.md](calibration.md)).\n\n"
               + asbuilt_tables(docs) + "\n")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true",
                    help="exit 1 when docs/design_file.md differs from the generated text")
    a = ap.parse_args(argv)
    text = render()
    if a.check:
        same = TARGET.is_file() and TARGET.read_text() == text
        print("docs/design_file.md is " + ("up to date" if same else
                                           "stale: run python tools/design_file_doc.py"))
        return 0 if same else 1
    TARGET.write_text(text)
    print(f"wrote {TARGET}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
