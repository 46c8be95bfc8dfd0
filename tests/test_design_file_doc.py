"""docs/design_file.md, the design-file reference, cannot rot: it is what
tools/design_file_doc.py generates from the design package (keys, defaults, field docs and
the checks' ranges), it names every key of the spec, and the ranges it states for the layouts
(written in the generator, not derived) are the ones the checks apply."""

from __future__ import annotations

import dataclasses
import importlib.util
import re
import sys

import pytest
from conftest import ROOT

from designkit.design import SECTIONS, asbuilt, default_design, design_from_dict, layouts
from designkit.errors import BadInputError

_spec = importlib.util.spec_from_file_location("tools_design_file_doc",
                                               ROOT / "tools" / "design_file_doc.py")
doc_tool = importlib.util.module_from_spec(_spec)
sys.modules["tools_design_file_doc"] = doc_tool
_spec.loader.exec_module(doc_tool)

DOC = ROOT / "docs" / "design_file.md"


def test_the_committed_reference_is_the_generated_one():
    assert DOC.read_text() == doc_tool.render(), \
        "docs/design_file.md is stale: run python tools/design_file_doc.py"


def _documented() -> dict:
    """{table heading: set of keys in its rows} of the reference."""
    out, heading = {}, None
    for line in DOC.read_text().splitlines():
        if line.startswith("## "):
            heading = line[3:].strip()
        m = re.match(r"\| `([a-z_]+)` \|", line)
        if m and heading:
            out.setdefault(heading, set()).add(m.group(1))
    return out


def test_every_key_of_the_spec_is_documented():
    seen = _documented()
    assert "name" in seen["Top level"]
    for sec, cls in SECTIONS.items():
        if sec == "array":
            continue
        missing = {f.name for f in dataclasses.fields(cls)} - seen[f"[{sec}]"]
        assert not missing, (sec, missing)
    layout_keys = {k for keys in layouts.LAYOUT_KEYS.values() for k in keys}
    assert layout_keys <= seen["[array]"]
    for kind, cls in layouts.LAYOUTS.items():  # every layout field is a design-file key
        names = {"axes" if f.name == "axis_vectors" else f.name for f in dataclasses.fields(cls)}
        assert names == set(layouts.LAYOUT_KEYS[kind]), kind
    assert {"coils", "coil", "core"} <= seen["[[groups]]"]
    for cls in (asbuilt.BuildTolerances, asbuilt.CoilDeviation):
        assert {f.name for f in dataclasses.fields(cls)} <= seen["[asbuilt]"]
    # the design's own top-level fields: each one a table or key of the reference
    tops = {f.name for f in dataclasses.fields(default_design())}
    assert tops <= set(SECTIONS) | {"name", "groups", "asbuilt", "other_magnets"}
    assert "## [[magnets]]" in DOC.read_text()


def test_every_default_shown_is_the_default_design():
    d = default_design()
    text = DOC.read_text()
    for sec, cls in SECTIONS.items():
        if sec == "array":
            continue
        for f in dataclasses.fields(cls):
            shown = doc_tool._toml(getattr(getattr(d, sec), f.name))
            assert f"| `{f.name}` | {doc_tool.unit_of(f.name) or '-'} | {shown} |" in text, \
                (sec, f.name)


@pytest.mark.parametrize("kind,key,bad,good", [
    ("grid", "rows", 0, 1), ("grid", "columns", 0, 2), ("grid", "pitch_m", 0.0, 0.06),
    ("hex", "rings", -1, 0), ("hex", "pitch_m", -0.01, 0.05),
    ("ring", "count", 0, 1), ("ring", "radius_m", 0.0, 0.08),
    ("ring", "tilt_deg", 90.0, 89.0), ("ring", "tilt_deg", -1.0, 0.0),
    ("free", "footprint_margin_m", -0.001, 0.0),
])
def test_the_layout_ranges_stated_are_the_ones_checked(kind, key, bad, good):
    assert key in doc_tool.LAYOUT_RULES[kind]
    table = {"layout": kind, key: good}
    if kind == "ring" and key != "radius_m":
        table["radius_m"] = 0.2  # room for the coils at any count
    if kind == "grid" and key != "pitch_m":
        table["pitch_m"] = 0.2
    design_from_dict({"array": table})
    with pytest.raises(BadInputError, match=f"array.{key}"):
        design_from_dict({"array": {**table, key: bad}})


def test_the_generator_can_say_the_file_is_stale(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(doc_tool, "TARGET", tmp_path / "design_file.md")
    (tmp_path / "design_file.md").write_text("old\n")
    assert doc_tool.main(["--check"]) == 1
    assert "stale" in capsys.readouterr().out
    assert doc_tool.main([]) == 0 and doc_tool.main(["--check"]) == 0
