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
import math
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from .. import rules
from ..design import Design
from ..errors import BadInputError, DesignkitError, DesignRuleError
from ..model import electrical as el
from ..support import validate as v
from ..support.atomic import atomic_path
from ..support.parallel import run_chunks
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
_ALIASES.update({"wire.diameter_m": "wire_diameter_m", "optimize.height_m": "height_m",
                 "drive.max_current_a": "current_a", "array.pitch_m": "pitch_m",
                 "core.length_m": "core_length_m"})
MAX_DESIGNS = 5_000_000
COLUMNS = ("inner_radius_m", "outer_radius_m", "length_m", "wire_diameter_m", "height_m",
           "current_a", "turns", "force_n", "resistance_ohm", "resistance_temperature_c",
           "resistance_cold_ohm", "inductance_h", "time_constant_s", "power_w", "valid",
           "feasible", "reason", "core_model")
"""Columns of a coil sweep (SI units in the names). ``resistance_ohm`` is the resistance the
limit applies to, at ``resistance_temperature_c``: the device's hot limit
(:data:`designkit.optimize.device_problem.HOT_TEMPERATURE_C`) when the design has a core (the
device constraints apply), else the wire's operating temperature (thesis eq. 2.14);
``resistance_cold_ohm`` is at the wire's operating temperature, the R of ``time_constant_s``
(cold copper: the longest L/R) and ``power_w``."""

RANGES: dict[str, tuple[float, float]] = {
    "inner_radius_m": (1e-4, 0.5), "outer_radius_m": (1e-4, 0.5), "length_m": (1e-4, 1.0),
    "wire_diameter_m": (1e-5, 0.01), "height_m": (1e-3, 1.0), "current_a": (1e-3, 1000.0),
    "pitch_m": (1e-3, 1.0), "core_length_m": (1e-4, 1.0), "core_protrusion_m": (0.0, 0.5),
}
"""Valid range of each swept parameter (SI; a length in m): a value outside is refused before
any work, with the millimetre hint when it reads as millimetres."""
PARAMETER_KEYS: dict[str, tuple[str, ...]] = {
    "inner_radius_m": ("coil.inner_radius_m", "core.radius_m"),
    "outer_radius_m": ("coil.outer_radius_m",),
    "length_m": ("coil.length_m", "core.length_m", "core.offset_m"),
    "wire_diameter_m": ("wire.diameter_m", "wire.insulated_diameter_m"),
    "height_m": ("optimize.height_m",),
    "current_a": ("drive.max_current_a",),
    "pitch_m": ("array.pitch_m",),
    "core_length_m": ("core.length_m", "core.offset_m"),
    "core_protrusion_m": ("core.offset_m",),
}
"""The design keys each swept parameter moves (a core follows its winding); every row's turns
come from its winding section (``coil.turns`` always moves). What
:func:`designkit.commands.common.unfixable_rules` is given."""


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
                 "force_design_point_n", "resistance_ohm", "resistance_temperature_c",
                 "settling_time_s",
                 "voltage_needed_v", "time_to_max_temperature_s", "valid", "feasible", "reason",
                 "core_model")
"""``force_n`` of an array row is the rendering objective: the smallest upward force over the
workspace region (:func:`designkit.optimize.rendering_force`); ``resistance_ohm`` is at the
device's hot limit (``resistance_temperature_c``), where its limit applies; ``reason`` says
why a row is not feasible (empty when it is); ``core_model`` names the force model of every
row."""
ARRAY_CORE_MODEL = "steel1010 fast slice model"
"""The core model of an array sweep row (:mod:`designkit.cores.rod`)."""


def design_core_model(design: Design) -> str:
    """The design's own force model: 'air' without a core, else 'surface-current' (the panel
    model of the design's core, as ``report`` evaluates it)."""
    return "air" if design.core is None else "surface-current"


