"""Design sweeps: evaluate a grid of coils (force at the design height, R, L, tau, power,
feasibility) or of whole arrays (rendering objective, device constraints) on local worker
processes or on a Dask distributed cluster.

A sweep is the Cartesian product of parameter ranges (:func:`parse_param` reads
``NAME=START:STOP:N``) applied to the design's coil problem
(:class:`designkit.optimize.CoilDesignProblem`); parameters not swept keep the design's values.
Each design is rounded to whole turns (floor of the packed section, at most the rule book's
winding fit) and evaluated with the optimizer's model (closed-form on-axis force, Bessel
inductance); feasible means the coil limits and the whole rule table (as ``designkit check``)
are met. Throughput: docs/optimize.md.
"""

from __future__ import annotations

import collections
import csv
import dataclasses
import itertools
import math
import os
import textwrap
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from .. import rules
from ..design import Design
from ..errors import BadInputError, DesignkitError, DesignRuleError, require
from ..model import electrical as el
from ..support import validate as v
from ..support.atomic import atomic_path
from ..support.progress import tqdm
from . import (CORE_MODEL_NAMES, DEVICE_CONSTRAINTS, CoilDesignProblem, device_candidate,
               device_problem_for, rendering_force)

PARAMETERS: dict[str, str] = {
    "inner_radius_m": "winding inner radius, m",
    "outer_radius_m": "winding outer radius, m",
    "length_m": "winding length, m",
    "wire_diameter_m": "bare wire diameter, m (insulated scales with the design's ratio)",
    "height_m": "magnet height above the coil top, m",
    "current_a": "coil current, A",
}
_ALIASES = {f"coil.{k}": k for k in ("inner_radius_m", "outer_radius_m", "length_m")}
_ALIASES.update({"wire.diameter_m": "wire_diameter_m", "optimize.height_m": "height_m"})
MAX_DESIGNS = 5_000_000
COLUMNS = ("inner_radius_m", "outer_radius_m", "length_m", "wire_diameter_m", "height_m",
           "current_a", "turns", "force_n", "resistance_ohm", "inductance_h", "time_constant_s",
           "power_w", "valid", "feasible", "reason", "core_model")


@dataclass(frozen=True)
class ParamRange:
    name: str
    start: float
    stop: float
    count: int

    @property
    def values(self) -> np.ndarray:
        return np.linspace(self.start, self.stop, self.count)


ARRAY_PARAMETERS: dict[str, str] = {
    "pitch_m": "array pitch (centre to centre), m",
    "core_length_m": "core length, m",
    "core_protrusion_m": "core top above the winding's top face, m",
    "inner_radius_m": "winding inner radius (the core keeps the design's radius ratio), m",
    "outer_radius_m": "winding outer radius, m",
    "length_m": "winding length, m",
    "wire_diameter_m": "bare wire diameter, m (insulated scales with the design's ratio)",
}
"""Parameters of ``designkit sweep --array`` (whole arrays, rendering objective)."""
ARRAY_COLUMNS = ("pitch_m", "inner_radius_m", "outer_radius_m", "length_m", "wire_diameter_m",
                 "core_radius_m", "core_length_m", "core_protrusion_m", "turns", "force_n",
                 "force_design_point_n", "resistance_ohm", "settling_time_s",
                 "voltage_needed_v", "time_to_max_temperature_s", "valid", "feasible", "reason",
                 "core_model")
"""``force_n`` of an array row is the rendering objective: the smallest upward force over the
workspace region (:func:`designkit.optimize.rendering_force`); ``reason`` says why a row is not
feasible (empty when it is); ``core_model`` names the force model of every row."""
ARRAY_CORE_MODEL = "steel1010 fast slice model"
"""The core model of an array sweep row (:mod:`designkit.cores.rod`)."""


def design_core_model(design: Design) -> str:
    """The design's own force model: 'air' without a core, else 'surface-current' (the panel
    model of the design's core, as ``report`` evaluates it)."""
    return "air" if design.core is None else "surface-current"


