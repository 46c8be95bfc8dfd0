"""Design files: TOML in and out, and the designs shipped by name (``--design optimized``).

A design file holds the tables of :class:`designkit.design.Design` (``[coil]``, ``[core]``,
``[array]``, ...); missing keys take the default design's values, unknown keys are errors.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import fields
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from ..errors import BadInputError
from .asbuilt import asbuilt_from_dict
from .spec import SECTIONS, Design, default_design


def design_from_dict(data: Mapping[str, Any], *, source: str = "design") -> Design:
    """Build a Design from a nested mapping (the TOML layout); unknown keys are errors."""
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        if key == "name":
            kwargs["name"] = value  # type-checked in check_design: 5 is not silently "5"
        elif key == "asbuilt":
            kwargs["asbuilt"] = asbuilt_from_dict(value, source)
        elif key in SECTIONS:
            if key == "core" and (value is False or value == {} and False):
                kwargs["core"] = None
                continue
            if not isinstance(value, Mapping):
                raise BadInputError(f"{source}: [{key}]", "a table", value)
            if key == "core" and value.get("enabled", True) is False:
                kwargs["core"] = None
                continue
            cls = SECTIONS[key]
            allowed = {f.name for f in fields(cls)}
            unknown = set(value) - allowed - ({"enabled"} if key == "core" else set())
            if unknown:
                raise BadInputError(f"{source}: [{key}] key", f"one of {sorted(allowed)}",
                                    sorted(unknown)[0])
            kwargs[key] = cls(**{k: val for k, val in value.items() if k != "enabled"})
        else:
            raise BadInputError(f"{source}: top-level key",
                                f"'name' or one of the tables {sorted(SECTIONS)}", key)
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
    for sec in SECTIONS:
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
