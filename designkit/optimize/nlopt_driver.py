"""A small general nlopt driver: maximize with inequality constraints, and quasi-random starts.

:func:`maximize` scales the variables to [0, 1] (finite bounds), runs one nlopt algorithm
(LD_SLSQP by default) from a start and, when SLSQP stops on round-off after real progress,
keeps the best feasible iterate and restarts once from it. :func:`halton` gives randomly
shifted Halton points for multistarts. The textbook tests (tests/test_optimize.py) use the
driver directly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import nlopt
import numpy as np


@dataclass(frozen=True)
class LocalRun:
    """One local solve: start, end point, objective, nlopt return code, evaluations."""

    start: tuple[float, ...]
    x: tuple[float, ...]
    value: float
    feasible: bool
    return_code: int
    evaluations: int


@dataclass(frozen=True)
class SolverOptions:
    """How one local solve runs and when it stops (nlopt's own names)."""

    xtol_rel: float = 1e-10
    """Relative tolerance on the (scaled) variables."""
    ftol_rel: float = 1e-14
    """Relative tolerance on the objective."""
    max_evaluations: int = 500
    algorithm: str = "LD_SLSQP"
    """An nlopt algorithm name (``LD_*`` use the gradients, ``LN_*`` do not)."""
    initial_step: float | None = None
    """First step of a derivative-free algorithm in the scaled variables (None: nlopt's)."""


def maximize(objective: Callable, constraints: Callable | None, n_constraints: int,
             lower: Sequence[float], upper: Sequence[float], start: Sequence[float],
             options: SolverOptions | None = None) -> LocalRun:
    """Maximize ``objective(x) -> (f, grad)`` s.t. ``constraints(x) -> (c, jac)`` <= 0 with nlopt.

    Variables are scaled to [0, 1] internally (bounds must be finite). ``constraints`` may be
    None (then ``n_constraints`` must be 0). ``options``: :class:`SolverOptions` (default:
    SLSQP to 1e-10 in x, at most 500 evaluations).
    """
    o = options or SolverOptions()
    xtol_rel, ftol_rel, max_evaluations = o.xtol_rel, o.ftol_rel, o.max_evaluations
    algorithm, initial_step = o.algorithm, o.initial_step
    lo = np.asarray(lower, dtype=float)
    hi = np.asarray(upper, dtype=float)
    span = hi - lo
    n = len(lo)
    count = [0]

    def unscale(u):
        return lo + np.clip(u, 0.0, 1.0) * span

    history: list[tuple[float, np.ndarray]] = []

    def f_nl(u, grad):
        count[0] += 1
        val, g = objective(unscale(u))
        history.append((float(val), np.array(u, dtype=float)))
        if grad.size:
            grad[:] = np.asarray(g) * span
        return float(val)

    def c_nl(result, u, grad):
        c, jac = constraints(unscale(u))
        result[:] = c
        if grad.size:
            grad[:, :] = np.asarray(jac) * span[None, :]

    def feasible(u) -> bool:
        return not n_constraints or bool(np.all(np.asarray(constraints(unscale(u))[0]) <= 1e-8))

    def best_seen(fallback):
        """SLSQP can stop on round-off after real progress: keep the best feasible iterate."""
        for val, u in sorted(history, key=lambda item: -item[0])[:20]:
            if feasible(u):
                return u
        return fallback

    def run_once(u_start):
        opt = nlopt.opt(getattr(nlopt, algorithm), n)
        opt.set_lower_bounds(np.zeros(n))
        opt.set_upper_bounds(np.ones(n))
        opt.set_max_objective(f_nl)
        if n_constraints:
            opt.add_inequality_mconstraint(c_nl, [1e-10] * n_constraints)
        opt.set_xtol_rel(xtol_rel)
        opt.set_ftol_rel(ftol_rel)
        opt.set_maxeval(max(max_evaluations - count[0], 1))
        if initial_step is not None:
            opt.set_initial_step(float(initial_step))
        try:
            return opt.optimize(u_start), opt.last_optimize_result()
        except nlopt.RoundoffLimited:
            return best_seen(u_start), -4

    u0 = np.clip((np.asarray(start, dtype=float) - lo) / span, 0.0, 1.0)
    u, code = run_once(u0)
    if code == -4 and count[0] < max_evaluations and not np.array_equal(u, u0):
        # one restart from the best iterate: a fresh quasi-Newton model usually finishes
        u2, code2 = run_once(u)
        if objective(unscale(u2))[0] >= objective(unscale(u))[0] and feasible(u2):
            u, code = u2, code2
    x = unscale(u)
    val = objective(x)[0]
    feas = feasible(u)
    return LocalRun(tuple(map(float, start)), tuple(map(float, x)), float(val), feas, int(code),
                    count[0])


def halton(n: int, dim: int, seed: int) -> np.ndarray:
    """Randomly shifted Halton points in [0, 1)^dim, shape (n, dim) (dim <= 10)."""
    primes = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29)[:dim]
    out = np.empty((n, dim))
    for j, b in enumerate(primes):
        for i in range(n):
            f, r, k = 1.0, 0.0, i + 1
            while k:
                f /= b
                r += f * (k % b)
                k //= b
            out[i, j] = r
    shift = np.random.default_rng(seed).random(dim)
    return (out + shift) % 1.0


def halton_box(lo, hi, n: int, seed: int) -> np.ndarray:
    """``n`` shifted-Halton points in the box [lo, hi], shape (n, len(lo))."""
    u = halton(n, len(lo), seed)
    return np.asarray(lo) + u * (np.asarray(hi) - np.asarray(lo))

