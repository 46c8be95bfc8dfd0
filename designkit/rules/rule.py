"""One rule of the rule book evaluated on a design: value, limit, the keys that fix it."""

from __future__ import annotations

from dataclasses import dataclass

TOLERANCE_M = 1e-9
"""Round-off allowed on a geometric rule, m (a rule met with equality holds)."""


@dataclass(frozen=True)
class Rule:
    """One rule evaluated on a design: ``value <= limit`` (kind 'upper') or ``>=`` ('lower')."""

    name: str
    value: float
    limit: float
    unit: str
    kind: str
    keys: tuple[str, ...]
    """Design keys (``section.field``) that change the outcome."""
    what: str
    fix: str
    """The sentence that says how to fix a violation."""
    tolerance: float = TOLERANCE_M
    group: str = "cad"
    """'cad': a rule of the printed assembly (``cad`` refuses the design); 'device': of the
    device's electrics and workspace (reported, not a reason to refuse printing)."""

    @property
    def margin(self) -> float:
        """limit - value ('upper') or value - limit ('lower'); >= 0 when met, in ``unit``."""
        return self.limit - self.value if self.kind == "upper" else self.value - self.limit

    @property
    def met(self) -> bool:
        return bool(self.margin >= -self.tolerance)

    @property
    def message(self) -> str:
        """``what`` with the numbers and the fix (lengths in mm)."""
        scale, unit = (1e3, "mm") if self.unit == "m" else (1.0, self.unit)
        rel = ">" if self.kind == "upper" else "<"
        return (f"{self.what}: {self.value * scale:.4g} {unit} {rel} the limit "
                f"{self.limit * scale:.4g} {unit}; {self.fix}.")

    def as_dict(self) -> dict:
        """The row of a constraint table (as :meth:`DeviceProblem.constraint_table`)."""
        return {"value": float(self.value), "limit": float(self.limit), "unit": self.unit,
                "kind": self.kind, "margin": float(self.margin), "met": self.met,
                "note": self.what, "keys": list(self.keys), "group": self.group}


def wall(name: str, what: str, value: float, min_wall_m: float, keys, fix: str) -> Rule:
    """A printed wall at least the printer's minimum (``cad.min_wall_m``), m."""
    return Rule(name, value, min_wall_m, "m", "lower", tuple(keys) + ("cad.min_wall_m",),
                f"{what} (printer minimum wall)", fix)
