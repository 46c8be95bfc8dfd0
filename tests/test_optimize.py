"""nlopt coil design: textbook optima, the closed form vs the field engine, the thesis problem."""

import math

import numpy as np
import pytest

from designkit import Coil, default_design
from designkit import electrical as el
from designkit import optimize as opt
from designkit.errors import BadInputError
from designkit.field import loop_field, winding_field
from designkit.pose import Pose


def test_axial_closed_form_matches_the_field_engine():
    for ri, ro, ln, h in [(0.012, 0.019, 0.1, 0.03), (0.005, 0.025, 0.035, 0.01),
                          (0.02, 0.021, 0.01, 0.08)]:
        j = 1000 / ((ro - ri) * ln)
        g = opt.axial_gradient_per_current_density(ri, ro, ln, h) * j
        _, G = winding_field(np.array([0, 0, h + ln / 2]), ri, ro, ln, 1000, 1.0,
                             gradient=True, rtol=1e-12)
        assert g == pytest.approx(G[2, 2], rel=1e-9)


def test_textbook_loop_radius_for_maximum_axial_gradient():
    # |dBz/dz| of a loop on its axis at distance d, ~ a^2 d / (a^2 + d^2)^(5/2), is largest
    # at a = d sqrt(2/3) (d/da = 0)
    d = 0.03

    def f(x):
        def g(a):
            return -loop_field(np.array([0, 0, d]), a, 1.0, gradient=True)[1][2, 2]
        h = 1e-8
        return g(x[0]), [(g(x[0] + h) - g(x[0] - h)) / (2 * h)]

    run = opt.maximize(f, None, 0, [0.001], [0.1], [0.08], xtol_rel=1e-12)
    assert run.x[0] == pytest.approx(d * math.sqrt(2 / 3), rel=1e-6)


def test_nlopt_tutorial_constrained_problem():
    # nlopt tutorial: min sqrt(x2) s.t. x2 >= (a x1 + b)^3, (a, b) = (2, 0), (-1, 1):
    # optimum x = (1/3, 8/27), f = sqrt(8/27)
    def f(x):
        return -math.sqrt(x[1]), [0.0, -0.5 / math.sqrt(x[1])]

    def c(x):
        vals, jac = [], []
        for a, b in ((2.0, 0.0), (-1.0, 1.0)):
            vals.append((a * x[0] + b) ** 3 - x[1])
            jac.append([3 * a * (a * x[0] + b) ** 2, -1.0])
        return np.array(vals), np.array(jac)

    run = opt.maximize(f, c, 2, [-1.0, 1e-6], [2.0, 3.0], [1.234, 2.678])
    assert run.x[0] == pytest.approx(1 / 3, rel=1e-6)
    assert run.x[1] == pytest.approx(8 / 27, rel=1e-6)
    assert -run.value == pytest.approx(math.sqrt(8 / 27), rel=1e-7)


def test_problem_gradients_match_finite_differences():
    p = opt.CoilDesignProblem.from_design(default_design())
    x = (0.011, 0.02, 0.06)
    ev, gf, gc = p.evaluate(x, gradient=True)
    for k in range(3):
        h = 1e-7
        xp, xm = list(x), list(x)
        xp[k] += h
        xm[k] -= h
        a, b = p.evaluate(xp), p.evaluate(xm)
        assert gf[k] == pytest.approx((a.force_n - b.force_n) / (2 * h), rel=1e-6)
        for i in range(2):
            assert gc[i, k] == pytest.approx((a.constraints[i] - b.constraints[i]) / (2 * h),
                                             rel=1e-5, abs=1e-6)


