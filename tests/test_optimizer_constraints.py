"""The constraint vector the optimizers' solvers see, against the electrical model.

Each solver (nlopt, through :func:`designkit.optimize.maximize`) is handed its constraint
function; the tests catch that function on its way in and evaluate it at a design whose
resistance meets the 6 ohm limit cold (20 C) and breaks it hot: the resistance constraint must
be R(T) / Rmax - 1 with R(T) from :mod:`designkit.model.electrical` at the temperature the
limit is stated for (the device problem: its hot temperature, 100 C; the thesis' coil problem:
the wire's operating temperature). A constraint evaluated at the wrong temperature lets the
solver accept a coil that is 31 % over its resistance limit when hot.
"""

from __future__ import annotations

import dataclasses
import importlib

import numpy as np
import pytest

from designkit.design import default_design
from designkit.model import electrical as el
from designkit.optimize import CoilDesignProblem, device_problem_for, solve, solve_device

FAST_MODEL = importlib.import_module("designkit.optimize.fast_model")
SOLVE = importlib.import_module("designkit.optimize.solve")


class _Caught(Exception):
    """Raised by the stand-in for the solver once it has the constraint function."""


def _catch_constraints(monkeypatch, module) -> dict:
    """Replace ``module.maximize`` by a stand-in that records its arguments and stops."""
    seen = {}

    def stand_in(objective, constraints, n_constraints, lower, upper, start, *options, **kw):
        seen.update(constraints=constraints, n=n_constraints, lower=np.asarray(lower),
                    upper=np.asarray(upper))
        raise _Caught

    monkeypatch.setattr(module, "maximize", stand_in)
    return seen


def _length_for_cold_resistance(ri, ro, d_bare, d_ins, wire, target_ohm) -> float:
    """Winding length (m) whose fully packed section has ``target_ohm`` at the wire's
    reference temperature (R is proportional to the length at fixed radii)."""
    n1 = el.turns_continuous(ri, ro, 1.0, d_ins, wire.packing)
    r1 = el.resistance_from_geometry(ri, ro, n1, d_bare, el.resistivity(
        wire, wire.reference_temperature_c))
    return target_ohm / r1


def test_device_solver_sees_the_resistance_at_the_hot_temperature(monkeypatch):
    design = default_design()
    problem = device_problem_for(design)
    wire = design.wire
    t_hot = problem.hot_temperature_c
    assert t_hot == el.DEFAULT_MAX_TEMPERATURE_C == 100.0  # the stated thermal limit
    r_max = design.optimize.max_resistance_ohm
    ri, ro, d = 0.008, 0.0135, 0.5e-3
    d_ins = problem.insulated(d)
    ln = _length_for_cold_resistance(ri, ro, d, d_ins, wire, 5.0)  # 5 ohm cold
    n = el.turns_continuous(ri, ro, ln, d_ins, wire.packing)
    r_cold = el.resistance_from_geometry(ri, ro, n, d, el.resistivity(wire, 20.0))
    r_hot = el.resistance_from_geometry(ri, ro, n, d, el.resistivity(wire, t_hot))
    assert r_cold < r_max < r_hot  # the design that tells the two temperatures apart
    x = [ri, ro, ln, 0.9 * ri, 0.5 * ln, 1e-3, d]
    seen = _catch_constraints(monkeypatch, FAST_MODEL)
    with pytest.raises(_Caught):
        solve_device(problem, starts=1)
    y = np.array(problem.search(x))
    assert np.all(seen["lower"] <= y) and np.all(y <= seen["upper"])
    c, jac = seen["constraints"](y)
    # DEVICE_CONSTRAINTS order: resistance first, then the supply (I R(hot) vs the driver)
    assert c[0] == pytest.approx(r_hot / r_max - 1.0, rel=1e-9)
    assert c[0] > 0.05  # infeasible to the solver: 9.5 % over the limit hot
    i = design.drive.max_current_a
    assert c[1] == pytest.approx(i * r_hot / design.drive.driver_max_voltage_v - 1.0, rel=1e-9)
    assert np.all(np.isfinite(jac))


def test_coil_solver_sees_the_resistance_at_the_operating_temperature(monkeypatch):
    design = default_design()
    hot = dataclasses.replace(design.wire, operating_temperature_c=80.0)
    design = dataclasses.replace(design, wire=hot)
    problem = CoilDesignProblem.from_design(design)
    ri, ro = 0.008, 0.016
    d = hot.diameter_m
    ln = _length_for_cold_resistance(ri, ro, d, hot.insulated_diameter_m, hot, 5.0)
    n = el.turns_continuous(ri, ro, ln, hot.insulated_diameter_m, hot.packing)
    r_op = el.resistance_from_geometry(ri, ro, n, d, el.resistivity(hot, 80.0))
    assert r_op > design.optimize.max_resistance_ohm > 5.0
    seen = _catch_constraints(monkeypatch, SOLVE)
    with pytest.raises(_Caught):
        solve(problem, starts=1)
    c, _ = seen["constraints"](np.array([ri, ro, ln]))
    assert c[0] == pytest.approx(r_op / design.optimize.max_resistance_ohm - 1.0, rel=1e-9)