def parse_param(text: str, parameters: dict[str, str] | None = None) -> ParamRange:
    """Parse ``NAME=START:STOP:N`` (N points, both ends included; N = 1 takes START).

    Raises BadInputError for an unknown NAME, a malformed range, N < 1 (empty range), or
    values outside the parameter's domain (e.g. a negative wire diameter).
    """
    if "=" not in text:
        raise BadInputError("--param", "NAME=START:STOP:N", text)
    name, _, rng = text.partition("=")
    params = PARAMETERS if parameters is None else parameters
    name = _ALIASES.get(name.strip(), name.strip())
    if name not in params:
        raise BadInputError("--param name", f"one of {sorted(params)}", name)
    parts = rng.split(":")
    if len(parts) != 3:
        raise BadInputError(f"--param {name}", "START:STOP:N", rng)
    start = v.finite(f"{name} START", _num(name, parts[0]))
    stop = v.finite(f"{name} STOP", _num(name, parts[1]))
    try:
        count = int(parts[2])
    except ValueError:
        raise BadInputError(f"{name} N", "a whole number >= 1", parts[2]) from None
    if count < 1:
        raise BadInputError(f"{name} N", "a whole number >= 1 (the range is empty)", count)
    if count > 1 and start == stop:
        raise BadInputError(f"{name} STOP", f"!= START ({start}) when N > 1", stop)
    for val, which in ((start, "START"), (stop, "STOP")):
        if not val > 0:
            raise BadInputError(f"{name} {which}", f"> 0 ({params[name]})", val)
    return ParamRange(name, start, stop, count)


def _num(name, s):
    try:
        return float(s)
    except ValueError:
        raise BadInputError(name, "a number", s) from None


def grid(ranges: Sequence[ParamRange]) -> tuple[list[str], np.ndarray]:
    """(names, values of shape (n_designs, n_params)) of the Cartesian product."""
    names = [r.name for r in ranges]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise BadInputError("--param", "each parameter at most once", dup)
    total = math.prod(r.count for r in ranges)
    if total > MAX_DESIGNS:
        raise BadInputError("grid size", f"<= {MAX_DESIGNS} designs", total)
    if not ranges:
        return [], np.zeros((1, 0))
    vals = np.array(list(itertools.product(*(r.values for r in ranges))), dtype=float)
    return names, vals


def _base_row(design: Design, core_model: str) -> dict:
    c, w = design.coil, design.wire
    return {"inner_radius_m": c.inner_radius_m, "outer_radius_m": c.outer_radius_m,
            "length_m": c.length_m, "wire_diameter_m": w.diameter_m,
            "height_m": design.optimize.height_m, "current_a": design.drive.max_current_a,
            "core_model": core_model}


def _row_problem(problem: CoilDesignProblem, height_m: float, current_a: float,
                 wire_diameter_m: float) -> CoilDesignProblem:
    """``problem`` at another design height (m), current (A) and bare wire (m; the insulated
    diameter keeps the design's ratio)."""
    d = problem.design
    ratio = problem.insulated_diameter_m / problem.wire_diameter_m
    return problem.with_design(
        optimize=dataclasses.replace(d.optimize, height_m=height_m),
        drive=dataclasses.replace(d.drive, max_current_a=current_a),
        wire=dataclasses.replace(d.wire, diameter_m=wire_diameter_m,
                                 insulated_diameter_m=wire_diameter_m * ratio))


