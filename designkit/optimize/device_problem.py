"""The real device's coil problem: winding, wire and 1010-steel core optimized together.

Search variables (:data:`SEARCH_VARIABLES`): the winding's inner/outer radius and length, core
fill (core radius / inner radius), core depth fraction (core length / (winding length +
protrusion)), core protrusion above the winding top, bare wire diameter (continuous; the
solver then picks a neighbouring IEC 60317 size), optionally the array pitch. Constraints
(:data:`DEVICE_CONSTRAINTS`, each with its margin): R at the hot limit < Rmax, I R(hot) <=
the supply (the design's, at most the driver's rating), 5 L_secant / R(cold) < T, adiabatic time from cold to hot at the
rendering duty >= its minimum, a winding at least one wire deep; with a varying pitch also
2 Ro + clearance <= pitch. Objective: the upward force on the axis at the design height, or
the smallest upward force the array renders over the workspace region (:mod:`.rendering`).
Models: the closed-form winding gradient (:mod:`.axial_kernel`), the exact Bessel air
inductance, the core by the fast slice model of :mod:`designkit.cores.rod` (corrected by the
surface-current panel model of :mod:`designkit.cores`). Details: docs/optimize.md.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from .. import rules
from ..cores.panel import Core
from ..cores.rod import RodGeometry, RodSettings, solve_rods
from ..design import Design
from ..errors import BadInputError
from ..model import electrical as el
from ..model.coil import Coil
from ..support import validate as v
from .axial_kernel import axial_gradient_per_current_density
from .design_view import DesignView
from .rendering import RodCoil, array_render_forces, render_forces_many
from .search_space import SEARCH_VARIABLES, SearchSpace, device_space, nearest_spacing_m
from .wire_table import GRADE1_INSULATION_RATIO, METRIC_DIAMETERS_M
from .workspace import fold_points, workspace_region

DEVICE_VARIABLES = ("inner_radius_m", "outer_radius_m", "length_m", "core_radius_m",
                    "core_length_m", "core_protrusion_m", "wire_diameter_m")
DEVICE_CONSTRAINTS = ("resistance_ohm", "supply_voltage_v", "settling_time_s",
                      "time_to_max_temperature_s", "winding_depth_m")
DEVICE_OBJECTIVES = ("design-point", "rendering")
PITCH_VARIABLE = "pitch_m"
"""The optional 8th search (and physical) variable, :attr:`DeviceProblem.pitch_bounds_m`."""

# stated operating conditions (defaults of OperatingConditions)
HOT_TEMPERATURE_C = 100.0
"""Winding temperature of the resistance and supply constraints, deg C (the thermal limit)."""
RENDER_DUTY = 0.5
"""Mean duty of the rendering drive for the heating constraint (assumed)."""
MIN_TIME_TO_HOT_S = 60.0
"""Shortest adiabatic time from cold to ``HOT_TEMPERATURE_C`` at the rendering duty, s."""
BOARD_CLEARANCE_M = 1e-3
"""Gap between the core top and the upper sensor board's underside, m (assumed, assembly)."""


@dataclass(frozen=True)
class OperatingConditions:
    """The stated operating conditions of the device constraints.

    hot_temperature_c : winding temperature of the resistance and supply constraints (the
        thermal limit: the coil must still take the operating current from the supply hot).
    render_duty : mean duty of the rendering drive for the heating constraint.
    min_time_to_hot_s : shortest adiabatic time from cold to ``hot_temperature_c`` at that duty.
    """

    hot_temperature_c: float = HOT_TEMPERATURE_C
    render_duty: float = RENDER_DUTY
    min_time_to_hot_s: float = MIN_TIME_TO_HOT_S


