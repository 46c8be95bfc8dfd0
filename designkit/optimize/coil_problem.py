"""The coil problem of thesis eq. 2.14: maximize the magnet's vertical force over the winding.

Maximize Fz = m_z dBz/dz at the design height above the coil's top face over the winding's
inner radius Ri, outer radius Ro and length Lc (optionally the core protrusion), subject to
R < Rmax, 5 L/R < T, Ro <= Rmax_outer, Lc <= Lmax, for the design's fixed wire. Turns follow
from the geometry, N = (Ro - Ri) Lc / (p d_ins^2) (p = 1 layered, sqrt(3)/2 orthocyclic),
continuous in the search and rounded down in the reported design. The force is evaluated at
``drive.max_current_a``: on the axis in closed form (:mod:`.axial_kernel`), with an iron core
through :class:`designkit.Core`. Constraints in nlopt form c(x) <= 0, scaled to O(1):
R / Rmax - 1, 5 tau / T - 1 and (Ri + d_ins - Ro) / d_ins. Inductance: the exact Bessel
integral of :mod:`designkit.model.electrical`. Model and derivation: docs/optimize.md.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass
from functools import cached_property
from typing import Literal, Sequence

import numpy as np

from ..cores.panel import Core
from ..cores.saturation import SaturationWarning
from ..design import CoreSpec, Design
from ..errors import BadInputError
from ..geometry.pose import Pose
from ..model import electrical as el
from ..model.coil import Coil
from ..support import validate as v
from .axial_kernel import axial_gradient_per_current_density
from .design_view import DesignView
from .wire_table import insulated_diameter_for

CoreModelName = Literal["air", "thesis-uniform", "surface-current"]
CORE_MODEL_NAMES: tuple[str, ...] = ("air", "thesis-uniform", "surface-current")

VARIABLES = ("inner_radius_m", "outer_radius_m", "length_m")
EXTRA_VARIABLES = ("core_protrusion_m",)
MIN_LENGTH_M = 0.005
"""Default lower bound of the winding length, m (a search-space choice)."""
THESIS_CORE_PROTRUSION_M = 0.005
"""Core length beyond each end of the winding when the design has no core, m (thesis: a
110 mm core on the 100 mm winding)."""
MAGNET_CLEARANCE_M = 1e-3
"""Default gap between the core top and the magnet's bottom face, m (a search-space choice)."""


@dataclass(frozen=True)
class Evaluation:
    """Model numbers of one continuous design x = (Ri, Ro, Lc[, protrusion]) (SI)."""

    x: tuple[float, ...]
    turns: float
    force_n: float
    resistance_ohm: float
    inductance_h: float
    time_constant_s: float
    power_w: float
    constraints: tuple[float, ...]
    """Scaled nlopt constraints c <= 0: resistance, settling time, wall."""

    @property
    def feasible(self) -> bool:
        return all(c <= 1e-9 for c in self.constraints)