def evaluate_chunk(problem: CoilDesignProblem, base: dict, names: Sequence[str],
                   values: np.ndarray) -> list[dict]:
    """Evaluate designs (rows of ``values`` for ``names`` over ``base``); worker entry point.

    Invalid geometry (outer radius not one insulated wire above the inner one, no whole turn):
    ``valid = False`` and empty numbers (None). Feasible = valid, R <= Rmax, 5 tau <= T and
    every row of the rule table (:func:`book_violations`: the rule book and, with a core, the
    device constraints) met; ``reason`` names what is not.
    """
    problems: dict = {}  # rows that differ only in the geometry share one problem
    out = []
    for row_vals in values:
        row = dict(base)
        row.update(zip(names, map(float, row_vals)))
        key = (row["height_m"], row["current_a"], row["wire_diameter_m"])  # core_model: shared
        if key not in problems:
            p = _row_problem(problem, *key)
            problems[key] = (p, _device_problem(p.design))
        p, dev = problems[key]
        x = (row["inner_radius_m"], row["outer_radius_m"], row["length_m"])
        n = 0
        if x[1] > x[0]:  # whole turns: the packed section, at most what the rule book fits
            n = min(math.floor(p.turns(x) + 1e-9), el.turns_from_geometry(
                *x, p.insulated_diameter_m, p.design.wire.packing))
        res = dict.fromkeys(COLUMNS)
        res.update(row)
        if x[1] < x[0] + p.insulated_diameter_m or n < 1:
            res.update(turns=max(n, 0), valid=False, feasible=False,
                       reason=infeasible_reason(p, res))
            out.append(res)
            continue
        ev = p.evaluate(x, turns=n)
        res.update(turns=n, force_n=ev.force_n, resistance_ohm=ev.resistance_ohm,
                   inductance_h=ev.inductance_h, time_constant_s=ev.time_constant_s,
                   power_w=ev.power_w, valid=True)
        broken = book_violations(p.design, dev, res, p.insulated_diameter_m)
        res["feasible"] = bool(ev.constraints[0] <= 0 and ev.constraints[1] <= 0 and not broken)
        res["reason"] = "; ".join(q for q in [infeasible_reason(p, res)] + broken if q)
        out.append(res)
    return out


def _device_problem(design: Design):
    """The device problem of a cored design (its constraint formulas), None without a core."""
    if design.core is None:
        return None
    try:
        return device_problem_for(design)
    except DesignkitError:
        return None


def row_design(design: Design, row: dict, insulated_m: float) -> Design:
    """The design of a coil sweep row (SI): the winding, turns and wire of ``row``; a core
    follows the winding as in the force model (the design's core/bore radius ratio, the
    design's protrusions above and below the winding kept). Raises what the design's own
    checks raise (e.g. coils overlapping at the pitch)."""
    c, k = design.coil, design.core
    ri, ro, ln = row["inner_radius_m"], row["outer_radius_m"], row["length_m"]
    if k is None:
        return dataclasses.replace(
            design, coil=dataclasses.replace(c, inner_radius_m=ri, outer_radius_m=ro,
                                             length_m=ln, turns=row["turns"]),
            wire=dataclasses.replace(design.wire, diameter_m=row["wire_diameter_m"],
                                     insulated_diameter_m=insulated_m))
    top = k.offset_m + k.length_m / 2 - c.length_m / 2
    x = [ri, ro, ln, min(ri, ri * k.radius_m / c.inner_radius_m), ln + k.length_m - c.length_m, top,
         row["wire_diameter_m"]]
    d2 = device_candidate(design, x, row["turns"], insulated_m)
    return dataclasses.replace(d2, core=dataclasses.replace(d2.core, bh=k.bh))


def book_violations(design: Design, device, row: dict, insulated_m: float) -> list[str]:
    """The rows of the rule table (as ``designkit check``) a valid coil sweep row breaks:
    'rule NAME' for the rule book (:mod:`designkit.rules`, what ``cad`` refuses included) and,
    with a core, 'NAME limit' for the device constraints of ``device`` (a
    :class:`designkit.optimize.DeviceProblem`) evaluated with the row's own inductance (no
    field solve); 'invalid design (...)' when the design's checks refuse the row."""
    try:
        d2 = row_design(design, row, insulated_m)
    except (DesignkitError, ValueError) as exc:
        if isinstance(exc, DesignRuleError):
            return ["invalid design (coils overlap: 2 x outer radius > pitch)"]
        return [f"invalid design ({getattr(exc, 'name', type(exc).__name__)})"]
    broken = []
    if device is not None and d2.core is not None:
        k = d2.core
        x = [row["inner_radius_m"], row["outer_radius_m"], row["length_m"], k.radius_m,
             k.length_m, k.offset_m + k.length_m / 2 - row["length_m"] / 2,
             row["wire_diameter_m"]]
        # the device formulas with the sweep model's inductance as the secant inductance
        table = device.table_with_inductance(x, row["turns"], row["inductance_h"])
        broken += [f"{name} limit" for name, r in table.items() if not r["met"]]
    broken += [f"rule {r.name}" for r in rules.violations(d2)]
    return broken


