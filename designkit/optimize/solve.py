"""Solve the coil problem of thesis eq. 2.14 to its global optimum, and studies on it.

:func:`solve`: nlopt LD_SLSQP from every point of a scrambled Sobol set of starts (the optimum
counts as reached by several starts when at least two agree and none does better), optionally
after nlopt GN_ISRES (global, evolutionary, constrained); variables scaled to [0, 1]. The
reported design is rounded down to whole turns and re-evaluated by the field engine, next to
the thesis' own design (24/38/100 mm, 1429 turns) under the same model. Beyond the thesis:
:func:`optimize_wire` (the standard wire table) and :func:`pareto_front` (force vs time
constant vs power, epsilon-constraint method).
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass, field
from typing import Literal, Sequence

import nlopt
import numpy as np
from scipy.stats import qmc

from ..errors import BadInputError
from ..support import validate as v
from ..support.progress import tqdm
from .coil_problem import CoilDesignProblem, DesignResult, evaluate_design, force_field_engine
from .nlopt_driver import LocalRun, maximize
from .wire_table import METRIC_DIAMETERS_M

GlobalMethod = Literal["multistart", "isres"]
GLOBAL_METHODS: tuple[str, ...] = ("multistart", "isres")
THESIS_POINT = (0.012, 0.019, 0.100)
"""The thesis' coil (Ri, Ro, Lc), m."""
THESIS_TURNS = 1429
THESIS_FORCE_N = 0.780
"""The force the thesis reports for its coil, N."""


@dataclass(frozen=True)
class OptimizeResult:
    best: DesignResult
    x: tuple[float, ...]
    evaluations: int
    """Objective calls made by nlopt (each with its gradient), all stages."""
    model_evaluations: int
    """Distinct model evaluations actually computed (repeated points are cached)."""
    seconds: float
    runs: tuple[LocalRun, ...]
    starts_at_best: int
    global_method: str
    starts_agree: bool
    """At least two starts reach the best objective to 1e-6 and none does better (a multistart
    agreement only; the device problem's :func:`designkit.optimize.verify_device` is the
    global check)."""
    thesis_point: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        b = dataclasses.asdict(self.best)
        out = {**b, "evaluations": self.evaluations,
               "model_evaluations": self.model_evaluations, "seconds": self.seconds,
               "global_method": self.global_method, "local_method": "LD_SLSQP",
               "starts": len(self.runs), "starts_at_best": self.starts_at_best,
               "starts_agree": self.starts_agree,
               "local_optima": [dataclasses.asdict(r) for r in self.runs],
               "thesis_point": self.thesis_point}
        return out


def _starts(problem: CoilDesignProblem, n: int, seed: int) -> np.ndarray:
    """``n`` scrambled Sobol starts in the bounds with a non-empty winding, (n, n_vars)."""
    lo = np.asarray(problem.lower)
    hi = np.asarray(problem.upper)
    with warnings.catch_warnings():  # balance of non-power-of-2 Sobol sets is not needed here
        warnings.simplefilter("ignore", UserWarning)
        u = qmc.Sobol(len(lo), scramble=True, seed=seed).random(n)
    x = lo + u * (hi - lo)
    # start with a non-empty winding: put Ro at least one wire above Ri
    d = problem.insulated_diameter_m
    x[:, 1] = np.maximum(x[:, 1], np.minimum(x[:, 0] + 2 * d, hi[1]))
    return x


def solve(problem: CoilDesignProblem, *, starts: int = 8, global_method: str = "multistart",
          seed: int = 0, isres_evaluations: int = 4000, progress: bool = False,
          thesis_point: bool = True) -> OptimizeResult:
    """Solve the coil design problem to its global optimum (see the module docs).

    Parameters
    ----------
    problem : CoilDesignProblem
    starts : int
        Local SLSQP runs from scrambled Sobol points (multistart), >= 1.
    global_method : {'multistart', 'isres'}
        'isres': nlopt GN_ISRES over the bounds first, then SLSQP from its result and from
        ``starts`` Sobol points.
    seed : int
    progress : bool
        tqdm bar over the starts.

    Returns
    -------
    OptimizeResult
        ``starts_agree`` is True when at least two starts reach the best objective to 1e-6
        relative and no start found a better feasible point.
    """
    if global_method not in GLOBAL_METHODS:
        raise BadInputError("global_method", f"one of {GLOBAL_METHODS}", global_method)
    starts = v.positive_int("starts", starts)
    t0 = time.perf_counter()
    cache: dict = {}
    count = [0]

    def full(x):
        key = tuple(np.round(np.asarray(x, dtype=float), 15))
        if key not in cache:
            count[0] += 1
            if len(cache) > 64:
                cache.clear()
            cache[key] = problem.evaluate(x, gradient=True)
        return cache[key]

    def obj(x):
        ev, gf, _ = full(x)
        return ev.force_n, gf

    def cons(x):
        ev, _, gc = full(x)
        return np.array(ev.constraints), gc

    x0s = list(_starts(problem, starts, seed))
    isres_calls = [0]
    if global_method == "isres":
        x0s.insert(0, _isres(problem, isres_evaluations, seed, isres_calls))
        count[0] += isres_calls[0]
    runs = []
    it = x0s
    if progress:
        it = tqdm(x0s, desc="optimize", unit="start")
    for x0 in it:
        runs.append(maximize(obj, cons, 3, problem.lower, problem.upper, x0))
    feasible = [r for r in runs if r.feasible]
    if not feasible:
        raise BadInputError("bounds", "a region with a design meeting R < Rmax and 5 tau < T",
                            (problem.lower, problem.upper),
                            "No start found a feasible design (infeasible problem).")
    best_run = max(feasible, key=lambda r: r.value)
    at_best = sum(1 for r in feasible if r.value >= best_run.value * (1 - 1e-6))
    seconds = time.perf_counter() - t0
    best = evaluate_design(problem, best_run.x)
    tp = {}
    if thesis_point:
        tp = thesis_point_summary(problem)
    calls = sum(r.evaluations for r in runs) + isres_calls[0]
    return OptimizeResult(best=best, x=best_run.x, evaluations=calls,
                          model_evaluations=count[0], seconds=seconds,
                          runs=tuple(runs), starts_at_best=at_best, global_method=global_method,
                          starts_agree=at_best >= 2, thesis_point=tp)


