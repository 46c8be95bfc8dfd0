"""The real device's coil problem: winding, wire and 1010-steel core optimized together.

Search variables (:data:`SEARCH_VARIABLES`): the winding's inner/outer radius and length, core
fill (core radius / inner radius), core depth fraction (core length / (winding length +
protrusion)), core protrusion above the winding top, bare wire diameter (continuous; the
solver then picks a neighbouring IEC 60317 size), optionally the array pitch. Constraints
(:data:`DEVICE_CONSTRAINTS`, each with its margin): R at the hot limit < Rmax, I R(hot) <=
the driver's rating, 5 L_secant / R(cold) < T, adiabatic time from cold to hot at the
rendering duty >= its minimum, a winding at least one wire deep; with a varying pitch also
2 Ro + clearance <= pitch. Objective: the upward force on the axis at the design height, or
the smallest upward force the array renders over the workspace region (:mod:`.rendering`).
Models: the closed-form winding gradient (:mod:`.axial_kernel`), the exact Bessel air
inductance, the core by the fast slice model of :mod:`designkit.cores.rod` (corrected by the
surface-current panel model of :mod:`designkit.cores`). Details: docs/optimize.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import rules
from ..cores.panel import Core
from ..cores.rod import solve_rods
from ..design import Design
from ..errors import BadInputError
from ..model import electrical as el
from ..model.coil import Coil
from ..support import validate as v
from .axial_kernel import axial_gradient_per_current_density
from .design_view import DesignView
from .rendering import array_render_forces
from .wire_table import GRADE1_INSULATION_RATIO, METRIC_DIAMETERS_M
from .workspace import fold_points, workspace_region

DEVICE_VARIABLES = ("inner_radius_m", "outer_radius_m", "length_m", "core_radius_m",
                    "core_length_m", "core_protrusion_m", "wire_diameter_m")
DEVICE_CONSTRAINTS = ("resistance_ohm", "supply_voltage_v", "settling_time_s",
                      "time_to_max_temperature_s", "winding_depth_m")
DEVICE_OBJECTIVES = ("design-point", "rendering")
PITCH_VARIABLE = "pitch_m"
"""The optional 8th search (and physical) variable, :attr:`DeviceProblem.pitch_bounds_m`."""
SEARCH_VARIABLES = ("inner_radius_m", "outer_radius_m", "length_m", "core_fill",
                    "core_depth_fraction", "core_protrusion_m", "wire_diameter_m")
"""What the optimizer moves: core radius = core_fill x inner radius (the bore bounds it) and
core length = core_depth_fraction x (winding length + protrusion) (the core's bottom never
below the winding's), so those two limits are bounds, not constraints."""

# stated operating conditions (defaults of DeviceProblem.from_design)
HOT_TEMPERATURE_C = 100.0
"""Winding temperature of the resistance and supply constraints, deg C (the thermal limit)."""
RENDER_DUTY = 0.5
"""Mean duty of the rendering drive for the heating constraint (assumed)."""
MIN_TIME_TO_HOT_S = 60.0
"""Shortest adiabatic time from cold to ``HOT_TEMPERATURE_C`` at the rendering duty, s."""
BOARD_CLEARANCE_M = 1e-3
"""Gap between the core top and the upper sensor board's underside, m (assumed, assembly)."""

# the search box (choices of this optimizer, not facts of the device)
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


def _array_pitch(design: Design) -> float:
    """The design's pitch, m (1 m for a single coil: no neighbour to overlap)."""
    return design.array.pitch_m if design.n_coils > 1 else 1.0


def _pitch_bounds(design: Design, coil_clearance_m: float,
                  pitch_range_m: tuple[float, float] | None) -> tuple[float, float]:
    """Checked (lo, hi) of a varying pitch, m (default: :meth:`DeviceProblem.from_design`)."""
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


def _search_bounds(design: Design, pitch_bounds, coil_clearance_m: float,
                   board_clearance_m: float) -> tuple[tuple, tuple]:
    """(lower, upper) of :data:`SEARCH_VARIABLES` [+ pitch], SI (see
    :meth:`DeviceProblem.from_design`)."""
    o = design.optimize
    widest = pitch_bounds[1] if pitch_bounds else _array_pitch(design)
    r_out = min(0.5 * (widest - coil_clearance_m), o.max_outer_radius_m)
    # buildability (designkit.rules): the core top stays below the upper sensor mount
    max_prot = max(min(design.sensors.offset_m - board_clearance_m,
                       rules.max_core_protrusion_m(design)), MIN_PROTRUSION_BOUND_M)
    lower = (o.min_inner_radius_m, o.min_inner_radius_m + MIN_WINDING_DEPTH_M,
             MIN_WINDING_LENGTH_M, CORE_FILL_BOUNDS[0], CORE_DEPTH_BOUNDS[0], 0.0,
             WIRE_BOUNDS_M[0]) + ((pitch_bounds[0],) if pitch_bounds else ())
    upper = (r_out - INNER_RADIUS_MARGIN_M, r_out, o.max_length_m, CORE_FILL_BOUNDS[1],
             CORE_DEPTH_BOUNDS[1], max_prot, WIRE_BOUNDS_M[1]) + (
                 (pitch_bounds[1],) if pitch_bounds else ())
    return lower, upper


@dataclass(frozen=True)
class DeviceProblem(DesignView):
    """The real device's coil problem on a design (SI). Build with :meth:`from_design`.

    The design gives the magnet, design height, drive (current, driver rating, total current),
    wire material, limits (``optimize``), sensor board and array; the problem adds the search
    space (bounds of :data:`SEARCH_VARIABLES` [+ pitch]), the objective and the stated
    operating conditions:

    hot_temperature_c : winding temperature of the resistance and supply constraints (the
        thermal limit: the coil must still take ``current_a`` from ``supply_voltage_v`` when hot).
    cold_temperature_c : temperature of the settling-time constraint (the wire's reference
        temperature: cold copper has the lowest R, so the longest L/R).
    Inductance: *secant* L(I) = L_air + lambda_core(I) / I at the operating current (the
    incremental value is reported too).
    """

    design: Design
    lower: tuple
    upper: tuple
    """Bounds (floats) of the search variables (:data:`SEARCH_VARIABLES` [+ pitch]), SI."""
    hot_temperature_c: float = HOT_TEMPERATURE_C
    render_duty: float = RENDER_DUTY
    min_time_to_hot_s: float = MIN_TIME_TO_HOT_S
    insulation_ratio: float = GRADE1_INSULATION_RATIO
    """Insulated / bare diameter of the wire family (grade-1 enamel, ~1.04-1.1)."""
    wire_table_m: tuple[float, ...] = METRIC_DIAMETERS_M
    corrections: tuple[float, float] = (1.0, 1.0)
    """(force, linkage) ratios panel / fast applied to the core's share."""
    n_slices: int = 12
    objective: str = "design-point"
    """'design-point': upward force on the axis at the design height; 'rendering': the
    smallest upward force the array renders over ``render_points_m`` (LP allocation,
    :func:`designkit.optimize.array_render_forces`)."""
    pitch_bounds_m: tuple[float, float] | None = None
    """Pitch as the 8th search variable (:data:`PITCH_VARIABLE`) within these bounds, m; None:
    the pitch is fixed at ``pitch_m``. Then the no-overlap condition 2 Ro + coil_clearance_m
    <= pitch is a constraint (not a bound)."""
    coil_clearance_m: float = 0.0
    """Pitch - 2 x outer radius that the rule book needs (flange lips, pocket clearances and
    the frame web: :func:`designkit.rules.pitch_clearance_m`; set by :meth:`from_design`), m."""
    centres_per_pitch: tuple = ((0.0, 0.0),)
    """Coil centres (x, y) in units of the pitch (the array's row-major layout)."""
    render_points_m: tuple = ()
    """Points (x, y, z) of the rendering objective, m (fixed: they do not move with the pitch)."""

    @property
    def n_search(self) -> int:
        """7 search variables, or 8 with the pitch."""
        return 7 if self.pitch_bounds_m is None else 8

    @property
    def constraint_names(self) -> tuple[str, ...]:
        return DEVICE_CONSTRAINTS + (("coil_overlap_m",) if self.pitch_bounds_m else ())

    @classmethod
    def from_design(cls, design: Design, *, hot_temperature_c: float = HOT_TEMPERATURE_C,
                    render_duty: float = RENDER_DUTY,
                    min_time_to_hot_s: float = MIN_TIME_TO_HOT_S,
                    coil_clearance_m: float | None = None,
                    board_clearance_m: float = BOARD_CLEARANCE_M,
                    objective: str = "design-point", vary_pitch: bool = False,
                    pitch_range_m: tuple[float, float] | None = None,
                    **changes) -> "DeviceProblem":
        """The device problem of ``design``: its magnet, height, drive, sensors and pitch.

        ``objective``: 'design-point' or 'rendering' (the smallest upward force over
        :func:`designkit.optimize.workspace_region` of ``design``, folded by the array's
        symmetry). ``vary_pitch``: the pitch becomes a search variable in ``pitch_range_m``
        (default: from 0.6 x the design's pitch to 2 x optimize.max_outer_radius_m +
        coil_clearance_m, or the design's pitch if larger); needs the rendering objective (at
        one point the pitch does not matter).

        Supply: the driver's rating (``drive.driver_max_voltage_v``). Bounds: inner radius
        [optimize.min_inner_radius_m, Ro bound - 0.3 mm]; outer radius up to
        (pitch - coil_clearance_m)/2 (no overlap at the pitch); winding length
        [10 mm, optimize.max_length_m]; core fill [0.25, 1]; core depth fraction [0.1, 1];
        protrusion above the winding [0, the upper sensor board's underside -
        board_clearance_m]; bare wire [0.2, 1.6] mm (the ``*_BOUNDS`` module constants).
        """
        if objective not in DEVICE_OBJECTIVES:
            raise BadInputError("objective", f"one of {DEVICE_OBJECTIVES}", objective)
        if coil_clearance_m is None:
            coil_clearance_m = rules.pitch_clearance_m(design)
        if vary_pitch and objective != "rendering":
            raise BadInputError("objective", "'rendering' when the pitch varies (the force at "
                                "one point does not depend on the pitch)", objective)
        pitch_bounds = (_pitch_bounds(design, coil_clearance_m, pitch_range_m) if vary_pitch
                        else None)
        lower, upper = _search_bounds(design, pitch_bounds, coil_clearance_m, board_clearance_m)
        n_coils = design.n_coils
        cen = np.array([[x, y] for x, y, _ in design.coil_centres_m()]) / (
            _array_pitch(design) if n_coils > 1 else 1.0)
        pts = ()
        if objective == "rendering":
            pts = tuple(tuple(float(c) for c in q)
                        for q in fold_points(workspace_region(design), cen))
        kw = dict(
            design=design, lower=lower, upper=upper, hot_temperature_c=hot_temperature_c,
            render_duty=render_duty, min_time_to_hot_s=min_time_to_hot_s,
            objective=objective, pitch_bounds_m=pitch_bounds, coil_clearance_m=coil_clearance_m,
            centres_per_pitch=tuple(map(tuple, cen)), render_points_m=pts)
        kw.update(changes)
        return cls(**kw)

    def __post_init__(self):
        v.in_range("render_duty", self.render_duty, 1e-3, 1.0)
        names = SEARCH_VARIABLES + (PITCH_VARIABLE,) * (self.n_search - 7)
        if len(self.lower) != self.n_search or len(self.upper) != self.n_search:
            raise BadInputError("bounds", f"{self.n_search} values for {names}",
                                (self.lower, self.upper))
        if self.objective not in DEVICE_OBJECTIVES:
            raise BadInputError("objective", f"one of {DEVICE_OBJECTIVES}", self.objective)
        if self.objective == "rendering" and not len(self.render_points_m):
            raise BadInputError("render_points_m", "at least one point for the rendering "
                                "objective", self.render_points_m)
        for name, lo, hi in zip(names, self.lower, self.upper):
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
                raise BadInputError(f"bounds of {name}", "0 <= lower < upper (finite, m)",
                                    (lo, hi))

    # ------------------------------------------------------------------ the design's numbers
    @property
    def total_current_a(self) -> float:
        return self.design.drive.total_current_a

    @property
    def supply_voltage_v(self) -> float:
        """The driver's rating, V (``drive.driver_max_voltage_v``)."""
        return self.design.drive.driver_max_voltage_v

    @property
    def resistivity_ref_ohm_m(self) -> float:
        return self.design.wire.resistivity_ohm_m

    @property
    def temperature_coefficient_per_k(self) -> float:
        return self.design.wire.temperature_coefficient_per_k

    @property
    def reference_temperature_c(self) -> float:
        return self.design.wire.reference_temperature_c

    @property
    def cold_temperature_c(self) -> float:
        """Temperature of the settling-time constraint, deg C (the wire's reference)."""
        return self.design.wire.reference_temperature_c

    @property
    def pitch_m(self) -> float:
        """The design's pitch, m (1 m for a single coil)."""
        return _array_pitch(self.design)

    @property
    def board_top_m(self) -> float:
        """Top of the upper sensor board above the coil tops, m."""
        return rules.board_top_m(self.design)

    @property
    def magnet_bottom_clearance_m(self) -> float:
        """Design height - magnet half length - upper-board top, m (>= 0 for the magnet to
        reach the design point)."""
        return self.design.optimize.height_m - self.design.magnet.length_m / 2 - self.board_top_m

    # ------------------------------------------------------------------ model pieces
    @staticmethod
    def physical(y) -> list[float]:
        """Search variables (:data:`SEARCH_VARIABLES` [+ pitch]) -> physical
        (:data:`DEVICE_VARIABLES` [+ pitch])."""
        ri, ro, ln, fill, depth, prot, d = [float(q) for q in y[:7]]
        return [ri, ro, ln, fill * ri, depth * (ln + prot), prot, d] + [float(q) for q in y[7:]]

    @staticmethod
    def search(x) -> list[float]:
        """Physical -> search variables (inverse of :meth:`physical`)."""
        ri, ro, ln, a, lc, prot, d = [float(q) for q in x[:7]]
        return [ri, ro, ln, a / ri, lc / (ln + prot), prot, d] + [float(q) for q in x[7:]]

    def resistivity(self, temperature_c: float) -> float:
        return self.resistivity_ref_ohm_m * (1.0 + self.temperature_coefficient_per_k
                                             * (temperature_c - self.reference_temperature_c))

    def insulated(self, bare_m: float) -> float:
        return bare_m * self.insulation_ratio

    def turns(self, x) -> float:
        return el.turns_continuous(x[0], x[1], x[2], self.insulated(x[6]), self.packing)

    @staticmethod
    def core_offset(x) -> float:
        """Core centre relative to the winding centre, m (core top = winding top + protrusion)."""
        return x[2] / 2 + x[5] - x[4] / 2

    def evaluate(self, x, *, turns: float | None = None, model: str = "fast") -> dict:
        """All model numbers at x (SI). ``model``: 'fast' (corrected slice model) or 'panel'.

        Returns a dict with force_n (upward force the coil renders at the design point with
        |I| = current_a, >= 0), winding/core shares of dBz/dz, R (hot, cold), L (secant,
        incremental; the fast model only), tau, supply voltage needed, thermal time, peak core B
        and the scaled constraints ``g`` (<= 0 feasible), in :data:`DEVICE_CONSTRAINTS` order.
        """
        x = [float(q) for q in x]
        if model == "fast":
            many = self.evaluate_many(np.array([x]), None if turns is None else [turns])
            return {k: (tuple(float(q) for q in val[0]) if k == "g" else float(val[0]))
                    for k, val in many.items()}
        if model != "panel":
            raise BadInputError("model", "'fast' or 'panel'", model)
        ri, ro, ln, a, lc, prot, d = x[:7]
        n = self.turns(x) if turns is None else float(turns)
        g_c, lam, peak = _panel_core(ri, ro, ln, n, min(a, ri), lc, self.core_offset(x),
                                     self.current_a, ln / 2 + self.height_m)
        l_air = el.air_inductance_from_geometry(ri, ro, ln, n, t_max=60.0)
        out = self._assemble(np.array([x]), np.array([n]), np.array([g_c]), np.array([lam]),
                             np.zeros(1), np.array([peak]), np.array([l_air]))
        # the panel model solves at one current: no incremental inductance (not a NaN)
        return {k: (tuple(float(q) for q in val[0]) if k == "g" else float(val[0]))
                for k, val in out.items() if k != "inductance_incremental_h"}

    def evaluate_many(self, xs, turns=None, air_cache: dict | None = None) -> dict:
        """Fast-model numbers of B designs at once: xs (B, 7) physical variables (SI).

        Same keys as :meth:`evaluate`, each a (B,) array (``g``: (B, 5)). ``air_cache``: a
        dict reused across calls for the air inductance per turn^2 by (ri, ro, Lc).
        """
        xs = np.atleast_2d(np.asarray(xs, dtype=float))
        ri, ro, ln, a, lc, prot, d = xs[:, :7].T
        n = self.turns(xs.T) if turns is None else np.asarray(turns, dtype=float)
        sol = solve_rods(ri, ro, ln, n, np.minimum(a, ri), lc, ln / 2 + prot - lc / 2,
                         self.current_a, n_slices=self.n_slices, quadrature="bessel")
        g_c = sol.axis_field(ln / 2 + self.height_m)[1] * self.corrections[0]
        lam = sol.linkage_wb * self.corrections[1]
        l_inc = sol.dlinkage_di_wb_per_a * self.corrections[1]
        cache = {} if air_cache is None else air_cache
        l_air = np.empty(len(xs))
        for k in range(len(xs)):
            key = (ri[k], ro[k], ln[k])
            per = cache.get(key)
            if per is None:
                if len(cache) > 4096:
                    cache.clear()
                per = cache[key] = el.air_inductance_from_geometry(*key, 1.0, t_max=60.0)
            l_air[k] = per * n[k] ** 2
        return self._assemble(xs, n, g_c, lam, l_inc, sol.peak_b_t, l_air)

    def pitch_of(self, x) -> float:
        """The design's pitch, m: its 8th variable when the pitch varies (and x has one: a
        given design's 7 variables sit at ``pitch_m``), else ``pitch_m``."""
        return float(x[7]) if self.pitch_bounds_m is not None and len(x) > 7 else self.pitch_m

    def render_forces(self, x, turns: float | None = None) -> np.ndarray:
        """Largest upward force the array renders at each of ``render_points_m`` (N, (P,)),
        bounded allocation with Fx = Fy = 0; core force ratio ``corrections[0]``."""
        x = [float(q) for q in x]
        n = self.turns(x) if turns is None else float(turns)
        cen = np.asarray(self.centres_per_pitch, dtype=float) * self.pitch_of(x)
        return array_render_forces(x[:7], n, self.current_a, self.total_current_a, cen,
                                   np.asarray(self.render_points_m, dtype=float),
                                   self.moment_a_m2, core_force_ratio=self.corrections[0],
                                   n_slices=self.n_slices)

    def _assemble(self, xs, n, g_c, lam, l_inc_core, peak, l_air) -> dict:
        """The numbers of :meth:`evaluate` from the core's share (arrays over designs, SI)."""
        ri, ro, ln, a, lc, prot, d = xs[:, :7].T
        i = self.current_a
        j = n * i / ((ro - ri) * ln)
        g_w = j * axial_gradient_per_current_density(ri, ro, ln, self.height_m)
        l_sec = l_air + lam / i
        wire_len = el.wire_length_from_geometry(ri, ro, n)
        area = math.pi * d * d / 4
        r_hot = self.resistivity(self.hot_temperature_c) * wire_len / area
        r_cold = self.resistivity(self.cold_temperature_c) * wire_len / area
        tau = l_sec / r_cold
        volt = i * r_hot
        mass = el.COPPER_DENSITY_KG_M3 * wire_len * area
        # adiabatic heating at the rendering duty: mean power duty x I^2 R(T), from cold
        alpha = self.temperature_coefficient_per_k
        a_c = alpha / (1 + alpha * (self.cold_temperature_c - self.reference_temperature_c))
        p0 = self.render_duty * i * i * r_cold
        t_hot = (mass * el.COPPER_SPECIFIC_HEAT_J_KG_K
                 * math.log1p(a_c * (self.hot_temperature_c - self.cold_temperature_c))
                 / (p0 * a_c))
        d_ins = self.insulated(d)
        g = np.stack([r_hot / self.max_resistance_ohm - 1.0,
                      volt / self.supply_voltage_v - 1.0,
                      5.0 * tau / self.max_settling_time_s - 1.0,
                      1.0 - t_hot / self.min_time_to_hot_s,
                      (ri + d_ins - ro) / 1e-3], axis=1)
        return {"turns": n, "force_n": self.moment_a_m2 * np.abs(g_w + g_c),
                "dbz_dz_winding_t_per_m": g_w, "dbz_dz_core_t_per_m": g_c,
                "resistance_ohm": r_hot, "resistance_cold_ohm": r_cold,
                "inductance_h": l_sec, "inductance_air_h": l_air,
                "inductance_incremental_h": l_air + l_inc_core,
                "time_constant_s": tau, "settling_time_s": 5 * tau, "voltage_needed_v": volt,
                "time_to_max_temperature_s": t_hot, "copper_mass_kg": mass,
                "peak_core_flux_density_t": peak, "g": g}

    def table_with_inductance(self, x, turns: float, inductance_h: float) -> dict:
        """:meth:`constraint_table` of one design from a given secant inductance (H), with no
        field solve: for callers (the coil sweep) that already have the coil's inductance."""
        zero = np.zeros(1)
        many = self._assemble(np.array([x], dtype=float), np.array([float(turns)]), zero, zero,
                              zero, zero, np.array([float(inductance_h)]))
        return self.constraint_table(x, {q: float(v[0]) for q, v in many.items() if q != "g"})

    def constraint_table(self, x, ev: dict, turns_fit: int | None = None) -> dict:
        """Each constraint: value, limit, kind, margin (>= 0 when met; in the value's unit)."""
        ri, ro, ln, a, lc, prot, d = [float(q) for q in x[:7]]
        items = {
            "resistance_ohm": (ev["resistance_ohm"], self.max_resistance_ohm, 1,
                               f"R at {self.hot_temperature_c:g} C"),
            "supply_voltage_v": (ev["voltage_needed_v"], self.supply_voltage_v, 1,
                                 f"I R at {self.hot_temperature_c:g} C vs the MD10C rating"),
            "settling_time_s": (ev["settling_time_s"], self.max_settling_time_s, 1,
                                f"5 L_secant({self.current_a:g} A) / "
                                f"R({self.cold_temperature_c:g} C)"),
            "time_to_max_temperature_s": (ev["time_to_max_temperature_s"],
                                          self.min_time_to_hot_s, -1,
                                          f"adiabatic, {self.render_duty:g} duty at "
                                          f"{self.current_a:g} A, {self.cold_temperature_c:g} "
                                          f"-> {self.hot_temperature_c:g} C"),
            "core_radius_m": (a, ri, 1, "core fits the bore"),
            "outer_diameter_m": (2 * ro, self.pitch_of(x) - self.coil_clearance_m, 1,
                                 "coils, flanges and frame pockets fit at the pitch"),
            "core_protrusion_m": (prot, self.upper[5], 1,
                                  "core top below the upper sensor board"),
            "magnet_bottom_m": (self.magnet_bottom_clearance_m + self.board_top_m,
                                self.board_top_m, -1,
                                "magnet bottom at the design height above the board top"),
        }
        if turns_fit is not None:
            items["turns"] = (ev["turns"], turns_fit, 1, f"{self.packing} packing")
        out = {}
        for name, (val, lim, sense, note) in items.items():
            margin = (lim - val) * sense
            out[name] = {"value": float(val), "limit": float(lim), "unit": _unit_of(name),
                         "kind": "upper" if sense > 0 else "lower", "margin": float(margin),
                         "met": bool(margin >= -1e-9 * max(abs(lim), 1e-12)), "note": note,
                         "keys": list(_FIXED_BY.get(name, ()))}
        return out


_FIXED_BY = {
    "resistance_ohm": ("coil.turns", "wire.diameter_m", "coil.inner_radius_m",
                       "coil.outer_radius_m", "optimize.max_resistance_ohm"),
    "supply_voltage_v": ("drive.max_current_a", "coil.turns", "wire.diameter_m",
                         "drive.driver_max_voltage_v"),
    "settling_time_s": ("coil.turns", "coil.length_m", "core.radius_m", "core.length_m",
                        "wire.diameter_m", "optimize.max_settling_time_s"),
    "time_to_max_temperature_s": ("drive.max_current_a", "wire.diameter_m"),
    "core_radius_m": ("core.radius_m", "coil.inner_radius_m"),
    "outer_diameter_m": ("coil.outer_radius_m", "array.pitch_m"),
    "core_protrusion_m": ("core.length_m", "core.offset_m", "sensors.offset_m"),
    "magnet_bottom_m": ("optimize.height_m", "sensors.offset_m"),
    "turns": ("coil.turns", "wire.insulated_diameter_m"),
}
"""The design keys that move each device constraint (``designkit check``'s "fixed by")."""


def _unit_of(name: str) -> str:
    """Unit of a constraint from its key's suffix (value, limit and margin share it)."""
    for suffix, unit in (("_ohm", "ohm"), ("_v", "V"), ("_s", "s"), ("_m", "m")):
        if name.endswith(suffix):
            return unit
    return "turns" if name == "turns" else ""


def _panel_core(ri, ro, ln, n, a, lc, offset, current, z_mag):
    """Core share of dBz/dz at the magnet (T/m), flux linkage (Wb), peak B (T): panel model."""
    ref = 1000
    core = Core(radius=a, length=lc, offset=offset, bh="steel1010")
    coil = Coil(ri, ro, ln, ref, core)
    i_ref = current * n / ref
    sol = core.solution(coil, i_ref)
    _, g = sol.field(np.array([[0.0, 0.0, z_mag]]), gradient=True)
    lam = sol.flux_linkage(coil) * (n / ref)
    return float(g[0, 2, 2]), float(lam), float(sol.peak_b)


def device_problem_for(design: Design, **kw) -> DeviceProblem:
    """:meth:`DeviceProblem.from_design` with the base design's wire insulation ratio kept
    when it is a real enamel build (> 1), else the grade-1 ratio."""
    ratio = design.wire.insulated_diameter_m / design.wire.diameter_m
    if ratio > 1.0 + 1e-9:
        kw.setdefault("insulation_ratio", ratio)
    return DeviceProblem.from_design(design, **kw)