def infeasible_reason(problem: CoilDesignProblem, row: dict) -> str:
    """Why a design row is not feasible, in words (empty for a feasible one).

    Geometry first (outer radius not one insulated wire above the inner one: no whole turn),
    then the limits of thesis eq. 2.14 (R <= Rmax, 5 L/R <= T). A length above 1 m is named as
    probably millimetres, the usual slip with ``--param inner_radius_m=6:10:3``.
    """
    reasons = []
    # no per-row numbers here (the row has them): equal reasons group in reason_summary
    if row.get("resistance_ohm") is None:
        if row["outer_radius_m"] < row["inner_radius_m"] + problem.insulated_diameter_m:
            reasons.append(f"outer radius < inner radius + one wire "
                           f"({problem.insulated_diameter_m * 1e3:.3g} mm)")
        else:
            reasons.append("no whole turn fits the winding section")
    else:
        if row["resistance_ohm"] > problem.max_resistance_ohm:
            reasons.append(f"R > {problem.max_resistance_ohm:g} ohm")
        if 5 * row["time_constant_s"] > problem.max_settling_time_s:
            reasons.append(f"5 L/R > {problem.max_settling_time_s * 1e3:g} ms")
    big = [k for k in ("inner_radius_m", "outer_radius_m", "length_m", "wire_diameter_m",
                       "height_m") if row[k] > 1.0]
    if big:
        reasons.append(f"{', '.join(big)} > 1 m: millimetres given where metres are expected?")
    return "; ".join(reasons)


def reason_summary(result: "SweepResult", most: int = 3) -> str:
    """The commonest reasons designs were infeasible, with counts, one per line."""
    counts = collections.Counter(r["reason"] for r in result.rows if not r["feasible"])
    lines = [f"  {n} x {why}" for why, n in counts.most_common(most)]
    if len(counts) > most:
        lines.append(f"  ... and {len(counts) - most} other reasons (column 'reason' of the CSV)")
    return "\n".join(lines)


@dataclass(frozen=True)
class SweepResult:
    names: tuple[str, ...]
    rows: list
    best_index: int | None
    seconds: float
    workers: int
    backend: str


def run_sweep(design: Design, ranges: Sequence[ParamRange], *, workers: int | None = None,
              scheduler: str | None = None, core_model: str | None = None, chunk_size: int = 250,
              progress: bool = True) -> SweepResult:
    """Evaluate the grid; local processes by default, Dask when ``scheduler`` is an address.

    Parameters
    ----------
    design : Design
    ranges : sequence of ParamRange
    workers : int, optional
        Local worker processes (default: the CPU count); 1 runs in this process.
    scheduler : str, optional
        Address of a dask.distributed scheduler (``tcp://host:8786``); the chunks run there.
    core_model : {'air', 'thesis-uniform', 'surface-current'}, optional
        Default: the design's own (:func:`design_core_model`); a cheaper one is an explicit
        choice, named in every row (``core_model``).
    chunk_size : int
        Designs per task.
    """
    if core_model is None:
        core_model = design_core_model(design)
    if core_model not in CORE_MODEL_NAMES:
        raise BadInputError("core_model", f"one of {CORE_MODEL_NAMES}", core_model)
    if workers is not None:
        workers = v.positive_int("workers", workers)
    chunk_size = v.positive_int("chunk_size", chunk_size)
    names, vals = grid(ranges)
    problem = CoilDesignProblem.from_design(design, core_model=core_model)
    base = _base_row(design, core_model)
    chunks = [vals[i:i + chunk_size] for i in range(0, len(vals), chunk_size)]
    return _run_chunks(evaluate_chunk, (problem, base, names), names, chunks, workers=workers,
                       scheduler=scheduler, progress=progress, desc="sweep")