@dataclass(frozen=True)
class CoilDesignProblem(DesignView):
    """Coil design problem of thesis eq. 2.14 on a design (all SI). Build with
    :meth:`from_design`.

    The design gives the magnet, the design height (``optimize.height_m``), the current
    (``drive.max_current_a``), the wire and the limits (``optimize``); the problem adds the
    search space (``variables`` and their bounds) and the force model (``core_model``).
    """

    design: Design
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    core_model: str = "air"
    variables: tuple[str, ...] = VARIABLES
    inductance_t_max: float = 100.0
    """``t_max`` of :func:`designkit.model.electrical.air_inductance_from_geometry`."""

    def __post_init__(self):
        w = self.design.wire
        if w.insulated_diameter_m < w.diameter_m * (1 - 1e-12):
            raise BadInputError("wire.insulated_diameter_m", f">= wire.diameter_m "
                                f"({w.diameter_m} m)", w.insulated_diameter_m)
        if self.core_model not in CORE_MODEL_NAMES:
            raise BadInputError("core_model", f"one of {CORE_MODEL_NAMES}", self.core_model)
        v.in_range("core.relative_permeability", self.core_relative_permeability, 1.0, 1e7)
        self._check_variables()
        self._check_bounds()

    def _check_variables(self):
        for name in self.variables:
            if name not in VARIABLES + EXTRA_VARIABLES:
                raise BadInputError("variables", f"names from {VARIABLES + EXTRA_VARIABLES}", name)
        if tuple(self.variables[:3]) != VARIABLES:
            raise BadInputError("variables", f"starting with {VARIABLES}", self.variables)
        if "core_protrusion_m" in self.variables and self.core_model == "air":
            raise BadInputError("variables", "core_protrusion_m only with a core model "
                                "('thesis-uniform' or 'surface-current')", self.core_model)

    def _check_bounds(self):
        if len(self.lower) != len(self.variables) or len(self.upper) != len(self.variables):
            raise BadInputError("bounds", f"{len(self.variables)} lower and upper values",
                                (self.lower, self.upper))
        for name, lo, hi in zip(self.variables, self.lower, self.upper):
            lo_ = v.nonnegative(f"lower bound of {name}", lo)
            hi_ = v.positive(f"upper bound of {name}", hi)
            if hi_ <= lo_:
                raise BadInputError(f"upper bound of {name}", f"> its lower bound ({lo_} m)", hi)
        if self.lower[0] <= 0:
            raise BadInputError("lower bound of inner_radius_m", "> 0 m", self.lower[0])
        # infeasible bounds: not even one layer of wire fits between the radius bounds
        if self.lower[0] + self.insulated_diameter_m > self.upper[1]:
            raise BadInputError(
                "bounds", f"room for one layer: min inner radius + insulated diameter "
                f"({self.lower[0] + self.insulated_diameter_m:.4g} m) <= max outer radius",
                self.upper[1], "The bounds admit no winding (infeasible bounds).")
        if self.upper[2] < self.insulated_diameter_m:
            raise BadInputError("upper bound of length_m", f">= the insulated wire diameter "
                                f"({self.insulated_diameter_m} m)", self.upper[2])

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_design(cls, design: Design, *, core_model: str = "air",
                    min_length_m: float = MIN_LENGTH_M, variables: Sequence[str] = VARIABLES,
                    max_core_protrusion_m: float | None = None, **changes) -> "CoilDesignProblem":
        """The eq. 2.14 problem of ``design`` (wire, limits, drive current, magnet, height).

        Bounds: Ri in [optimize.min_inner_radius_m, Rmax - d_ins], Ro in
        [min_inner + d_ins, optimize.max_outer_radius_m], Lc in [min_length_m,
        optimize.max_length_m]; core protrusion (if a variable) in [0, max_core_protrusion_m]
        (default: up to :data:`MAGNET_CLEARANCE_M` below the magnet's bottom face).
        """
        o, w = design.optimize, design.wire
        v.positive("wire.diameter_m", w.diameter_m)
        d = w.insulated_diameter_m
        lower = [o.min_inner_radius_m, o.min_inner_radius_m + d, min_length_m]
        upper = [max(o.max_outer_radius_m - d, o.min_inner_radius_m * (1 + 1e-9)),
                 o.max_outer_radius_m, o.max_length_m]
        variables = tuple(variables)
        if "core_protrusion_m" in variables:
            top = (o.height_m - design.magnet.length_m / 2 - MAGNET_CLEARANCE_M
                   if max_core_protrusion_m is None else max_core_protrusion_m)
            lower.append(0.0)
            upper.append(top)
        kw = dict(design=design, lower=tuple(lower), upper=tuple(upper), core_model=core_model,
                  variables=variables)
        kw.update(changes)
        return cls(**kw)

    def with_design(self, **sections) -> "CoilDesignProblem":
        """Same search space on the design with these sections replaced (typed specs)."""
        return dataclasses.replace(self, design=dataclasses.replace(self.design, **sections))

    def with_wire(self, bare_m: float, insulated_m: float | None = None) -> "CoilDesignProblem":
        """Same problem with another wire (bounds that depend on d_ins are kept)."""
        ins = insulated_diameter_for(bare_m) if insulated_m is None else insulated_m
        return self.with_design(wire=dataclasses.replace(
            self.design.wire, diameter_m=bare_m, insulated_diameter_m=ins))

    # ------------------------------------------------------------------ the design's numbers
    @property
    def wire_diameter_m(self) -> float:
        return self.design.wire.diameter_m

    @property
    def insulated_diameter_m(self) -> float:
        return self.design.wire.insulated_diameter_m

    @cached_property
    def resistivity_ohm_m(self) -> float:
        """Copper resistivity at the wire's operating temperature, ohm m."""
        return el.resistivity(self.design.wire)

    @property
    def core_relative_permeability(self) -> float:
        """The design core's (or the default core's) relative permeability."""
        core = self.design.core
        return (core if core is not None else CoreSpec()).relative_permeability

    @property
    def core_protrusion_m(self) -> float:
        """Core length beyond each end of the winding when it is not a variable, m."""
        core = self.design.core
        if core is None:
            return THESIS_CORE_PROTRUSION_M
        return max(0.0, 0.5 * (core.length_m - self.design.coil.length_m))

    # ------------------------------------------------------------------ model
    @property
    def packing_factor(self) -> float:
        return el.packing_factor(self.packing)

    def turns(self, x) -> float:
        return (x[1] - x[0]) * x[2] / (self.insulated_diameter_m ** 2 * self.packing_factor)

    def _protrusion(self, x) -> float:
        return x[3] if len(self.variables) > 3 else self.core_protrusion_m

    def air_force(self, x, *, turns: float | None = None):
        """|Fz| of the air winding at the design point, N, and d|Fz|/dx (complex step)."""
        ri, ro, ln = x[0], x[1], x[2]
        n = self.turns(x) if turns is None else turns
        j = n * self.current_a / ((ro - ri) * ln)
        g = axial_gradient_per_current_density(ri, ro, ln, self.height_m)
        f = -self.moment_a_m2 * j * g
        if turns is not None:
            return float(f), None
        # J is geometry-independent for a fully packed section: differentiate g only
        h = 1e-30
        xs = np.array([ri, ro, ln], dtype=complex) + 1j * h * np.eye(3)
        dg = axial_gradient_per_current_density(xs[:, 0], xs[:, 1], xs[:, 2],
                                                self.height_m).imag / h
        return float(f), -self.moment_a_m2 * j * dg

    def resistance(self, x, turns: float | None = None) -> float:
        n = self.turns(x) if turns is None else turns
        return el.resistance_from_geometry(x[0], x[1], n, self.wire_diameter_m,
                                           self.resistivity_ohm_m)

    def _resistance_grad(self, x) -> np.ndarray:
        # R = rho pi (Ro^2 - Ri^2) Lc / (p d_ins^2 A_w)
        c = (self.resistivity_ohm_m * math.pi
             / (self.packing_factor * self.insulated_diameter_m ** 2
                * math.pi * self.wire_diameter_m ** 2 / 4.0))
        return np.array([-2 * x[0] * x[2] * c, 2 * x[1] * x[2] * c,
                         (x[1] ** 2 - x[0] ** 2) * c])

    def _core_coil(self, x, turns_ref: int = 1000) -> Coil:
        core = Core(radius=x[0], length=x[2] + 2 * self._protrusion(x),
                    relative_permeability=self.core_relative_permeability, offset=0.0,
                    model=self.core_model)
        return Coil(x[0], x[1], x[2], turns_ref, core)

    def _core_parts(self, x, turns: float) -> tuple[float, float]:
        """(|Fz| added by the core, N; extra inductance, H) for the continuous design."""
        ref = 1000
        coil = self._core_coil(x, ref)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SaturationWarning)
            p = np.array([[0.0, 0.0, self.height_m + x[2] / 2]])
            _, g = coil.core.field_local(p, coil, self.current_a * turns / ref, gradient=True)
            extra = coil.core.extra_inductance(coil) * (turns / ref) ** 2
        return float(-self.moment_a_m2 * g[0, 2, 2]), float(extra)

    def evaluate(self, x, *, turns: float | None = None, gradient: bool = False):
        """Model numbers at x; with ``gradient`` also (d force, d constraints) w.r.t. x.

        ``turns``: override the continuous turns (used for the rounded design).
        """
        x = tuple(float(q) for q in x)
        if gradient and turns is not None:
            raise BadInputError("turns", "None when gradient=True (gradients are at the "
                                "geometry's continuous turns)", turns)
        n = self.turns(x) if turns is None else float(turns)
        if gradient:
            f_air, df = self.air_force(x)
        else:
            f_air = self.air_force(x, turns=n)[0]
        r = self.resistance(x, n)
        if gradient:
            ell, dl = el.air_inductance_from_geometry(x[0], x[1], x[2], n,
                                                      t_max=self.inductance_t_max, gradient=True)
        else:
            ell = el.air_inductance_from_geometry(x[0], x[1], x[2], n,
                                                  t_max=self.inductance_t_max)
        f = f_air
        if self.core_model != "air":
            fc, lc = self._core_parts(x, n)
            f += fc
            ell += lc
        tau = ell / r
        cons = (r / self.max_resistance_ohm - 1.0,
                5.0 * tau / self.max_settling_time_s - 1.0,
                (x[0] + self.insulated_diameter_m - x[1]) / self.insulated_diameter_m)
        ev = Evaluation(x, n, f, r, ell, tau, self.current_a ** 2 * r, cons)
        if not gradient:
            return ev
        nv = len(x)
        dn = np.zeros(nv)
        pk = self.insulated_diameter_m ** 2 * self.packing_factor
        dn[:3] = [-x[2] / pk, x[2] / pk, (x[1] - x[0]) / pk]
        grad_f = np.zeros(nv)
        grad_f[:3] = df
        grad_r = np.zeros(nv)
        grad_r[:3] = self._resistance_grad(x)
        # the air inductance gradient is at fixed turns: add the N^2 dependence
        grad_l = np.zeros(nv)
        grad_l[:3] = np.array(dl) + 2.0 * (ell if self.core_model == "air" else
                                           ell - lc) / n * dn[:3]
        if self.core_model != "air":
            step = 1e-6
            for k in range(nv):
                xp, xm = list(x), list(x)
                xp[k] += step
                xm[k] -= step
                if k == 3:
                    xm[k] = max(xm[k], 0.0)
                fp, lp = self._core_parts(xp, self.turns(xp))
                fm, lm = self._core_parts(xm, self.turns(xm))
                grad_f[k] += (fp - fm) / (xp[k] - xm[k])
                grad_l[k] += (lp - lm) / (xp[k] - xm[k])
        grad_tau = grad_l / r - ell / r ** 2 * grad_r
        grad_c = np.zeros((3, nv))
        grad_c[0] = grad_r / self.max_resistance_ohm
        grad_c[1] = 5.0 * grad_tau / self.max_settling_time_s
        grad_c[2, 0] = 1.0 / self.insulated_diameter_m
        grad_c[2, 1] = -1.0 / self.insulated_diameter_m
        return ev, grad_f, grad_c


