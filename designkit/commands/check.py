"""``designkit check``: the whole rule table of a design, and whether it can be built.

Prints every rule of the rule book (:mod:`designkit.rules`) and, for a cored design, every
device constraint under the saturating panel model (:func:`designkit.optimize.rule_table`):
value, limit, margin (>= 0 is met), the design keys that fix it. The same table decides
``optimize`` (its bounds), ``report`` (its "violates" line) and ``cad`` (its refusal: the
rules of group 'cad'). Any layout: coils in their poses (docs/rules.md). Exit codes:
:data:`EXIT_MET` when every row is met, :data:`EXIT_VIOLATED` when one is violated (the row
names the design keys that fix it), 1 on bad input (a design file that cannot be read or is
refused: one line naming the key, its value and the valid range).
"""

from __future__ import annotations

import argparse

from ..design import load_design
from ..optimize import rule_table
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


def run(args: argparse.Namespace) -> int:
    design = load_design(args.design)
    table = rule_table(design)
    print(table_text(design.name, table))
    if design.core is None:
        print("no core: the device constraints (R, I R, 5 L/R, heating) are those of the "
              "iron-core device problem and were not evaluated")
    return EXIT_MET if all(r["met"] for r in table.values()) else EXIT_VIOLATED