def _isres(problem: CoilDesignProblem, maxeval: int, seed: int, count) -> np.ndarray:
    """nlopt GN_ISRES (global, stochastic, handles the inequality constraints) -> a start."""
    lo = np.asarray(problem.lower)
    hi = np.asarray(problem.upper)
    n = len(lo)
    nlopt.srand(seed)
    cache = {}

    def ev(u):
        key = tuple(u)
        if key not in cache:
            count[0] += 1
            cache.clear()
            cache[key] = problem.evaluate(lo + u * (hi - lo))
        return cache[key]

    opt = nlopt.opt(nlopt.GN_ISRES, n)
    opt.set_lower_bounds(np.zeros(n))
    opt.set_upper_bounds(np.ones(n))
    opt.set_max_objective(lambda u, g: ev(u).force_n)

    def c(result, u, g):
        result[:] = ev(u).constraints

    opt.add_inequality_mconstraint(c, [1e-8] * 3)
    opt.set_maxeval(maxeval)
    u = opt.optimize(np.full(n, 0.5))
    return lo + u * (hi - lo)


def thesis_point_summary(problem: CoilDesignProblem) -> dict:
    """The thesis' design (24/38/100 mm, 1429 turns) under this problem's model (SI)."""
    x = list(THESIS_POINT)
    if len(problem.variables) > 3:
        x.append(problem.core_protrusion_m)
    ev = problem.evaluate(x, turns=THESIS_TURNS)
    return {
        "inner_radius_m": x[0], "outer_radius_m": x[1], "length_m": x[2],
        "turns": THESIS_TURNS, "resistance_ohm": ev.resistance_ohm,
        "inductance_h": ev.inductance_h, "time_constant_s": ev.time_constant_s,
        "settling_time_s": 5 * ev.time_constant_s,
        "force_n": force_field_engine(problem, x, THESIS_TURNS),
        "thesis_reported_force_n": THESIS_FORCE_N, "feasible": ev.feasible,
        "core_model": problem.core_model,
    }


def optimize_wire(problem: CoilDesignProblem, diameters_m: Sequence[float] | None = None, *,
                  starts: int = 4, progress: bool = False) -> list[tuple[float, OptimizeResult]]:
    """Solve for each standard wire (default: the metric IEC 60317 table), best first.

    Insulated diameter of each: :func:`insulated_diameter_for`. Returns (bare diameter, result)
    sorted by force; diameters whose bounds admit no winding are skipped.
    """
    diameters = METRIC_DIAMETERS_M if diameters_m is None else tuple(diameters_m)
    out = []
    it = diameters
    if progress:
        it = tqdm(diameters, desc="wire table", unit="wire")
    for d in it:
        v.positive("wire diameter", d)
        try:
            p = problem.with_wire(d)
            res = solve(p, starts=starts, thesis_point=False)
        except BadInputError:
            continue
        out.append((d, res))
    out.sort(key=lambda t: -t[1].best.force_n)
    return out


@dataclass(frozen=True)
class ParetoPoint:
    force_n: float
    time_constant_s: float
    power_w: float
    x: tuple[float, ...]
    turns: float


def pareto_front(problem: CoilDesignProblem, *, tau_caps_s: Sequence[float] | None = None,
                 power_caps_w: Sequence[float] | None = None, starts: int = 3,
                 progress: bool = False) -> list[ParetoPoint]:
    """Force vs time constant vs power: non-dominated designs by the epsilon-constraint method.

    For each pair of caps (tau <= tau_cap, I^2 R <= P_cap) maximize the force; keep the
    designs no other design beats in all three (max force, min tau, min power). Default caps:
    6 values of tau up to the problem's T/5 and 6 of power up to I^2 Rmax.
    """
    tmax = problem.max_settling_time_s / 5
    pmax = problem.current_a ** 2 * problem.max_resistance_ohm
    taus = np.geomspace(tmax / 20, tmax, 6) if tau_caps_s is None else np.asarray(tau_caps_s)
    pows = np.linspace(pmax / 6, pmax, 6) if power_caps_w is None else np.asarray(power_caps_w)
    pts = []
    pairs = [(t, p) for t in taus for p in pows]
    it = pairs
    if progress:
        it = tqdm(pairs, desc="pareto", unit="solve")
    for t, p in it:
        sub = problem.with_design(optimize=dataclasses.replace(
            problem.design.optimize, max_settling_time_s=5 * float(t),
            max_resistance_ohm=float(p) / problem.current_a ** 2))
        try:
            res = solve(sub, starts=starts, thesis_point=False)
        except BadInputError:
            continue
        ev = problem.evaluate(res.x)
        pts.append(ParetoPoint(ev.force_n, ev.time_constant_s, ev.power_w, res.x, ev.turns))
    front = []
    for a in pts:
        dominated = any(
            (b.force_n >= a.force_n and b.time_constant_s <= a.time_constant_s
             and b.power_w <= a.power_w)
            and (b.force_n > a.force_n or b.time_constant_s < a.time_constant_s
                 or b.power_w < a.power_w)
            for b in pts)
        if not dominated:
            front.append(a)
    front.sort(key=lambda q: q.force_n)
    return front


