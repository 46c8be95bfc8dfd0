"""``designkit check``: the whole rule table of a design, and whether it can be built.

Prints every rule of the rule book (:mod:`designkit.rules`) and every device constraint
(:func:`designkit.optimize.rule_table`: a cored design's under the saturating panel model, an
air-core design's R, I R, 5 L/R and heating with the closed-form air-core inductance): value,
limit, margin (>= 0 is met), the design keys that fix it. The same table decides
``optimize`` (its bounds), ``report`` (its "violates" line) and ``cad`` (its refusal: the
rules of group 'cad'). Any layout: coils in their poses (docs/rules.md). Then, per Hall sensor,
the coil currents that take it out of its linear range (:func:`designkit.rules.sensor_saturation`:
reported, not a rule -- the runner leaves out a sensor it predicts beyond 80 % of its range).
Exit codes: :data:`EXIT_MET` when every row is met, :data:`EXIT_VIOLATED` when one is violated
(the row names the design keys that fix it), 1 on bad input (a design file that cannot be read
or is refused: one line naming the key, its value and the valid range).
"""

from __future__ import annotations

import argparse

from ..design import load_design
from ..errors import BadInputError
from ..optimize import rule_table
from ..rules import sensor_saturation
from .common import add_design_argument, add_progress_argument, shown_margin

EXIT_MET = 0
"""Every rule of the design holds."""
EXIT_VIOLATED = 3
"""At least one rule is violated (bad input is 1, as for every command)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_design_argument(parser)
    add_progress_argument(parser)


def _number(value: float, unit: str) -> str:
    """Lengths in mm, round-off (|x| < 1e-12 of the unit) printed as 0."""
    scale, shown = (1e3, "mm") if unit == "m" else (1.0, unit)
    x = value * scale
    return f"{0.0 if abs(x) < 1e-9 else x:.5g} {shown}".rstrip()


def table_text(name: str, table: dict) -> str:
    """The rule table as aligned text (one row per rule, lengths in mm)."""
    rows = [("rule", "group", "value", "limit", "margin", "ok", "fixed by")]
    for rule, r in table.items():
        sign = "<=" if r["kind"] == "upper" else ">="
        rows.append((rule, r.get("group", "device"), _number(r["value"], r["unit"]),
                     f"{sign} {_number(r['limit'], r['unit'])}", _number(shown_margin(r), r["unit"]),
                     "ok" if r["met"] else "VIOLATED", ", ".join(r.get("keys", [])) or "-"))
    widths = [max(len(row[k]) for row in rows) for k in range(6)]
    lines = [f"design '{name}': {len(table)} rules (margin >= 0 is met)"]
    for row in rows:
        lines.append("  ".join(c.ljust(w) for c, w in zip(row[:6], widths)) + "  " + row[6])
    bad = [n for n, r in table.items() if not r["met"]]
    cad_bad = [n for n in bad if table[n].get("group") == "cad"]
    lines.append(f"violated: {', '.join(bad) or 'none'}; buildable by designkit cad: "
                 f"{'no (' + ', '.join(cad_bad) + ')' if cad_bad else 'yes'}")
    return "\n".join(lines)


def saturation_text(design, rows: list) -> str:
    """The sensors' saturation currents as aligned text (positions in mm), and which sensors
    the design's own current limit can blind."""
    limit = design.drive.max_current_a
    lines = [f"sensor saturation (TLV493D linear range +-{design.sensors.range_t * 1e3:g} mT per "
             "axis, the coils' field alone; the runner leaves out a sensor it predicts beyond "
             "80 % of it):",
             "  sensor  position (mm)              one coil alone     all coils, worst signs"]
    for r in rows:
        pos = ", ".join(f"{1e3 * x:6.1f}" for x in r["position_m"])
        lines.append(f"  {r['sensor']:6d}  ({pos})  {r['one_coil_a']:6.2f} A (coil {r['coil']})"
                     f"  {r['all_coils_a']:6.2f} A")
    one = [r["sensor"] for r in rows if r["one_coil_a"] < limit]
    worst = [r["sensor"] for r in rows if r["all_coils_a"] < limit]
    lines.append(f"at the design's {limit:g} A per coil: one coil alone blinds sensors "
                 f"{one or 'none'}; some pattern of all coils blinds sensors {worst or 'none'}")
    return "\n".join(lines)


def saturation_of(design) -> str:
    """:func:`saturation_text` of the design's sensors, or the one line saying why there is
    none: a sensor inside a coil's iron has no field model (the model refuses it), and the
    rule table above already names the rule it breaks and the keys that fix it."""
    try:
        rows = sensor_saturation(design)
    except BadInputError as exc:
        return f"sensor saturation: not evaluated ({exc})"
    return saturation_text(design, rows)


def run(args: argparse.Namespace) -> int:
    design = load_design(args.design)
    table = rule_table(design)
    print(table_text(design.name, table))
    print(saturation_of(design))
    return EXIT_MET if all(r["met"] for r in table.values()) else EXIT_VIOLATED
