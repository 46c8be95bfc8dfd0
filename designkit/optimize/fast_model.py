"""The corrected fast model as the device optimizer sees it, and its local solve.

:class:`FastModel` evaluates search-variable vectors by the batched fast slice model of
:meth:`DeviceProblem.evaluate_many` (a whole finite-difference stencil in one batch), caches
the values and gives forward-difference gradients; :func:`local_solve` is the local solve on it
(SLSQP; for the rendering objective in epigraph form, polished by COBYLA). The fast model's
core shares are multiplied by the panel/fast ``corrections`` of the problem; how well the
corrected model reproduces the panel model is bounded a posteriori (:data:`RESIDUAL_BOUND`,
docs/optimize.md).
"""

from __future__ import annotations

import numpy as np

from .device_problem import DEVICE_CONSTRAINTS, DeviceProblem
from .nlopt_driver import LocalRun, SolverOptions, maximize

FAST_MODEL_ENVELOPE = {"force_rel_err": (-0.2, 0.6), "inductance_rel_err": (-0.25, 0.1)}
"""Uncorrected fast model / panel model - 1 over the optimizer's bounds (upward force, secant
inductance at the operating current): the envelope that seeded random designs in the bounds
stay inside (tests/test_optimize.py; measured spread: docs/optimize.md). Measured, not proven,
and wide: the fast model only steers the search; the bound claimed for the reported numbers
is :data:`RESIDUAL_BOUND`."""
RESIDUAL_BOUND = 1e-2
"""Stated bound on the corrected fast model at the reported optimum: its upward force and
secant inductance within 1 % of the panel model's (the correction loop of
:func:`designkit.optimize.solve_device` re-solves until the residual meets it)."""


class FastModel:
    """Cached fast evaluations and forward-difference gradients of the search variables.

    A row of :meth:`values_many`: [objective, g (``n_g`` scaled constraints <= 0), then for
    the rendering objective the upward force at each render point (N)]; the objective is the
    design-point force or the smallest render-point force (N).
    """

    def __init__(self, problem: DeviceProblem, fixed: dict[int, float] | None = None):
        self.p = problem
        self.fixed = dict(fixed or {})
        self.free = [k for k in range(problem.n_search) if k not in self.fixed]
        self.lo = np.array([problem.lower[k] for k in self.free])
        self.hi = np.array([problem.upper[k] for k in self.free])
        self.n_g = len(problem.constraint_names)
        self.rendering = problem.objective == "rendering"
        self.cache: dict = {}
        self.air_cache: dict = {}
        self.calls = 0

    def full_y(self, y) -> list[float]:
        x = [0.0] * self.p.n_search
        for k, val in self.fixed.items():
            x[k] = val
        for k, val in zip(self.free, y):
            x[k] = float(val)
        return x

    def full_x(self, y) -> list[float]:
        """Physical design of the free search variables y."""
        return DeviceProblem.physical(self.full_y(y))

    def values(self, y) -> np.ndarray:
        """[objective_n, g_0, ..., g_{n_g - 1}(, forces_n)] at the free variables y (SI)."""
        return self.values_many(np.asarray(y, dtype=float)[None, :])[0]

    def values_many(self, ys) -> np.ndarray:
        """:meth:`values` of the rows of ys (B, n_free), the missing ones in one batch."""
        ys = np.atleast_2d(np.asarray(ys, dtype=float))
        keys = [tuple(np.round(row, 14)) for row in ys]
        miss = [i for i, k in enumerate(keys) if k not in self.cache]
        if miss:
            if len(self.cache) + len(miss) > 4096:
                self.cache.clear()
            xs = np.array([self.full_x(ys[i]) for i in miss])
            n_pts = len(self.p.render_points_m) if self.rendering else 0
            out = np.zeros((len(miss), 1 + self.n_g + n_pts))
            # empty winding: no force, depth constraint violated
            empty = xs[:, 1] <= xs[:, 0] * (1 + 1e-9)
            out[empty, len(DEVICE_CONSTRAINTS)] = (xs[empty, 0] + self.p.insulated(xs[empty, 6])
                                                   - xs[empty, 1]) / 1e-3
            if (~empty).any():
                ev = self.p.evaluate_many(xs[~empty], air_cache=self.air_cache)
                out[~empty, 0] = ev["force_n"]
                out[~empty, 1:1 + len(DEVICE_CONSTRAINTS)] = ev["g"]
                if self.rendering:  # the whole stencil in one batch
                    f = self.p.render_forces_many(xs[~empty])
                    out[~empty, 1 + self.n_g:] = f
                    out[~empty, 0] = f.min(axis=1)
            if self.n_g > len(DEVICE_CONSTRAINTS):  # the coils' pockets keep a frame web
                out[:, 1 + len(DEVICE_CONSTRAINTS)] = [self.p.overlap_m(x) / 1e-3 for x in xs]
            self.calls += len(miss)
            for i, row in zip(miss, out):
                self.cache[keys[i]] = row
        return np.array([self.cache[k] for k in keys])

    def with_gradient(self, y):
        """Values and forward-difference Jacobian (steps 1e-6 of each span), one batch."""
        y = np.asarray(y, dtype=float)
        span = self.hi - self.lo
        h = 1e-6 * span
        # step inwards at the upper bound so the model is never evaluated outside
        h = np.where(y + h > self.hi, -h, h)
        pts = np.vstack([y[None, :], y[None, :] + np.diag(h)])
        vals = self.values_many(pts)
        base = vals[0]
        jac = ((vals[1:] - base[None, :]) / h[:, None]).T
        return base, jac