@dataclass(frozen=True)
class DesignResult:
    """The optimized coil, rounded to whole turns, evaluated with the field engine (SI)."""

    inner_radius_m: float
    outer_radius_m: float
    length_m: float
    turns: int
    turns_continuous: float
    core_protrusion_m: float | None
    resistance_ohm: float
    inductance_h: float
    time_constant_s: float
    current_a: float
    power_w: float
    force_n: float
    force_continuous_n: float
    constraints: dict
    core_model: str


def _constraint_table(problem: CoilDesignProblem, ev: Evaluation, x) -> dict:
    """Each constraint's value, limit, margin (>= 0 when satisfied) and whether it is active
    (margin below 1e-6 of the limit)."""
    items = {  # name: (value, limit, +1 for an upper limit / -1 for a lower limit)
        "resistance_ohm": (ev.resistance_ohm, problem.max_resistance_ohm, 1),
        "settling_time_s": (5 * ev.time_constant_s, problem.max_settling_time_s, 1),
        "outer_radius_m": (x[1], problem.upper[1], 1),
        "length_m": (x[2], problem.upper[2], 1),
        "inner_radius_m": (x[0], problem.lower[0], -1),
        "winding_depth_m": (x[1] - x[0], problem.insulated_diameter_m, -1),
    }
    out = {}
    for name, (val, lim, sense) in items.items():
        margin = (lim - val) * sense
        out[name] = {"value": float(val), "limit": float(lim),
                     "kind": "upper" if sense > 0 else "lower", "margin": float(margin),
                     "active": bool(margin <= 1e-6 * abs(lim))}
    return out


