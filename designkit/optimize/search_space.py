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

import numpy as np

from .. import rules
from ..design import Design
from ..design.layouts import Layout
from ..errors import BadInputError

SEARCH_VARIABLES = ("inner_radius_m", "outer_radius_m", "length_m", "core_fill",
                    "core_depth_fraction", "core_protrusion_m", "wire_diameter_m")
"""What the optimizer moves: core radius = core_fill x inner radius (the bore bounds it) and
core length = core_depth_fraction x (winding length + protrusion) (the core's bottom never
below the winding's), so those two limits are bounds, not constraints."""
LAYOUT_VARIABLES = {"grid": ("pitch_m",), "hex": ("pitch_m",), "ring": ("radius_m", "tilt_deg")}
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


def chord_factor(n: int) -> float:
    """Distance of neighbouring top centres of a ring of ``n`` / its radius: 2 sin(pi / n)
    (1 for one coil)."""
    return 2 * math.sin(math.pi / n) if n > 1 else 1.0


def nearest_spacing_m(design: Design) -> float:
    """Distance of the nearest two top-face centres, m: the pitch of a grid or hex lattice,
    1 m for a single coil."""
    if design.n_coils < 2:
        return 1.0
    if design.array.kind in ("grid", "hex"):
        return design.array.pitch_m
    t = design.array.top_centres_m()
    d = np.linalg.norm(t[:, None, :] - t[None, :, :], axis=-1)
    return float(d[np.triu_indices(len(t), 1)].min())


def _spacing_range(design: Design, name: str, coil_clearance_m: float,
                   given: tuple[float, float] | None) -> tuple[float, float]:
    """Checked (lo, hi) of a varying pitch or ring radius, m (defaults: :func:`device_space`)."""
    o = design.optimize
    if design.n_coils < 2:
        raise BadInputError("array", f"at least 2 coils when {name} varies", design.n_coils)
    scale = 1.0 if name == "pitch_m" else chord_factor(design.array.count)
    value = getattr(design.array, name)
    if given is None:
        given = (max(PITCH_RANGE_FACTOR * value, (2 * o.min_inner_radius_m
                                                  + 2 * MIN_PITCH_WINDING_DEPTH_M
                                                  + coil_clearance_m) / scale),
                 max(value, (2 * o.max_outer_radius_m + coil_clearance_m) / scale))
    lo, hi = (float(q) for q in given)
    smallest = (2 * o.min_inner_radius_m + 2 * MIN_WINDING_DEPTH_M + coil_clearance_m) / scale
    if not (math.isfinite(lo) and math.isfinite(hi) and smallest < lo < hi):
        raise BadInputError(
            f"{name} range", f"finite lo < hi (m) with lo > {smallest:.4g} m (neighbours of the "
            f"smallest inner radius, {2 * MIN_WINDING_DEPTH_M * 1e3:g} mm of winding and the "
            "clearance)", given)
    return lo, hi


def _tilt_range(given: tuple[float, float] | None) -> tuple[float, float]:
    """Checked (lo, hi) of a varying ring tilt, degrees (default: upright to the printable
    limit, :data:`designkit.rules.MAX_OVERHANG_DEG`)."""
    lo, hi = (0.0, rules.MAX_OVERHANG_DEG) if given is None else (float(q) for q in given)
    if not (math.isfinite(lo) and math.isfinite(hi) and 0.0 <= lo < hi < 90.0):
        raise BadInputError("tilt_deg range", "0 <= lo < hi < 90 (degrees)", given)
    return lo, hi


def device_space(design: Design, vary: Mapping[str, tuple[float, float] | None],
                 coil_clearance_m: float, board_clearance_m: float) -> SearchSpace:
    """The device problem's search space on ``design``.

    ``vary``: layout keys to search ({name: (lo, hi) or None for the default range}; the
    pitch's default: from 0.6 x the design's pitch to 2 x optimize.max_outer_radius_m +
    coil_clearance_m, or the design's pitch if larger; a ring's radius: the same for the
    distance of neighbouring coils, 2 r sin(pi / count); its tilt: 0 to
    :data:`designkit.rules.MAX_OVERHANG_DEG`). Coil bounds: inner radius
    [optimize.min_inner_radius_m, Ro bound - 0.3 mm]; outer radius up to
    (widest spacing - coil_clearance_m)/2; winding length [10 mm, optimize.max_length_m];
    core fill [0.25, 1]; core depth fraction [0.1, 1]; protrusion above the winding [0, the
    upper sensor board's underside - board_clearance_m]; bare wire [0.2, 1.6] mm.
    """
    allowed = LAYOUT_VARIABLES.get(design.array.kind, ())
    for name in vary:
        if name not in allowed:
            raise BadInputError(f"layout variable for layout '{design.array.kind}'",
                                f"one of {list(allowed)}" if allowed else
                                "none (this layout has no variable the optimizer searches)",
                                name)
    layout_vars = []
    widest = nearest_spacing_m(design)
    for name in allowed:  # in the layout's order
        if name not in vary:
            continue
        if name == "tilt_deg":
            layout_vars.append(Variable(name, *_tilt_range(vary[name])))
            continue
        lo, hi = _spacing_range(design, name, coil_clearance_m, vary[name])
        layout_vars.append(Variable(name, lo, hi))
        widest = hi * (1.0 if name == "pitch_m" else chord_factor(design.array.count))
    o = design.optimize
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