def test_thesis_problem_optimum_is_feasible_global_and_beats_the_thesis_design():
    design = default_design()
    p = opt.CoilDesignProblem.from_design(design)
    res = opt.solve(p, starts=6)
    b = res.best
    assert res.verified_global and res.starts_at_best >= 2
    # independent re-check of the returned design with the Coil object and electrical module
    coil = Coil(b.inner_radius_m, b.outer_radius_m, b.length_m, b.turns,
                pose=Pose((0, 0, -b.length_m / 2)))
    r = el.resistance(coil, design.wire)
    tau = el.inductance(coil) / r
    assert r <= design.optimize.max_resistance_ohm
    assert 5 * tau <= design.optimize.max_settling_time_s
    assert b.outer_radius_m <= design.optimize.max_outer_radius_m * (1 + 1e-12)
    assert b.length_m <= design.optimize.max_length_m * (1 + 1e-12)
    assert b.inner_radius_m >= design.optimize.min_inner_radius_m * (1 - 1e-12)
    turns_fit = el.turns_continuous(b.inner_radius_m, b.outer_radius_m, b.length_m,
                                    design.wire.insulated_diameter_m)
    assert b.turns <= turns_fit
    _, g = coil.field(np.array([0, 0, design.optimize.height_m]), 6.0, gradient=True)
    assert b.force_n == pytest.approx(-design.magnet.moment_a_m2 * g[2, 2], rel=1e-9)
    assert b.force_n > res.thesis_point["force_n"]
    assert b.constraints["resistance_ohm"]["active"]
    # no point of a coarse grid of feasible designs beats it
    for ri in np.linspace(0.005, 0.02, 5):
        for ro in np.linspace(0.01, 0.025, 5):
            for ln in np.linspace(0.01, 0.1, 5):
                if ro > ri + 0.001:
                    ev = p.evaluate((ri, ro, ln))
                    if ev.feasible:
                        assert ev.force_n <= b.force_continuous_n


def test_pareto_front_is_non_dominated_and_respects_caps():
    p = opt.CoilDesignProblem.from_design(default_design())
    front = opt.pareto_front(p, tau_caps_s=[0.001, 0.004], power_caps_w=[100.0, 216.0],
                             starts=2)
    assert len(front) >= 2
    for a in front:
        assert a.time_constant_s <= 0.004 * (1 + 1e-6) and a.power_w <= 216 * (1 + 1e-6)
        for b in front:
            assert not (b.force_n > a.force_n and b.time_constant_s < a.time_constant_s
                        and b.power_w < a.power_w)


def test_wire_table_enumeration():
    p = opt.CoilDesignProblem.from_design(default_design())
    out = opt.optimize_wire(p, [0.5e-3, 0.8e-3], starts=2)
    assert len(out) == 2
    assert out[0][1].best.force_n >= out[1][1].best.force_n
    for d, res in out:
        assert res.best.resistance_ohm <= 6.0


def test_infeasible_bounds_are_rejected():
    d = default_design().replace(**{"optimize.min_inner_radius_m": 0.0248})
    with pytest.raises(BadInputError, match="bound of outer_radius_m"):
        opt.CoilDesignProblem.from_design(d)
    with pytest.raises(BadInputError, match="core_model"):
        opt.CoilDesignProblem.from_design(default_design(), core_model="iron")


def test_core_protrusion_variable_needs_a_core():
    with pytest.raises(BadInputError, match="core_protrusion_m"):
        opt.CoilDesignProblem.from_design(default_design(),
                                          variables=opt.VARIABLES + ("core_protrusion_m",))


def test_freeing_the_core_protrusion_cannot_lower_the_optimum():
    """A relaxation: the 3-variable optimum (protrusion fixed at 5 mm) is a feasible point of
    the 4-variable problem, so its optimum must be at least as large (and its constraints hold).
    Also guards the driver against returning the start point when SLSQP stops on round-off."""
    import warnings

    from designkit.core import SaturationWarning

    design = default_design()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SaturationWarning)
        fixed = opt.CoilDesignProblem.from_design(design, core_model="thesis-uniform")
        free = opt.CoilDesignProblem.from_design(
            design, core_model="thesis-uniform",
            variables=opt.VARIABLES + ("core_protrusion_m",), max_core_protrusion_m=0.02)
        r_fixed = opt.solve(fixed, starts=2)
        r_free = opt.solve(free, starts=2)
    assert r_free.best.force_n >= r_fixed.best.force_n * (1 - 1e-6)
    assert all(c["margin"] >= -1e-6 for c in r_free.best.constraints.values())