def evaluate_design(problem: CoilDesignProblem, x, turns: int | None = None,
                    *, field_engine: bool = True) -> DesignResult:
    """Evaluate x with whole ``turns`` (default: floor of the continuous turns).

    With ``field_engine`` the force comes from :meth:`designkit.Coil.field` (winding quadrature
    at rtol 1e-10 + the core model), not from the optimizer's closed form.
    """
    x = tuple(float(q) for q in x)
    n_cont = problem.turns(x)
    n = int(math.floor(n_cont + 1e-9)) if turns is None else int(turns)
    n = max(n, 1)
    ev = problem.evaluate(x, turns=n)
    force = ev.force_n
    if field_engine:
        force = force_field_engine(problem, x, n)
    ev_cont = problem.evaluate(x)
    table = _constraint_table(problem, ev, x)
    # activity is a property of the continuous optimum (rounding down leaves a small margin)
    cont = _constraint_table(problem, ev_cont, x)
    for k in table:
        table[k]["active"] = cont[k]["active"]
    prot = problem._protrusion(x) if problem.core_model != "air" else None
    return DesignResult(
        inner_radius_m=x[0], outer_radius_m=x[1], length_m=x[2], turns=n,
        turns_continuous=n_cont, core_protrusion_m=prot, resistance_ohm=ev.resistance_ohm,
        inductance_h=ev.inductance_h, time_constant_s=ev.time_constant_s,
        current_a=problem.current_a, power_w=ev.power_w, force_n=force,
        force_continuous_n=ev_cont.force_n, constraints=table,
        core_model=problem.core_model)


def force_field_engine(problem: CoilDesignProblem, x, turns: int) -> float:
    """|Fz| at the design point from :class:`designkit.Coil` (field engine), N."""
    core = None
    if problem.core_model != "air":
        core = problem._core_coil(x).core
    coil = Coil(x[0], x[1], x[2], turns, core, Pose((0.0, 0.0, -x[2] / 2)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SaturationWarning)
        _, g = coil.field(np.array([0.0, 0.0, problem.height_m]), problem.current_a,
                          gradient=True, rtol=1e-10)
    return float(-problem.moment_a_m2 * g[2, 2])