def evaluate_array_chunk(design: Design, names: Sequence[str], values: np.ndarray) -> list[dict]:
    """Evaluate whole arrays (rows of ``values`` for ``names`` over ``design``); worker entry.

    Each row: the design's array with the swept pitch, winding, wire and 1010-steel core (the
    design's core radius / inner radius kept, core top ``core_protrusion_m`` above the
    winding top, the core's bottom where its length puts it), whole turns
    from the layered window, the device constraints of
    :class:`designkit.optimize.DeviceProblem` (fast slice core model) and the rendering
    objective (smallest upward force over the workspace region, LP per point). Invalid rows
    (overlapping coils, no whole turn): valid = False. ``reason``: why a row is invalid or
    which device constraints and rules (:mod:`designkit.rules`) it breaks (empty if feasible).
    """
    c = design.coil
    k = design.core
    ratio = design.wire.insulated_diameter_m / design.wire.diameter_m
    fill = k.radius_m / c.inner_radius_m if k is not None else 1.0
    base = {"pitch_m": design.array.pitch_m, "inner_radius_m": c.inner_radius_m,
            "outer_radius_m": c.outer_radius_m, "length_m": c.length_m,
            "wire_diameter_m": design.wire.diameter_m,
            "core_length_m": k.length_m if k is not None else c.length_m,
            "core_protrusion_m": (k.offset_m + k.length_m / 2 - c.length_m / 2)
            if k is not None else 0.0}
    out = []
    for row_vals in values:
        row = dict(base)
        row.update(zip(names, map(float, row_vals)))
        res = dict.fromkeys(ARRAY_COLUMNS)
        res.update({q: row[q] for q in base})
        res["core_model"] = ARRAY_CORE_MODEL
        res["current_a"] = design.drive.max_current_a  # stated in the figure, not a column
        d_ins = row["wire_diameter_m"] * ratio
        ri, ro, ln = row["inner_radius_m"], row["outer_radius_m"], row["length_m"]
        prot, lc = row["core_protrusion_m"], row["core_length_m"]
        res["core_radius_m"] = ri * fill
        x = [ri, ro, ln, ri * fill, lc, prot, row["wire_diameter_m"]]
        n = 0
        if ro > ri:
            n = el.turns_from_geometry(ri, ro, ln, d_ins, design.wire.packing)
        # no per-row numbers in a reason: equal reasons group in reason_summary
        why = "no whole turn fits the winding section" if n < 1 else ""
        try:
            if why:
                raise BadInputError("row", why, row)
            d2 = device_candidate(design, x, n, d_ins, pitch_m=row["pitch_m"])
        except (DesignkitError, ValueError) as exc:
            if not why:
                why = ("coils overlap (2 x outer radius > pitch)"
                       if isinstance(exc, DesignRuleError) else
                       f"invalid design ({getattr(exc, 'name', type(exc).__name__)})")
            res.update(turns=n, valid=False, feasible=False, reason=why)
            out.append(res)
            continue
        p = device_problem_for(d2)
        ev = p.evaluate(x, turns=n)
        rend = rendering_force(d2, coil_x=x, turns=n)
        broken = [f"{name} limit" for name, g in zip(DEVICE_CONSTRAINTS, ev["g"]) if g > 0]
        broken += [f"rule {r.name}" for r in rules.violations(d2)]
        res.update(turns=n, force_n=rend["min_upward_force_n"],
                   force_design_point_n=ev["force_n"], resistance_ohm=ev["resistance_ohm"],
                   settling_time_s=ev["settling_time_s"],
                   voltage_needed_v=ev["voltage_needed_v"],
                   time_to_max_temperature_s=ev["time_to_max_temperature_s"], valid=True,
                   feasible=not broken, reason="; ".join(broken))
        out.append(res)
    return out


def run_array_sweep(design: Design, ranges: Sequence[ParamRange], *, workers: int | None = None,
                    scheduler: str | None = None, chunk_size: int = 2,
                    progress: bool = True) -> SweepResult:
    """Sweep whole arrays with the rendering objective (:func:`evaluate_array_chunk`);
    local processes by default, a dask.distributed cluster with ``scheduler``. The best row is
    the feasible one with the largest rendering objective."""
    if design.core is None:
        raise BadInputError("design.core", "a core (the array sweep models 1010-steel cores)",
                            None)
    if workers is not None:
        workers = v.positive_int("workers", workers)
    chunk_size = v.positive_int("chunk_size", chunk_size)
    names, vals = grid(ranges)
    chunks = [vals[i:i + chunk_size] for i in range(0, len(vals), chunk_size)]
    return _run_chunks(evaluate_array_chunk, (design, names), names, chunks, workers=workers,
                       scheduler=scheduler, progress=progress, desc="array sweep")