FEASIBLE_MARGIN = 0.01
"""How far inside every scaled constraint the feasibility stage of :func:`local_solve` goes."""


def feasible_start(model: FastModel, y0, max_evaluations: int = 80) -> np.ndarray:
    """A point of the box where every constraint holds, found from ``y0`` by maximizing the
    smallest scaled margin s (g_i(y) + s <= 0, s <= :data:`FEASIBLE_MARGIN`) with SLSQP;
    ``y0`` itself when it is feasible or none is found."""
    y0 = np.asarray(y0, dtype=float)
    ng, nv = model.n_g, len(y0)
    g0 = model.values(y0)[1:1 + ng]
    if np.all(g0 <= 0):
        return y0

    def margin(u):
        grad = np.zeros(nv + 1)
        grad[-1] = 1.0
        return float(u[-1]), grad

    def cons(u):
        val, jac = model.with_gradient(u[:-1])
        j = np.zeros((ng, nv + 1))
        j[:, :nv] = jac[1:1 + ng]
        j[:, -1] = 1.0
        return val[1:1 + ng] + u[-1], j

    worst = float(np.max(g0))
    run = maximize(margin, cons, ng, np.r_[model.lo, -worst - 1.0], np.r_[model.hi, FEASIBLE_MARGIN],
                   np.r_[y0, -worst], SolverOptions(xtol_rel=1e-6, ftol_rel=1e-9,
                                                    max_evaluations=max_evaluations))
    y = np.asarray(run.x[:-1])
    return y if np.all(model.values(y)[1:1 + ng] <= 1e-8) else y0


def local_solve(model: FastModel, y0, max_evaluations: int = 80, *, xtol_rel: float = 1e-5,
                ftol_rel: float = 1e-9) -> LocalRun:
    """A local solve from y0 on the corrected fast model: SLSQP with the batched
    finite-difference gradient. The rendering objective (a minimum over points of LP values)
    is solved in epigraph form (maximize t subject to t <= F_p(y) at every point), then
    polished by nlopt's derivative-free COBYLA from there: the LP values are kinked where an
    active set changes, and a one-sided difference there can stall SLSQP."""
    options = SolverOptions(xtol_rel=xtol_rel, ftol_rel=ftol_rel, max_evaluations=max_evaluations)
    ng = model.n_g

    def obj(y):
        val, jac = model.with_gradient(y)
        return val[0], jac[0]

    def cons(y):
        val, jac = model.with_gradient(y)
        return val[1:1 + ng], jac[1:1 + ng]

    if not model.rendering:
        return maximize(obj, cons, ng, model.lo, model.hi, y0, options)
    y0 = feasible_start(model, y0)  # the epigraph stage and the polish need a feasible start
    n_pts = len(model.p.render_points_m)
    t_hi = 10.0 * float(np.max(model.values(y0)[1 + ng:])) + 1.0
    nv = len(y0)

    def obj_t(u):
        g = np.zeros(nv + 1)
        g[-1] = 1.0
        return float(u[-1]), g

    def cons_t(u):
        val, jac = model.with_gradient(u[:-1])
        c = np.r_[val[1:1 + ng], u[-1] - val[1 + ng:]]  # N; forces are O(1 N)
        j = np.zeros((ng + n_pts, nv + 1))
        j[:ng, :nv] = jac[1:1 + ng]
        j[ng:, :nv] = -jac[1 + ng:]
        j[ng:, -1] = 1.0
        return c, j

    run = maximize(obj_t, cons_t, ng + n_pts, np.r_[model.lo, 0.0], np.r_[model.hi, t_hi],
                   np.r_[y0, 0.0], options)
    y1 = np.asarray(run.x[:-1])
    v1 = model.values(y1)
    feas1 = bool(np.all(v1[1:1 + ng] <= 1e-8))
    y, val, feas, code, calls = y1, float(v1[0]), feas1, run.return_code, run.evaluations
    if not feas1 or run.return_code not in (1, 3, 4):  # stalled: polish without gradients
        pol = maximize(lambda y_: (model.values(y_)[0], None),
                       lambda y_: (model.values(y_)[1:1 + ng], None), ng, model.lo, model.hi,
                       y1 if feas1 else y0,
                       SolverOptions(xtol_rel=1e-6, ftol_rel=1e-9,
                                     max_evaluations=max_evaluations, algorithm="LN_COBYLA",
                                     initial_step=0.02 if feas1 else None))
        calls += pol.evaluations
        if pol.feasible and (not feas1 or pol.value > val):
            y, val, feas, code = np.asarray(pol.x), pol.value, True, pol.return_code
    return LocalRun(tuple(map(float, y0)), tuple(map(float, y)), float(val), feas, code, calls)


