"""cad's refusal: the rule book's buildability rules (:mod:`designkit.rules`) on a design.

The rules are defined once, in designkit, as arithmetic on the design (no build123d), so a
bad design fails here at once with a message that names the numbers and the design key that
fixes it; the same rules bound the optimizer and fill ``designkit check`` and ``report``. The
geometric interference check of the built assembly (:func:`cad.assembly.interferences`)
backs them up; :func:`fit_in_build_volume` is the one printer rule that needs the parts.
"""

from __future__ import annotations

from designkit import rules as rule_book
from designkit.errors import DesignRuleError

from .params import CadParams, fit_in_build_volume

__all__ = ["check_rules", "fit_in_build_volume", "violations"]


def violations(p: CadParams) -> list[str]:
    """Every violated buildability rule as a sentence that suggests the fix (empty: all good)."""
    return [r.message for r in rule_book.violations(p.design, group="cad")]


def check_rules(p: CadParams) -> None:
    """Raise :class:`DesignRuleError` listing every violated rule (with its fix), or return."""
    bad = violations(p)
    if bad:
        raise DesignRuleError(f"{len(bad)} design rule(s) violated for '{p.design_name}' "
                              "(designkit check --design FILE prints them all):\n  - "
                              + "\n  - ".join(bad))
