"""Solve the real device's problem: fast multistart, standard wire, corrected re-solves.

Stages of :func:`solve_device`: SLSQP multistart on the corrected fast model (coarse
tolerances: the starts only find the basin) -> the two IEC 60317 sizes around the continuous
wire, each re-solved -> the a-posteriori correction loop (:func:`correct_for_wire`): the panel
model (:mod:`designkit.cores`, steel1010) at the rounded design, the panel/fast ratios of the
core's shares as corrections, re-solve until the corrected fast model reproduces the panel
model within :data:`RESIDUAL_BOUND` -> whole layers and turns, every reported number the panel
model's. With a varying layout the rounded coil's layout is re-chosen (the pitch by bounded
Brent, a ring's radius and tilt by COBYLA).
Infeasible bounds: :func:`_diagnose_infeasible` names each constraint that cannot be met and
by how much. Method and proof: docs/optimize.md.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import nlopt
import numpy as np
from scipy.optimize import minimize_scalar

from ..design import Design
from ..design.layouts import layout_to_table
from ..errors import BadInputError
from ..model import electrical as el
from ..rules import reachable_height_m
from ..support import validate as v
from ..support.blas import one_blas_thread
from ..support.progress import tqdm
from .candidate import device_candidate
from .device_problem import DEVICE_CONSTRAINTS, DEVICE_VARIABLES, PITCH_VARIABLE, DeviceProblem
from .fast_model import FAST_MODEL_ENVELOPE, RESIDUAL_BOUND, FastModel, local_solve
from .nlopt_driver import LocalRun, SolverOptions, halton_box, maximize
from .search_space import SEARCH_VARIABLES


def _device_starts(problem: DeviceProblem, n: int, seed: int) -> np.ndarray:
    """Shifted-Halton starts made geometrically sensible (core in the bore, Ro above Ri)."""
    x = halton_box(problem.lower, problem.upper, n, seed)
    x[:, 1] = np.maximum(x[:, 1], np.minimum(x[:, 0] + 2e-3, problem.upper[1]))
    return x


def round_design(problem: DeviceProblem, x) -> tuple[list[float], int]:
    """Whole turns: the section shrunk to whole layers x whole turns per layer (layered) or
    the floor of the continuous turns (orthocyclic), core trimmed to stay inside. (x, turns)."""
    x = [float(q) for q in x]
    d = problem.insulated(x[6])
    if problem.packing == "layered":
        layers = max(1, int(math.floor((x[1] - x[0]) / d + 1e-9)))
        per = max(1, int(math.floor(x[2] / d + 1e-9)))
        x[1] = x[0] + layers * d
        x[2] = per * d
        n = layers * per
    else:
        n = el.turns_from_geometry(x[0], x[1], x[2], d, problem.packing)
    x[4] = min(x[4], x[2] + x[5])
    return x, int(n)


@dataclass(frozen=True)
class DeviceResult:
    """The optimized device (SI) and how it was found."""

    x: tuple[float, ...]
    """Rounded design: whole layers and turns per layer."""
    turns: int
    x_continuous: tuple[float, ...]
    """Continuous optimum, :data:`DEVICE_VARIABLES` (+ pitch when it varies)."""
    wire_diameter_m: float
    insulated_diameter_m: float
    evaluation: dict
    """Panel-model numbers of the rounded design (:meth:`DeviceProblem.evaluate`)."""
    constraints: dict
    corrections: tuple[float, float]
    correction_history: tuple
    starts: tuple[LocalRun, ...]
    fast_evaluations: int
    panel_evaluations: int
    seconds: float
    fast_model_check: dict = field(default_factory=dict)
    """The fast model against the panel model at the reported design (:func:`_fast_vs_panel`;
    method, bound, residual, whether within it)."""
    rendering: dict = field(default_factory=dict)
    """Rendering objective of the reported design (objective 'rendering' only)."""
    core_model: str = "steel1010 (fast slice model corrected by the surface-current panel model)"

    @property
    def feasible(self) -> bool:
        return all(c["met"] for c in self.constraints.values())

    def as_dict(self, problem: DeviceProblem) -> dict:
        ev = self.evaluation
        ri, ro, ln, a, lc, prot, d = self.x[:7]
        names = DEVICE_VARIABLES + problem.space.layout_names
        out = {
            "inner_radius_m": ri, "outer_radius_m": ro, "length_m": ln, "turns": self.turns,
            "wire_diameter_m": d, "insulated_wire_diameter_m": self.insulated_diameter_m,
            "core_radius_m": a, "core_length_m": lc, "core_protrusion_m": prot,
            "core_offset_m": DeviceProblem.core_offset(self.x),
            "resistance_ohm": ev["resistance_ohm"],
            "resistance_cold_ohm": ev["resistance_cold_ohm"],
            "inductance_h": ev["inductance_h"], "inductance_kind": "secant at current_a",
            "inductance_air_h": ev["inductance_air_h"],
            "time_constant_s": ev["time_constant_s"], "settling_time_s": ev["settling_time_s"],
            "supply_voltage_v": problem.supply_voltage_v, "current_a": problem.current_a,
            "voltage_needed_v": ev["voltage_needed_v"],
            "force_n": ev["force_n"],
            "force_definition": "largest upward Fz (z up, on the magnet) the coil renders at "
                                "the design point with |I| <= current_a (bipolar drive)",
            "dbz_dz_t_per_m": ev["dbz_dz_winding_t_per_m"] + ev["dbz_dz_core_t_per_m"],
            "design_height_m": problem.height_m,
            "peak_core_flux_density_t": ev["peak_core_flux_density_t"],
            "time_to_max_temperature_s": ev["time_to_max_temperature_s"],
            "copper_mass_kg": ev["copper_mass_kg"],
            "core_model": self.core_model, "temperature_c": problem.hot_temperature_c,
            "cold_temperature_c": problem.cold_temperature_c,
            "render_duty": problem.render_duty, "packing": problem.packing,
            "seconds": self.seconds, "fast_evaluations": self.fast_evaluations,
            "panel_evaluations": self.panel_evaluations,
            "corrections": {"force": self.corrections[0], "linkage": self.corrections[1]},
            "correction_history": [list(map(float, c)) for c in self.correction_history],
            "fast_model_check": self.fast_model_check,
            "rendering": self.rendering or None,
            "continuous_optimum": dict(zip(names, map(float, self.x_continuous))),
            "search_variables": list(problem.space.names),
            "objective": problem.objective, "pitch_m": problem.spacing_of(self.x),
            "pitch_varied": problem.pitch_bounds_m is not None,
            "layout": layout_to_table(problem.layout_of(self.x)),
            "layout_varied": list(problem.space.layout_names),
            "starts": len(self.starts),
            "local_optima": [dataclasses.asdict(r) for r in self.starts],
            "constraints": self.constraints,
            "margins": {k: c["margin"] for k, c in self.constraints.items()},
            "feasible": self.feasible,
        }
        return out


def _diagnose_infeasible(problem: DeviceProblem) -> BadInputError:
    """Which constraint makes the bounds infeasible, and by how much (fast model)."""
    # the constraints do not depend on the objective: diagnose on the cheap one
    model = FastModel(dataclasses.replace(problem, objective="design-point"))
    names = DEVICE_CONSTRAINTS
    worst = []
    y0 = _device_starts(problem, 1, 1)[0]
    n_var = len(y0)
    for i, name in enumerate(names):
        def f(u, grad, i=i):
            y = model.lo + u * (model.hi - model.lo)
            val, jac = model.with_gradient(y)
            if grad.size:
                grad[:] = jac[1 + i] * (model.hi - model.lo)
            return float(val[1 + i])
        opt = nlopt.opt(nlopt.LD_SLSQP, n_var)
        opt.set_lower_bounds(np.zeros(n_var))
        opt.set_upper_bounds(np.ones(n_var))
        opt.set_min_objective(f)
        opt.set_maxeval(200)
        opt.set_xtol_rel(1e-6)
        u0 = (y0 - model.lo) / (model.hi - model.lo)
        try:
            u = opt.optimize(u0)
        except nlopt.RoundoffLimited:
            u = u0
        best = f(u, np.zeros(0))
        if best > 1e-6:
            worst.append((best, name))
    scale = {"resistance_ohm": (problem.max_resistance_ohm, "ohm"),
             "supply_voltage_v": (problem.supply_voltage_v, "V"),
             "settling_time_s": (problem.max_settling_time_s, "s"),
             "time_to_max_temperature_s": (problem.min_time_to_hot_s, "s"),
             "winding_depth_m": (1e-3, "m")}
    if problem.magnet_bottom_clearance_m < 0:
        worst.append((-problem.magnet_bottom_clearance_m, "magnet_bottom_m"))
        scale["magnet_bottom_m"] = (1.0, "m")
    if worst:
        worst.sort(reverse=True)
        parts = []
        for g, name in worst:
            lim, unit = scale[name]
            parts.append(f"{name}: misses its limit by at least {g * lim:.4g} {unit} "
                         f"({g * 100:.3g} % of the limit) at the best point within the bounds")
        return BadInputError("bounds", "bounds that admit a design meeting every constraint",
                             (problem.lower, problem.upper),
                             "Infeasible: " + "; ".join(parts) + ".")
    return BadInputError("bounds", "bounds that admit a design meeting every constraint",
                         (problem.lower, problem.upper),
                         "Each constraint can be met alone but no start met all together "
                         "(they conflict inside these bounds).")


def solve_device(problem: DeviceProblem, *, starts: int = 4, seed: int = 0,
                 max_corrections: int = 4, correction_tol: float = RESIDUAL_BOUND,
                 progress: bool = False) -> DeviceResult:
    """Optimize the device (see :func:`_solve_device`), BLAS on one thread.

    ``max_corrections``: at most this many panel-model evaluations in the correction loop
    (:func:`correct_for_wire`); ``correction_tol``: the residual bound it enforces
    (:data:`RESIDUAL_BOUND`).
    """
    with one_blas_thread():
        return _solve_device(problem, starts=starts, seed=seed,
                             max_corrections=max_corrections, correction_tol=correction_tol,
                             progress=progress)


def _solve_device(problem: DeviceProblem, *, starts: int = 4, seed: int = 0,
                  max_corrections: int = 4, correction_tol: float = RESIDUAL_BOUND,
                  progress: bool = False) -> DeviceResult:
    """Optimize the device (stages in the module docstring): fast multistart -> standard wire ->
    corrected re-solves until the panel model agrees -> whole turns, evaluated by the panel
    model.

    Raises BadInputError naming the constraint (and by how much) when the bounds are
    infeasible.
    """
    starts = v.positive_int("starts", starts)
    t0 = time.perf_counter()
    if problem.magnet_bottom_clearance_m < 0:
        raise _diagnose_infeasible(problem)
    model = FastModel(problem)
    runs = []
    it = list(_device_starts(problem, starts, seed))
    bar = None
    if progress:
        bar = tqdm(total=starts + 2, desc="optimize", unit="stage")
    for y0 in it:
        # coarse tolerances: the starts only have to find the basin; the wire stage polishes
        runs.append(local_solve(model, y0, xtol_rel=1e-3, ftol_rel=1e-6))
        if bar is not None:
            bar.update(1)
    fast_calls = model.calls
    feas = [r for r in runs if r.feasible]
    if not feas:
        if bar is not None:
            bar.close()
        raise _diagnose_infeasible(problem)
    best = max(feas, key=lambda r: r.value)
    # standard wire: the two table sizes around the continuous optimum
    d_cont = best.x[6]
    table = sorted(problem.wire_table_m)
    below = [d for d in table if d <= d_cont]
    above = [d for d in table if d > d_cont]
    cands = ([below[-1]] if below else []) + ([above[0]] if above else [])
    prob = problem
    wire_runs = []
    for d in cands:
        m = FastModel(prob, {6: d})
        r = local_solve(m, [best.x[k] for k in m.free])
        fast_calls += m.calls
        if r.feasible:
            wire_runs.append((r.value, d, m.full_y(r.x)))
    if not wire_runs:
        if bar is not None:
            bar.close()
        raise BadInputError("wire_table_m", "a standard wire near the continuous optimum "
                            f"({d_cont * 1e3:.3f} mm) that admits a feasible design",
                            [round(c * 1e3, 3) for c in cands])
    _, wire, y = max(wire_runs)
    if bar is not None:
        bar.update(1)
    c = correct_for_wire(prob, wire, y, max_corrections=max_corrections,
                          correction_tol=correction_tol)
    if bar is not None:
        bar.update(1)
        bar.close()
    return DeviceResult(
        x=c["x_round"], turns=c["turns"], x_continuous=c["x"], wire_diameter_m=wire,
        insulated_diameter_m=prob.insulated(wire), evaluation=c["evaluation"],
        constraints=c["constraints"], corrections=c["corrections"],
        correction_history=c["history"], starts=tuple(runs),
        fast_evaluations=fast_calls + c["fast_calls"], panel_evaluations=c["panel_calls"],
        seconds=time.perf_counter() - t0, fast_model_check=c["check"],
        rendering=c["rendering"])


def _fast_vs_panel(prob: DeviceProblem, ev_panel: dict, ev_fast_raw: dict,
                   corr: tuple[float, float]) -> dict:
    """Relative errors of the fast model against the panel model at one design: uncorrected,
    and corrected with ``corr`` (force_n and inductance_h; dimensionless)."""
    mom, i = prob.moment_a_m2, prob.current_a
    g_w = ev_panel["dbz_dz_winding_t_per_m"]
    f_p, l_p = ev_panel["force_n"], ev_panel["inductance_h"]
    lam_fast = (ev_fast_raw["inductance_h"] - ev_fast_raw["inductance_air_h"]) * i
    f_c = mom * abs(g_w + ev_fast_raw["dbz_dz_core_t_per_m"] * corr[0])
    l_c = ev_panel["inductance_air_h"] + lam_fast * corr[1] / i
    return {"force_rel_err": f_c / f_p - 1.0, "inductance_rel_err": l_c / l_p - 1.0,
            "uncorrected_force_rel_err": ev_fast_raw["force_n"] / f_p - 1.0,
            "uncorrected_inductance_rel_err": ev_fast_raw["inductance_h"] / l_p - 1.0}


def _best_pitch(prob: DeviceProblem, x, turns: int) -> list[float]:
    """The rounded coil's best pitch (bounded Brent on the rendering objective, xatol 1e-5 m):
    rounding to whole layers shrinks the outer radius, which frees the pitch to move."""
    lo = max(prob.pitch_bounds_m[0], 2 * x[1] + prob.coil_clearance_m)
    hi = prob.pitch_bounds_m[1]
    x = list(x)
    if hi - lo <= 1e-9:
        return x

    def neg(pitch):
        return -float(prob.render_forces(x[:7] + [pitch], turns).min())

    res = minimize_scalar(neg, bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-5})
    # the ends too: the optimum often sits on the no-overlap limit
    cands = [(res.fun, float(res.x)), (neg(lo), lo), (neg(hi), hi)]
    x[7] = min(cands)[1]
    return x


def _best_layout(prob: DeviceProblem, x, turns: int) -> list[float]:
    """The rounded coil's best layout variables: the pitch by :func:`_best_pitch`, others
    (a ring's radius and tilt) by COBYLA from the continuous optimum's under the no-overlap
    constraint (:meth:`DeviceProblem.overlap_m`)."""
    names = prob.space.layout_names
    if names == (PITCH_VARIABLE,):
        return _best_pitch(prob, x, turns)
    x = list(x)
    k = len(SEARCH_VARIABLES)

    def value(v):
        return float(prob.render_forces(x[:k] + list(v), turns).min()), None

    def overlap(v):
        return np.array([prob.overlap_m(x[:k] + list(v)) / 1e-3]), None

    start = x[k:]
    run = maximize(value, overlap, 1, prob.lower[k:], prob.upper[k:], start,
                   SolverOptions(xtol_rel=1e-6, ftol_rel=1e-9, max_evaluations=60,
                                 algorithm="LN_COBYLA", initial_step=0.05))
    if run.feasible and run.value > value(start)[0]:
        x[k:] = list(run.x)
    return x


def correct_for_wire(prob: DeviceProblem, wire: float, y, *, max_corrections: int = 4,
                      correction_tol: float = RESIDUAL_BOUND) -> dict:
    """A-posteriori correction loop for one wire (the proof of the fast model's numbers).

    Each pass: the panel model (validated :mod:`designkit.cores`, steel1010) at the rounded
    design x_k; the *residual* of the corrected fast model that found x_k (force and secant
    inductance, relative to the panel model's, at x_k); if both are within ``correction_tol``
    and the panel model finds x_k feasible, x_k is the answer. Otherwise the panel / fast
    ratios of the core's shares measured at x_k become the corrections and the corrected fast
    model is re-solved from x_k. At most ``max_corrections`` panel evaluations; the reported
    design is always one the panel model evaluated, and ``check['within_bound']`` says whether
    its residual met the bound. Returns the rounded design with its panel-model numbers (SI).
    """
    phys = DeviceProblem.physical
    history = []
    panel_calls = fast_calls = 0
    corr = (1.0, 1.0)
    y = list(y)
    raw = dataclasses.replace(prob, corrections=(1.0, 1.0))
    for k in range(max(int(max_corrections), 1)):
        x_round, n = round_design(prob, phys(y))
        ev_panel = prob.evaluate(x_round, turns=n, model="panel")
        panel_calls += 1
        ev_fast = raw.evaluate(x_round, turns=n)
        check = _fast_vs_panel(prob, ev_panel, ev_fast, corr)
        new = (ev_panel["dbz_dz_core_t_per_m"] / ev_fast["dbz_dz_core_t_per_m"],
               (ev_panel["inductance_h"] - ev_panel["inductance_air_h"])
               / max(ev_fast["inductance_h"] - ev_fast["inductance_air_h"], 1e-30))
        history.append(new)
        used = corr
        within = max(abs(check["force_rel_err"]),
                     abs(check["inductance_rel_err"])) <= correction_tol
        corr = new
        prob = dataclasses.replace(prob, corrections=corr)
        if (within and all(gv <= 1e-9 for gv in ev_panel["g"])) or k + 1 >= max_corrections:
            break
        m = FastModel(prob, {6: wire})
        r = local_solve(m, [y[q] for q in m.free])
        fast_calls += m.calls
        if not r.feasible:
            break
        y = m.full_y(r.x)
    x_cont = phys(y)
    fit = el.turns_from_geometry(x_round[0], x_round[1], x_round[2], prob.insulated(wire),
                                 prob.packing)
    table_c = prob.constraint_table(x_round, ev_panel, fit)
    rendering = {}
    if prob.space.layout_names:
        x_round = _best_layout(prob, x_round, n)
    if prob.objective == "rendering":
        # the array objective of the reported design, its cores scaled by the panel/fast force
        # ratio measured at this design
        f = prob.render_forces(x_round, n)
        rendering = {"min_upward_force_n": float(f.min()), "upward_force_n": f.tolist(),
                     "points_m": [list(q) for q in prob.render_points_m],
                     "pitch_m": prob.spacing_of(x_round),
                     "layout": layout_to_table(prob.layout_of(x_round)),
                     "core_force_ratio": float(corr[0]),
                     "allocation": "LP per point: |I_k| <= current_a, sum |I_k| <= "
                                   "total_current_a, Fx = Fy = 0",
                     "points_note": "the workspace region folded by the array's mirror "
                                    "symmetries (each distinct point once)"}
    check.update({
        "method": "a-posteriori correction: the optimum is re-evaluated by the panel model "
                  "(designkit.cores surface-current, steel1010) and every reported number is "
                  "the panel model's; the corrected fast model that found it must reproduce "
                  "the panel force and secant inductance there within bound_rel, else the "
                  "panel/fast ratios are updated and the problem re-solved",
        "bound_rel": float(correction_tol), "within_bound": bool(within),
        "corrections_used": [float(c) for c in used], "panel_evaluations": panel_calls,
        "uncorrected_envelope_rel": dict(FAST_MODEL_ENVELOPE)})
    return {"x": tuple(map(float, x_cont)), "x_round": tuple(map(float, x_round)),
            "turns": n, "evaluation": ev_panel, "constraints": table_c, "corrections": corr,
            "history": tuple(history), "fast_calls": fast_calls, "panel_calls": panel_calls,
            "feasible": all(t["met"] for t in table_c.values()), "check": check,
            "rendering": rendering}


def device_design(base: Design, result: DeviceResult, problem: DeviceProblem, *,
                  name: str = "optimized") -> Design:
    """The optimum as a complete :class:`Design` (everything not optimized from ``base``).

    Coil, wire (bare and insulated diameter), core (radius, length, offset, 1010 steel B-H),
    drive (supply = the problem's: the design's, at most the driver's rating; current = the
    operating current) and, when they were variables, the layout's keys (pitch, ring radius,
    tilt) come from the result.
    """
    drive = dataclasses.replace(base.drive, supply_voltage_v=problem.supply_voltage_v,
                                max_current_a=problem.current_a)
    # the workspace starts where the magnet can be: above the upper sensor board
    workspace = dataclasses.replace(
        base.workspace, z_min_m=max(base.workspace.z_min_m, reachable_height_m(base)))
    return device_candidate(base, result.x, int(result.turns), result.insulated_diameter_m,
                            name=name, drive=drive, workspace=workspace,
                            array=problem.layout_of(result.x))
