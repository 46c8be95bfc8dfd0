"""Input checks at the public edge. Kernels never check; these functions do, once."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import BadInputError


def _number(name: str, value: Any, unit: str, what: str, ok) -> float:
    """``value`` as a finite float for which ``ok(v)`` holds, else BadInputError naming
    ``what`` ("a finite number > 0", ...) and the unit."""
    valid = f"{what} {unit}".rstrip()
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise BadInputError(name, valid, value) from None
    if not (math.isfinite(v) and ok(v)):
        raise BadInputError(name, valid, value)
    return v


def positive(name: str, value: Any, unit: str = "m") -> float:
    """Return ``value`` as float, or raise if it is not a finite number > 0."""
    return _number(name, value, unit, "a finite number > 0", lambda v: v > 0.0)


def nonnegative(name: str, value: Any, unit: str = "m") -> float:
    return _number(name, value, unit, "a finite number >= 0", lambda v: v >= 0.0)


def finite(name: str, value: Any, unit: str = "") -> float:
    return _number(name, value, unit, "a finite number", lambda v: True)


def in_range(name: str, value: Any, low: float, high: float, unit: str = "",
             *, low_open: bool = False, high_open: bool = False) -> float:
    v = finite(name, value, unit)
    lo_ok = v > low if low_open else v >= low
    hi_ok = v < high if high_open else v <= high
    if not (lo_ok and hi_ok):
        lb = "(" if low_open else "["
        hb = ")" if high_open else "]"
        raise BadInputError(name, f"in {lb}{low:g}, {high:g}{hb} {unit}".rstrip(), value)
    return v


def positive_int(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer, float)):
        raise BadInputError(name, "a whole number > 0", value)
    if isinstance(value, float) and not value.is_integer():
        raise BadInputError(name, "a whole number > 0", value)
    if int(value) <= 0:
        raise BadInputError(name, "a whole number > 0", value)
    return int(value)


def points(value: Any, name: str = "points") -> tuple[np.ndarray, bool]:
    """Return ``(P, single)``: P of shape (n, 3) float64 in metres; single if input was (3,)."""
    try:
        p = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise BadInputError(name, "array-like of shape (3,) or (n, 3), m", type(value).__name__) from None
    single = p.ndim == 1
    if single:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 3:
        raise BadInputError(name, "array-like of shape (3,) or (n, 3), m", f"shape {np.shape(value)}")
    if not np.all(np.isfinite(p)):
        bad = np.argwhere(~np.isfinite(p))[0]
        raise BadInputError(name, "finite (no NaN or Inf)",
                            f"{p[bad[0], bad[1]]} at row {bad[0]}, column {bad[1]}")
    return p, single


def vector3(name: str, value: Any, unit: str = "") -> np.ndarray:
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise BadInputError(name, f"a finite 3-vector {unit}".rstrip(), value) from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise BadInputError(name, f"a finite 3-vector {unit}".rstrip(), value)
    return v