def parse_param(text: str, parameters: dict[str, str] | None = None) -> ParamRange:
    """Parse ``NAME=START:STOP:N`` (N points, both ends included; N = 1 takes START), SI
    values (a length in m, as the name says).

    Raises BadInputError for an unknown NAME, a malformed range, N < 1 (empty range), or a
    value outside the parameter's range (:data:`RANGES`), with the millimetre hint when the
    number reads as millimetres (``length_m=10:100:3``).
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
        check_value(name, val, which, params[name])
    return ParamRange(name, start, stop, count)


def check_value(name: str, value: float, which: str, what: str) -> float:
    """``value`` of the swept parameter ``name`` inside :data:`RANGES` (and > 0 unless its
    range starts at 0), else BadInputError: the parameter, the value and the range in one line,
    with the millimetre hint for a length that reads as millimetres."""
    lo, hi = RANGES[name]
    unit = "m" if name.endswith("_m") else "A"
    if (lo <= value <= hi) and (value > 0 or lo == 0.0):
        return value
    hint = ""
    if unit == "m" and lo <= value * 1e-3 <= hi:
        hint = (f"Millimetres where metres are expected? {value:g} mm is {value * 1e-3:g} m: "
                f"write {value * 1e-3:g} or {value:g}mm.")
    raise BadInputError(f"--param {name} {which}", f"in [{lo:g}, {hi:g}] {unit} ({what})",
                        value, hint)


def _num(name, s):
    try:
        return float(s)
    except ValueError:
        raise BadInputError(name, "a number", s) from None


@dataclass(frozen=True)
class Grid:
    """The Cartesian product of parameter ranges in row-major order (the last parameter varies
    fastest), served by slices (:meth:`rows`) without being built whole."""

    ranges: tuple[ParamRange, ...]

    @classmethod
    def of(cls, ranges: Sequence[ParamRange]) -> "Grid":
        """The grid of ``ranges``: each parameter at most once, at most :data:`MAX_DESIGNS`."""
        names = [r.name for r in ranges]
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            raise BadInputError("--param", "each parameter at most once", dup)
        total = math.prod(r.count for r in ranges)
        if total > MAX_DESIGNS:
            raise BadInputError("grid size", f"<= {MAX_DESIGNS} designs", total)
        return cls(tuple(ranges))

    @property
    def names(self) -> list[str]:
        return [r.name for r in self.ranges]

    @property
    def size(self) -> int:
        return math.prod(r.count for r in self.ranges)

    def rows(self, start: int, stop: int) -> np.ndarray:
        """Designs ``start`` to ``stop - 1``: values (n, n_params) in :attr:`names` order."""
        idx = np.arange(start, stop)
        if not self.ranges:
            return np.zeros((len(idx), 0))
        sub = np.unravel_index(idx, tuple(r.count for r in self.ranges))
        return np.stack([r.values[i] for r, i in zip(self.ranges, sub)], axis=1)

    def describe(self) -> str:
        """'1000000 designs (100 inner_radius_m x 100 length_m x 100 outer_radius_m)'."""
        parts = " x ".join(f"{r.count} {r.name}" for r in self.ranges)
        return f"{self.size} design{'' if self.size == 1 else 's'} ({parts})"

    def varied_keys(self) -> tuple[str, ...]:
        """The design keys the grid moves (:data:`PARAMETER_KEYS`; ``coil.turns`` always)."""
        return ("coil.turns",) + tuple(k for r in self.ranges for k in PARAMETER_KEYS[r.name])


def grid(ranges: Sequence[ParamRange]) -> tuple[list[str], np.ndarray]:
    """(names, values of shape (n_designs, n_params)) of the Cartesian product (whole)."""
    g = Grid.of(ranges)
    if not ranges:
        return [], np.zeros((1, 0))
    return g.names, g.rows(0, g.size)


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
        t_r, r_lim = limit_resistance(p, dev, x, n, ev.resistance_ohm)
        res.update(turns=n, force_n=ev.force_n, resistance_ohm=r_lim,
                   resistance_temperature_c=t_r, resistance_cold_ohm=ev.resistance_ohm,
                   inductance_h=ev.inductance_h, time_constant_s=ev.time_constant_s,
                   power_w=ev.power_w, valid=True)
        broken = book_violations(p.design, dev, res, p.insulated_diameter_m)
        res["feasible"] = bool(ev.constraints[0] <= 0 and ev.constraints[1] <= 0 and not broken)
        res["reason"] = "; ".join(q for q in [infeasible_reason(p, res)] + broken if q)
        out.append(res)
    return out


def limit_resistance(problem: CoilDesignProblem, device, x, turns: int,
                     cold_ohm: float) -> tuple[float, float]:
    """(temperature, deg C; resistance, ohm) the row's resistance limit applies at: the device
    problem's hot temperature with a core (``device`` not None: its constraints apply), else
    the wire's operating temperature (``cold_ohm``, thesis eq. 2.14)."""
    if device is None:
        return problem.design.wire.operating_temperature_c, cold_ohm
    t = device.hot_temperature_c
    return t, el.resistance_from_geometry(x[0], x[1], turns, problem.wire_diameter_m,
                                          el.resistivity(problem.design.wire, t))


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
        if row["resistance_cold_ohm"] > problem.max_resistance_ohm:
            reasons.append(f"R({problem.design.wire.operating_temperature_c:g} C) > "
                           f"{problem.max_resistance_ohm:g} ohm")
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
        The most designs per task (chunks start at one design and grow to a few seconds of
        work: :func:`designkit.support.parallel.run_chunks`).
    """
    if core_model is None:
        core_model = design_core_model(design)
    if core_model not in CORE_MODEL_NAMES:
        raise BadInputError("core_model", f"one of {CORE_MODEL_NAMES}", core_model)
    if workers is not None:
        workers = v.positive_int("workers", workers)
    chunk_size = v.positive_int("chunk_size", chunk_size)
    g = Grid.of(ranges)
    problem = CoilDesignProblem.from_design(design, core_model=core_model)
    base = _base_row(design, core_model)
    run = run_chunks(evaluate_chunk, (problem, base, g.names), g, workers=workers,
                     scheduler=scheduler, progress=("sweep", "design") if progress else None,
                     max_chunk=chunk_size)
    return _result(g.names, run)


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
                   resistance_temperature_c=p.hot_temperature_c,
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
    g = Grid.of(ranges)
    run = run_chunks(evaluate_array_chunk, (design, g.names), g, workers=workers,
                     scheduler=scheduler,
                     progress=("array sweep", "array") if progress else None,
                     max_chunk=chunk_size)
    return _result(g.names, run)


def _result(names, run) -> SweepResult:
    """The rows of a :func:`designkit.support.parallel.run_chunks` run; the best row is the
    feasible one with the largest ``force_n``."""
    rows = [r for ch in run.results for r in ch]
    feas = [i for i, r in enumerate(rows) if r["feasible"]]
    best = max(feas, key=lambda i: rows[i]["force_n"]) if feas else None
    return SweepResult(tuple(names), rows, best, run.seconds, run.workers, run.backend)


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