def _run_chunks(fn, head: tuple, names, chunks, *, workers: int | None, scheduler: str | None,
                progress: bool, desc: str) -> SweepResult:
    """Evaluate ``fn(*head, chunk)`` for every chunk (rows of one dict per design) on a dask
    scheduler, local processes or, with one worker or one chunk, in this process; the best
    row is the feasible one with the largest ``force_n``."""
    t0 = time.perf_counter()
    bar = None
    if progress:
        bar = tqdm(total=sum(len(ch) for ch in chunks), desc=desc, unit="design")
    results: list = [None] * len(chunks)
    try:
        if scheduler is not None:
            backend = f"dask:{scheduler}"
            n_workers = _run_dask_fn(scheduler, fn, head, chunks, results, bar)
        elif (workers or os.cpu_count() or 1) == 1 or len(chunks) == 1:
            backend, n_workers = "serial", 1
            for i, ch in enumerate(chunks):
                results[i] = fn(*head, ch)
                if bar is not None:
                    bar.update(len(ch))
        else:
            n_workers = workers or os.cpu_count() or 1
            backend = "processes"
            with ProcessPoolExecutor(max_workers=n_workers) as ex:
                futs = {ex.submit(fn, *head, ch): i for i, ch in enumerate(chunks)}
                for fut in as_completed(futs):
                    i = futs[fut]
                    results[i] = fut.result()
                    if bar is not None:
                        bar.update(len(chunks[i]))
    finally:
        if bar is not None:
            bar.close()
    rows = [r for ch in results for r in ch]
    feas = [i for i, r in enumerate(rows) if r["feasible"]]
    best = max(feas, key=lambda i: rows[i]["force_n"]) if feas else None
    return SweepResult(tuple(names), rows, best, time.perf_counter() - t0, n_workers, backend)


def _run_dask_fn(address, fn, head: tuple, chunks, results, bar) -> int:
    """Submit ``fn(*head, chunk)`` per chunk to a dask scheduler; fill ``results`` in order."""
    distributed = require("dask.distributed", "dask[distributed]", "designkit sweep --scheduler")
    try:
        client = distributed.Client(address, timeout="10s")
    except OSError as exc:
        raise BadInputError("--scheduler", "the address of a running dask scheduler",
                            address, str(exc)) from None
    try:
        n = max(len(client.scheduler_info().get("workers", {})), 1)
        futs = [client.submit(fn, *head, ch, pure=False) for ch in chunks]
        index = {f.key: i for i, f in enumerate(futs)}
        for fut in distributed.as_completed(futs):
            i = index[fut.key]
            results[i] = fut.result()
            if bar is not None:
                bar.update(len(chunks[i]))
    finally:
        client.close()
    return n


