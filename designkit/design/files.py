"""Design files: TOML in and out, and the designs shipped by name (``--design optimized``).

A design file holds the tables of :class:`designkit.design.Design` (``[coil]``, ``[core]``,
``[array]``, ...); missing keys take the default design's values, unknown keys are errors.
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
from dataclasses import fields
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from ..errors import BadInputError
from .asbuilt import asbuilt_from_dict
from .layouts import layout_from_table, layout_to_table
from .spec import Design, default_design
from .tables import SECTIONS, CoilGroup, CoilSpec, CoreSpec, MagnetSpec, implied_shape


def design_from_dict(data: Mapping[str, Any], *, source: str = "design") -> Design:
    """Build a Design from a nested mapping (the TOML layout); unknown keys are errors."""
    kwargs: dict[str, Any] = {}
    groups = None
    for key, value in data.items():
        if key == "name":
            kwargs["name"] = value  # type-checked in check_design: 5 is not silently "5"
        elif key == "asbuilt":
            kwargs["asbuilt"] = asbuilt_from_dict(value, source)
        elif key == "groups":
            groups = value
        elif key == "magnets":
            if "magnet" in data:
                raise BadInputError(f"{source}: [magnet] and [[magnets]]", "one of the two "
                                    "([[magnets]] lists every magnet, the first is [magnet])",
                                    "both")
            kwargs.update(_magnets(value, source))
        elif key in SECTIONS:
            if not isinstance(value, Mapping):
                raise BadInputError(f"{source}: [{key}]", "a table", value)
            if key == "array":
                kwargs["array"] = layout_from_table(dict(value), source)
            elif key == "core" and value.get("enabled", True) is False:
                kwargs["core"] = None
            else:
                kwargs[key] = _section(key, SECTIONS[key], value, source)
        else:
            raise BadInputError(f"{source}: top-level key",
                                f"'name', 'groups', 'magnets' or one of the tables "
                                f"{sorted(SECTIONS)}", key)
    if groups is not None:
        kwargs["groups"] = _groups(groups, kwargs.get("coil", CoilSpec()),
                                   kwargs.get("core", CoreSpec()), source)
    return Design(**kwargs)


def _section(key: str, cls: type, value: Mapping[str, Any], source: str,
             base: Any = None) -> Any:
    """One table as its dataclass; missing keys from ``base`` (default: the class's)."""
    allowed = {f.name for f in fields(cls)}
    unknown = set(value) - allowed - ({"enabled"} if key.endswith("core") else set())
    if unknown:
        raise BadInputError(f"{source}: [{key}] key", f"one of {sorted(allowed)}",
                            sorted(unknown)[0])
    values = {k: _tuples(val) for k, val in value.items() if k != "enabled"}
    if key == "workspace":
        values = implied_shape(values)
    if base is not None:
        return dataclasses.replace(base, **values)
    return cls(**values)


def _magnets(tables: Any, source: str) -> dict[str, Any]:
    """``[[magnets]]``: the first is ``magnet``, the rest ``other_magnets``."""
    if not isinstance(tables, list) or not tables or not all(
            isinstance(t, Mapping) for t in tables):
        raise BadInputError(f"{source}: magnets", "a non-empty array of tables ([[magnets]])",
                            tables)
    specs = [_section(f"magnets[{k}]", MagnetSpec, t, source) for k, t in enumerate(tables)]
    return {"magnet": specs[0], "other_magnets": tuple(specs[1:])}


def _tuples(value: Any) -> Any:
    """TOML arrays (lists, nested) as tuples: the spec is immutable and hashable."""
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value


def _groups(tables: Any, coil: CoilSpec, core: CoreSpec | None, source: str) -> tuple:
    """``[[groups]]``: each a coil list with partial ``coil`` / ``core`` tables over the
    design's own."""
    if not isinstance(tables, list) or not all(isinstance(t, Mapping) for t in tables):
        raise BadInputError(f"{source}: groups", "an array of tables ([[groups]])", tables)
    out = []
    for g, t in enumerate(tables):
        where = f"{source}: groups[{g}]"
        unknown = set(t) - {"coils", "coil", "core"}
        if unknown:
            raise BadInputError(f"{where} key", "one of ['coils', 'coil', 'core']",
                                sorted(unknown)[0])
        coils = t.get("coils")
        if not isinstance(coils, list) or not coils:
            raise BadInputError(f"{where}.coils", "a non-empty list of coil indices", coils)
        g_core = core
        core_table = t.get("core", {})
        if core_table.get("enabled", True) is False:
            g_core = None
        elif core_table:
            g_core = _section(f"groups[{g}].core", CoreSpec, core_table, source,
                              core if core is not None else CoreSpec())
        g_coil = _section(f"groups[{g}].coil", CoilSpec, t.get("coil", {}), source, coil)
        out.append(CoilGroup(tuple(coils), g_coil, g_core))
    return tuple(out)


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
    for sec in SECTIONS:
        obj = getattr(design, sec)
        if sec == "magnet" and design.other_magnets:
            for magnet in design.magnets:
                lines.append("[[magnets]]")
                lines += [f"{f.name} = {json.dumps(getattr(magnet, f.name))}"
                          for f in fields(magnet)]
                lines.append("")
            continue
        lines.append(f"[{sec}]")
        table = (layout_to_table(obj) if sec == "array" else
                 {"enabled": False} if obj is None else
                 {f.name: getattr(obj, f.name) for f in fields(obj)})
        lines += [f"{k} = {json.dumps(val)}" for k, val in table.items()]
        lines.append("")
    for group in design.groups:
        lines += ["[[groups]]", f"coils = {json.dumps(list(group.coils))}", "[groups.coil]"]
        lines += [f"{f.name} = {json.dumps(getattr(group.coil, f.name))}"
                  for f in fields(group.coil)]
        lines.append("[groups.core]")
        lines += (["enabled = false"] if group.core is None else
                  [f"{f.name} = {json.dumps(getattr(group.core, f.name))}"
                   for f in fields(group.core)])
        lines.append("")
    if design.asbuilt is not None:
        lines.append(design.asbuilt.to_toml())
    return "\n".join(lines)