@dataclass(frozen=True)
class DeviceProblem(DesignView):
    """The real device's coil problem on a design (SI). Build with :meth:`from_design`.

    The design gives the magnet, design height, drive (current, driver rating, total current),
    wire material, limits (``optimize``), sensor board and array; the problem adds the search
    space (:class:`designkit.optimize.search_space.SearchSpace`: the coil's variables and any
    layout variable, with bounds), the objective and the stated operating conditions
    (:class:`OperatingConditions`). The settling-time constraint is taken cold (the wire's
    reference temperature: cold copper has the lowest R, so the longest L/R). Inductance:
    *secant* L(I) = L_air + lambda_core(I) / I at the operating current (the incremental value
    is reported too).
    """

    design: Design
    space: SearchSpace
    conditions: OperatingConditions = OperatingConditions()
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
    coil_clearance_m: float = 0.0
    """Pitch - 2 x outer radius that the rule book needs (flange lips, pocket clearances and
    the frame web: :func:`designkit.rules.pitch_clearance_m`; set by :meth:`from_design`), m.
    With a layout variable the no-overlap condition 2 Ro + coil_clearance_m <= pitch is a
    constraint (not a bound)."""
    render_points_m: tuple = ()
    """Points (x, y, z) of the rendering objective, m (fixed: they do not move with the
    layout)."""

    @property
    def lower(self) -> tuple:
        """Lower bounds of the search variables, SI."""
        return self.space.lower

    @property
    def upper(self) -> tuple:
        """Upper bounds of the search variables, SI."""
        return self.space.upper

    @property
    def pitch_bounds_m(self) -> tuple[float, float] | None:
        """Bounds of the pitch when it is a search variable (:data:`PITCH_VARIABLE`), m."""
        return self.space.bounds(PITCH_VARIABLE)

    @property
    def hot_temperature_c(self) -> float:
        return self.conditions.hot_temperature_c

    @property
    def render_duty(self) -> float:
        return self.conditions.render_duty

    @property
    def min_time_to_hot_s(self) -> float:
        return self.conditions.min_time_to_hot_s

    @property
    def n_search(self) -> int:
        """The coil's 7 search variables and the layout's."""
        return len(self.space.variables)

    @property
    def constraint_names(self) -> tuple[str, ...]:
        return DEVICE_CONSTRAINTS + (("coil_overlap_m",) if self.space.layout_names else ())

    @classmethod
    def from_design(cls, design: Design, *, objective: str = "design-point",
                    vary: Mapping[str, tuple[float, float] | None] | None = None,
                    conditions: OperatingConditions | None = None,
                    coil_clearance_m: float | None = None,
                    board_clearance_m: float = BOARD_CLEARANCE_M,
                    **changes) -> "DeviceProblem":
        """The device problem of ``design``: its magnet, height, drive, sensors and layout.

        ``objective``: 'design-point' or 'rendering' (the smallest upward force over
        :func:`designkit.optimize.workspace_region` of ``design``, folded by the array's
        symmetry). ``vary``: layout keys that become search variables ({'pitch_m': (lo, hi)
        or None for the default range}, :func:`designkit.optimize.search_space.device_space`,
        which states the bounds); they need the rendering objective (at one point the layout
        does not matter). ``conditions``: :class:`OperatingConditions` (default: the module
        constants). Supply: the design's (:attr:`supply_voltage_v`, at most the driver's
        rating).
        """
        vary = dict(vary or {})
        if objective not in DEVICE_OBJECTIVES:
            raise BadInputError("objective", f"one of {DEVICE_OBJECTIVES}", objective)
        if coil_clearance_m is None:
            coil_clearance_m = rules.pitch_clearance_m(design)
        if vary and objective != "rendering":
            raise BadInputError("objective", f"'rendering' when the layout varies ({', '.join(vary)}:"
                                " the force at one point does not depend on it)", objective)
        space = device_space(design, vary, coil_clearance_m, board_clearance_m)
        pts = ()
        if objective == "rendering":
            folded = fold_points(workspace_region(design), design.array.top_centres_m(),
                                 design.array.axes())
            pts = tuple(tuple(float(c) for c in q) for q in folded)
        kw = dict(design=design, space=space, conditions=conditions or OperatingConditions(),
                  objective=objective, coil_clearance_m=coil_clearance_m, render_points_m=pts)
        kw.update(changes)
        return cls(**kw)

    def __post_init__(self):
        v.in_range("render_duty", self.render_duty, 1e-3, 1.0)
        if self.space.names[:len(SEARCH_VARIABLES)] != SEARCH_VARIABLES:
            raise BadInputError("space", f"the coil's variables {SEARCH_VARIABLES} first",
                                self.space.names)
        if self.objective not in DEVICE_OBJECTIVES:
            raise BadInputError("objective", f"one of {DEVICE_OBJECTIVES}", self.objective)
        if self.objective == "rendering" and not len(self.render_points_m):
            raise BadInputError("render_points_m", "at least one point for the rendering "
                                "objective", self.render_points_m)
        self.space.checked()

    # ------------------------------------------------------------------ the design's numbers
    @property
    def total_current_a(self) -> float:
        return self.design.drive.total_current_a

    @property
    def supply_voltage_v(self) -> float:
        """The supply the coils are designed for, V: the design's ``drive.supply_voltage_v``,
        at most the named driver's rating (a supply above it is the rule
        ``design_supply_voltage_v``; :meth:`firmware_io.hw.driver.DriverRating.usable_supply_v`)."""
        d = self.design.drive
        return el.driver_rating(d).usable_supply_v(d.supply_voltage_v)

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
        """The distance of the design's nearest two coils, m: a lattice's pitch (1 m for a
        single coil)."""
        return nearest_spacing_m(self.design)

    @property
    def board_top_m(self) -> float:
        """Top of the highest sensor board or printed part under the magnet at the design
        point, m (:func:`designkit.rules.design_point_floor_m` less the magnet's half
        length)."""
        return rules.design_point_floor_m(self.design) - self.design.magnet.length_m / 2

    @property
    def magnet_bottom_clearance_m(self) -> float:
        """Design height - magnet half length - :attr:`board_top_m`, m (>= 0 for the magnet to
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
        g_c, lam, peak = panel_core(x, n, self.current_a, ln / 2 + self.height_m)
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
        sol = solve_rods(RodGeometry(ri, ro, ln, n, np.minimum(a, ri), lc, ln / 2 + prot - lc / 2),
                         self.current_a, RodSettings(n_slices=self.n_slices, quadrature="bessel"))
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

    def spacing_of(self, x) -> float:
        """Distance of the nearest two top-face centres of the layout of ``x``, m (a
        lattice's pitch)."""
        if self.design.array.kind in ("grid", "hex"):
            return self.pitch_of(x)
        return nearest_spacing_m(dataclasses.replace(self.design, array=self.layout_of(x)))

    def overlap_m(self, x) -> float:
        """How much closer than a frame web the flange pockets of the coils of ``x`` come, m
        (<= 0: they fit). A grid or hex lattice: 2 Ro + coil_clearance_m - pitch; any other
        layout: the minimum wall less the smallest signed distance of the pockets in their
        poses (:func:`designkit.rules.lattice_gap_m`)."""
        ro = float(x[1])
        if self.design.array.kind in ("grid", "hex"):
            return 2 * ro + self.coil_clearance_m - self.pitch_of(x)
        c = self.design.cad
        gap = rules.lattice_gap_m(self.layout_of(x), ro + c.flange_lip_m + c.pocket_clearance_m,
                                  float(x[2]), c.flange_thickness_m)
        return c.min_wall_m - gap

    def layout_of(self, x):
        """The layout of search or physical vector ``x``: the design's, with the layout
        variables of ``x`` when it has them (:meth:`SearchSpace.layout_of`)."""
        return self.space.layout_of(self.design.array, x)

    def render_forces(self, x, turns: float | None = None) -> np.ndarray:
        """Largest upward force the array renders at each of ``render_points_m`` (N, (P,)),
        bounded allocation with Fx = Fy = 0; core force ratio ``corrections[0]``."""
        x = [float(q) for q in x]
        n = self.turns(x) if turns is None else float(turns)
        coil = RodCoil(tuple(x[:7]), n, self.current_a, self.corrections[0], self.n_slices)
        return array_render_forces(coil, self.layout_of(x),
                                   np.asarray(self.render_points_m, dtype=float),
                                   self.moment_a_m2, self.total_current_a)

    def render_forces_many(self, xs) -> np.ndarray:
        """:meth:`render_forces` of the rows of ``xs`` (B, n) physical vectors, their own turns,
        (B, P) N, in one batch (:func:`designkit.optimize.rendering.render_forces_many`)."""
        xs = [[float(q) for q in x] for x in xs]
        coils = [RodCoil(tuple(x[:7]), self.turns(x), self.current_a, self.corrections[0],
                         self.n_slices) for x in xs]
        return render_forces_many(coils, [self.layout_of(x) for x in xs],
                                  np.asarray(self.render_points_m, dtype=float),
                                  self.moment_a_m2, self.total_current_a)

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
                                 f"I R at {self.hot_temperature_c:g} C vs the supply"),
            "settling_time_s": (ev["settling_time_s"], self.max_settling_time_s, 1,
                                f"5 L_secant({self.current_a:g} A) / "
                                f"R({self.cold_temperature_c:g} C)"),
            "time_to_max_temperature_s": (ev["time_to_max_temperature_s"],
                                          self.min_time_to_hot_s, -1,
                                          f"adiabatic, {self.render_duty:g} duty at "
                                          f"{self.current_a:g} A, {self.cold_temperature_c:g} "
                                          f"-> {self.hot_temperature_c:g} C"),
            "core_radius_m": (a, ri, 1, "core fits the bore"),
            "outer_diameter_m": (2 * ro, (self.pitch_of(x) - self.coil_clearance_m
                                          if self.design.array.kind in ("grid", "hex")
                                          else 2 * ro - self.overlap_m(x)), 1,
                                 "coils, flanges and frame pockets fit at the "
                                 + ("pitch" if self.design.array.kind in ("grid", "hex")
                                    else "spacing")),
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
                         "keys": list(_FIXED_BY.get(name, ()) if name != "outer_diameter_m"
                                      else ("coil.outer_radius_m",)
                                      + rules.layout_keys(self.design))}
        return out


_FIXED_BY = {
    "resistance_ohm": ("coil.turns", "wire.diameter_m", "coil.inner_radius_m",
                       "coil.outer_radius_m", "optimize.max_resistance_ohm"),
    "supply_voltage_v": ("drive.max_current_a", "coil.turns", "wire.diameter_m",
                         "drive.supply_voltage_v", "drive.driver_max_voltage_v"),
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


def panel_core(x, turns: float, current_a: float, z_mag_m: float):
    """Core share of dBz/dz at the magnet (T/m), flux linkage (Wb), peak B (T) of the coil of
    physical variables ``x`` (:data:`DEVICE_VARIABLES`) with ``turns`` at ``current_a``: the
    panel model (steel1010), the magnet ``z_mag_m`` above the winding centre on the axis."""
    ri, ro, ln, a, lc = x[:5]
    n, current, z_mag = turns, current_a, z_mag_m
    ref = 1000
    core = Core(radius=min(a, ri), length=lc, offset=DeviceProblem.core_offset(x),
                bh="steel1010")
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