# ====================================================================== output
def write_csv(result: SweepResult, path: str | Path,
              columns: Sequence[str] = COLUMNS) -> Path:
    """Rows as CSV (SI units in the column names; empty cells for invalid geometry)."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(columns)
            for r in result.rows:
                w.writerow(["" if r[c] is None else
                            (int(r[c]) if isinstance(r[c], bool) else r[c]) for c in columns])
    return Path(path)


def plot(result: SweepResult, path: str | Path, *,
         objective: str = "force at the design point",
         limits: str = "R and 5 L/R limits", subtitle: str = "") -> Path:
    """PNG of the force over the (first two) swept parameters: feasible designs coloured by
    force, infeasible ones grey, the best feasible design starred (see :func:`sweep_figure`)."""
    import matplotlib.pyplot as plt

    fig = sweep_figure(result, objective=objective, limits=limits, subtitle=subtitle)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return Path(path)


def _shown(name: str, value: float) -> float:
    return value * 1e3 if name.endswith("_m") else value


def sweep_figure(result: SweepResult, *, objective: str = "force at the design point",
                 limits: str = "R and 5 L/R limits", subtitle: str = ""):
    """The matplotlib figure of :func:`plot`.

    With more than two swept parameters the plot is the slice through the best feasible design
    (the first grid values when none is feasible), and the title says so. The legend sits above
    the axes, where it cannot hide points; a sweep with no feasible design says why in the
    axes instead of showing an empty plot. ``subtitle``: a first title line (e.g. the model,
    current and height the forces assume).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(result.names) or ["inner_radius_m"]
    rows = result.rows
    anchor = rows[result.best_index] if result.best_index is not None else rows[0]
    fixed = names[2:]
    shown = [r for r in rows if all(r[k] == anchor[k] for k in fixed)]
    valid = [r for r in shown if r["valid"]]
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=110)
    xn = names[0]
    if len(names) >= 2:
        yn = names[1]
        inf = [r for r in valid if not r["feasible"]]
        fe = [r for r in valid if r["feasible"]]
        if inf:
            ax.scatter([_shown(xn, r[xn]) for r in inf], [_shown(yn, r[yn]) for r in inf],
                       c="0.7", marker="x", s=10, label="infeasible")
        if fe:
            sc = ax.scatter([_shown(xn, r[xn]) for r in fe], [_shown(yn, r[yn]) for r in fe],
                            c=[r["force_n"] * 1e3 for r in fe], s=14, cmap="viridis",
                            label="feasible")
            fig.colorbar(sc, ax=ax, label=f"{objective} (mN)")
        ax.set_ylabel(_label(yn))
        by = _shown(yn, anchor[yn])
    else:
        xs = [_shown(xn, r[xn]) for r in valid]
        ax.plot(xs, [r["force_n"] * 1e3 for r in valid], "-", color="0.6")
        if any(not r["feasible"] for r in valid):
            ax.scatter([x for x, r in zip(xs, valid) if not r["feasible"]],
                       [r["force_n"] * 1e3 for r in valid if not r["feasible"]], c="0.5",
                       marker="x", s=30, label="infeasible")
        ax.scatter([x for x, r in zip(xs, valid) if r["feasible"]],
                   [r["force_n"] * 1e3 for r in valid if r["feasible"]], s=12, label="feasible")
        ax.set_ylabel(f"{objective} (mN)")
        by = anchor["force_n"] * 1e3 if anchor["force_n"] is not None else None
    if result.best_index is not None:
        ax.plot([_shown(xn, anchor[xn])], [by], "r*", ms=14,
                label=f"best {anchor['force_n'] * 1e3:.0f} mN")
    ax.set_xlabel(_label(xn))
    feasible = sum(1 for r in rows if r["feasible"])
    title = (f"{subtitle}\n" if subtitle else "") + \
        f"{len(rows)} design{'' if len(rows) == 1 else 's'}, {feasible} feasible ({limits})\n" \
        f"{_conditions(anchor, names)}"
    if fixed:
        where = ", ".join(f"{_label(k).split(' (')[0]} = {_shown(k, anchor[k]):.4g}"
                          f"{' mm' if k.endswith('_m') else (' A' if k.endswith('_a') else '')}"
                          for k in fixed)
        title += (f"\nslice at {where} ({len(shown)} of {len(rows)} designs; "
                  f"{'best design' if result.best_index is not None else 'first grid value'})")
    ax.set_title(title, fontsize=9, pad=22)
    if feasible == 0:
        why = [r["reason"] for r in rows if r.get("reason")]
        common = max(set(why), key=why.count) if why else "unknown"
        # at the top of the axes when points are drawn: centred it would hide the middle one
        ax.text(0.5, 0.97 if valid else 0.5,
                "no feasible design\n" + textwrap.fill(f"most common reason: {common}", 48),
                transform=ax.transAxes, ha="center", va="top" if valid else "center",
                fontsize=9, bbox=dict(boxstyle="round", facecolor="white", edgecolor="0.5",
                                      alpha=0.9))
        if not valid:
            ax.set_xticks([])
            ax.set_yticks([])
    if ax.get_legend_handles_labels()[0]:
        # above the axes: a legend inside would sit on the points it names
        ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=3, fontsize=8,
                  frameon=False, borderaxespad=0.1)
    fig.tight_layout()
    return fig


def _conditions(row: dict, swept: Sequence[str]) -> str:
    """'model ..., current ... A, magnet at ... mm' of a figure (the unswept ones)."""
    parts = [f"model: {row.get('core_model') or 'unknown'}"]
    if row.get("current_a") is not None and "current_a" not in swept:
        parts.append(f"current {row['current_a']:g} A")
    if row.get("height_m") is not None and "height_m" not in swept:
        parts.append(f"magnet at {row['height_m'] * 1e3:g} mm above the coil top")
    return ", ".join(parts)


def _label(name: str) -> str:
    return name[:-2] + " (mm)" if name.endswith("_m") else name.replace("_a", " (A)")
