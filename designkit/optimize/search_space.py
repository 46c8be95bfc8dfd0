"""The device problem's search space: named variables with their bounds, as one value.

The first seven are the coil's (:data:`SEARCH_VARIABLES`); a layout variable (``pitch_m`` of a
grid or hex layout, ``radius_m`` and ``tilt_deg`` of a ring: :data:`LAYOUT_VARIABLES`, the
layout's own design-file keys) may follow, and a candidate's layout is the design's layout with
those keys replaced (:meth:`SearchSpace.layout_of`, :func:`dataclasses.replace`). The bounds
are choices of this optimizer (the module constants), not facts of the device; the
buildability rules they imply are :mod:`designkit.rules`'.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Mapping

from .. import rules
from ..design import Design
from ..design.layouts import Layout
from ..errors import BadInputError

SEARCH_VARIABLES = ("inner_radius_m", "outer_radius_m", "length_m", "core_fill",
                    "core_depth_fraction", "core_protrusion_m", "wire_diameter_m")
"""What the optimizer moves: core radius = core_fill x inner radius (the bore bounds it) and
core length = core_depth_fraction x (winding length + protrusion) (the core's bottom never
below the winding's), so those two limits are bounds, not constraints."""
LAYOUT_VARIABLES = {"grid": ("pitch_m",), "hex": ("pitch_m",)}
"""The layout keys the optimizer may vary, by layout kind."""

MIN_WINDING_LENGTH_M = 0.010
"""Shortest winding searched, m."""
MIN_WINDING_DEPTH_M = 0.2e-3
"""Outer radius at least this above the smallest inner radius, m."""
INNER_RADIUS_MARGIN_M = 0.3e-3
"""Largest inner radius this below the largest outer radius, m."""
CORE_FILL_BOUNDS = (0.25, 1.0)
"""Core radius / inner radius."""
CORE_DEPTH_BOUNDS = (0.1, 1.0)
"""Core length / (winding length + protrusion)."""
MIN_PROTRUSION_BOUND_M = 1e-4
"""Smallest upper bound of the core protrusion, m (keeps the box non-empty)."""
WIRE_BOUNDS_M = (0.20e-3, 1.60e-3)
"""Bare wire diameter, m: the ends of the IEC 60317 metric table."""
PITCH_RANGE_FACTOR = 0.6
"""Default smallest pitch searched, as a fraction of the design's pitch."""
MIN_PITCH_WINDING_DEPTH_M = 0.5e-3
"""Default smallest pitch: coils of the smallest inner radius this deep, m."""


@dataclass(frozen=True)
class Variable:
    """One search variable: its name (SI unit in the suffix) and bounds."""

    name: str
    lower: float
    upper: float


@dataclass(frozen=True)
class SearchSpace:
    """The search variables in order: the coil's seven, then the layout's."""

    variables: tuple[Variable, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(q.name for q in self.variables)

    @property
    def lower(self) -> tuple[float, ...]:
        return tuple(q.lower for q in self.variables)

    @property
    def upper(self) -> tuple[float, ...]:
        return tuple(q.upper for q in self.variables)

    @property
    def layout_names(self) -> tuple[str, ...]:
        """The layout keys among the variables (after the coil's seven)."""
        return self.names[len(SEARCH_VARIABLES):]

    def bounds(self, name: str) -> tuple[float, float] | None:
        """(lower, upper) of a variable, or None when it is not searched."""
        for q in self.variables:
            if q.name == name:
                return (q.lower, q.upper)
        return None

    def layout_of(self, base: Layout, x) -> Layout:
        """``base`` with the layout variables of ``x`` (a vector of this space, or the coil's
        seven alone: then ``base`` itself)."""
        extra = list(x[len(SEARCH_VARIABLES):])
        if not extra or not self.layout_names:
            return base
        return dataclasses.replace(base, **{n: float(v) for n, v in
                                            zip(self.layout_names, extra)})

    def checked(self) -> "SearchSpace":
        """This space, every bound finite with 0 <= lower < upper (BadInputError naming the
        variable otherwise)."""
        for q in self.variables:
            if not (math.isfinite(q.lower) and math.isfinite(q.upper) and 0 <= q.lower < q.upper):
                raise BadInputError(f"bounds of {q.name}", "0 <= lower < upper (finite, m)",
                                    (q.lower, q.upper))
        return self


def _array_pitch(design: Design) -> float:
    """The design's pitch, m (1 m for a single coil: no neighbour to overlap)."""
    return design.array.pitch_m if design.n_coils > 1 else 1.0


def _pitch_bounds(design: Design, coil_clearance_m: float,
                  pitch_range_m: tuple[float, float] | None) -> tuple[float, float]:
    """Checked (lo, hi) of a varying pitch, m (default: :func:`device_space`)."""
    o, pitch = design.optimize, _array_pitch(design)
    if design.n_coils < 2:
        raise BadInputError("array", "at least 2 coils when the pitch varies",
                            design.n_coils)
    if pitch_range_m is None:
        pitch_range_m = (max(PITCH_RANGE_FACTOR * pitch, 2 * o.min_inner_radius_m
                             + 2 * MIN_PITCH_WINDING_DEPTH_M + coil_clearance_m),
                         max(pitch, 2 * o.max_outer_radius_m + coil_clearance_m))
    lo_p, hi_p = (float(q) for q in pitch_range_m)
    smallest = 2 * o.min_inner_radius_m + 2 * MIN_WINDING_DEPTH_M + coil_clearance_m
    if not (math.isfinite(lo_p) and math.isfinite(hi_p) and smallest < lo_p < hi_p):
        raise BadInputError(
            "pitch_range_m", f"finite lo < hi with lo > 2 x min inner radius + "
            f"{2 * MIN_WINDING_DEPTH_M * 1e3:g} mm + clearance ({smallest:.4g} m)", pitch_range_m)
    return lo_p, hi_p


def device_space(design: Design, vary: Mapping[str, tuple[float, float] | None],
                 coil_clearance_m: float, board_clearance_m: float) -> SearchSpace:
    """The device problem's search space on ``design``.

    ``vary``: layout keys to search ({name: (lo, hi) or None for the default range}; the
    pitch's default: from 0.6 x the design's pitch to 2 x optimize.max_outer_radius_m +
    coil_clearance_m, or the design's pitch if larger). Coil bounds: inner radius
    [optimize.min_inner_radius_m, Ro bound - 0.3 mm]; outer radius up to
    (widest pitch - coil_clearance_m)/2 (no overlap at the pitch); winding length
    [10 mm, optimize.max_length_m]; core fill [0.25, 1]; core depth fraction [0.1, 1];
    protrusion above the winding [0, the upper sensor board's underside - board_clearance_m];
    bare wire [0.2, 1.6] mm.
    """
    allowed = LAYOUT_VARIABLES.get(design.array.kind, ())
    for name in vary:
        if name not in allowed:
            raise BadInputError(f"layout variable for layout '{design.array.kind}'",
                                f"one of {list(allowed)}" if allowed else
                                "none (this layout has no variable the optimizer searches)",
                                name)
    layout_vars = []
    if "pitch_m" in vary:
        lo_p, hi_p = _pitch_bounds(design, coil_clearance_m, vary["pitch_m"])
        layout_vars.append(Variable("pitch_m", lo_p, hi_p))
    o = design.optimize
    widest = layout_vars[0].upper if layout_vars else _array_pitch(design)
    r_out = min(0.5 * (widest - coil_clearance_m), o.max_outer_radius_m)
    # buildability (designkit.rules): the core top stays below the upper sensor mount
    max_prot = max(min(design.sensors.offset_m - board_clearance_m,
                       rules.max_core_protrusion_m(design)), MIN_PROTRUSION_BOUND_M)
    lower = (o.min_inner_radius_m, o.min_inner_radius_m + MIN_WINDING_DEPTH_M,
             MIN_WINDING_LENGTH_M, CORE_FILL_BOUNDS[0], CORE_DEPTH_BOUNDS[0], 0.0,
             WIRE_BOUNDS_M[0])
    upper = (r_out - INNER_RADIUS_MARGIN_M, r_out, o.max_length_m, CORE_FILL_BOUNDS[1],
             CORE_DEPTH_BOUNDS[1], max_prot, WIRE_BOUNDS_M[1])
    coil_vars = tuple(Variable(n, lo, hi) for n, lo, hi in zip(SEARCH_VARIABLES, lower, upper))
    return SearchSpace(coil_vars + tuple(layout_vars))
