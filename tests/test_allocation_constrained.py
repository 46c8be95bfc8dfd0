"""firmware_io.allocation.allocate_within: the bounded allocation with G I <= h (a scene keeping
Hall sensors in their linear range), against SLSQP on the split currents (an independent QP
solve with the same constraints written out), on the thesis device's force matrices and the
coils' field at its sensors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from firmware_io.allocation import Allocator, allocate, allocate_within
from firmware_io.errors import BadInputError


@pytest.fixture(scope="module")
def device(thesis_array):
    """(force matrices (m, 3, 9) N/A at random workspace points, the coils' field at the 18
    sensors (18, 3, 9) T/A)."""
    from designkit.model.array import force_matrix
    from designkit.design import default_design

    d = default_design()
    rng = np.random.default_rng(21)
    h = d.workspace.half_width_m
    pts = rng.uniform([-h, -h, 0.025], [h, h, 0.05], (12, 3))
    a = thesis_array.actuation_matrix(pts)
    fm = np.einsum("ij,kjl->kil", force_matrix(d.magnet.moment_vector_a_m2), a[:, 3:])
    s = thesis_array.sensor_positions_m().reshape(-1, 3)
    c = thesis_array.actuation_matrix(s)[:, :3, :]
    return fm, c


def _sensor_rows(c, sensors, rest_t, limit_t):
    """(G, h): |C_s I + rest_s| <= limit per axis for the chosen sensors."""
    cs = c[sensors].reshape(-1, c.shape[2])
    b = rest_t[sensors].reshape(-1)
    return np.concatenate([cs, -cs]), np.concatenate([limit_t - b, limit_t + b])


def _reference(fm, f, u, tl, rows, unipolar):
    """SLSQP on the split currents z >= 0 (I = z+ - z-), box, budget and G I <= h written out;
    the best of three starts (0 and two scaled random ones): the objective."""
    g, h = rows
    n = fm.shape[1]
    p = np.eye(n) if unipolar else np.hstack([np.eye(n), -np.eye(n)])
    scale = np.abs(fm).max() * u
    a, b = fm.dot(p) * u / scale, f / scale
    gs, ub = g.dot(p) * u, np.ones(p.shape[1])
    cons = [{"type": "ineq", "fun": lambda z: h - gs.dot(z), "jac": lambda z: -gs},
            {"type": "ineq", "fun": lambda z: tl / u - z.sum(),
             "jac": lambda z: -np.ones_like(z)}]
    best = np.inf
    rng = np.random.default_rng(0)
    for z0 in (np.zeros(p.shape[1]), 0.01 * rng.random(p.shape[1]),
               0.05 * rng.random(p.shape[1])):
        r = minimize(lambda z: float(np.sum((a.dot(z) - b) ** 2)), z0,
                     jac=lambda z: 2 * a.T.dot(a.dot(z) - b), method="SLSQP",
                     bounds=[(0.0, 1.0)] * len(ub), constraints=cons,
                     options={"ftol": 1e-16, "maxiter": 2000})
        z = np.clip(r.x, 0.0, 1.0)
        if np.all(gs.dot(z) <= h + 1e-9) and z.sum() <= tl / u + 1e-9:
            best = min(best, float(np.sum((a.dot(z) - b) ** 2)) * scale ** 2)
    return best


def test_a_constraint_that_does_not_bind_changes_nothing(device):
    fm, c = device
    f = np.array([0.0, 0.0, 0.05])
    x0, r0 = allocate(fm[0], f, 6.0, 54.0)
    rows = _sensor_rows(c, [4, 13], np.zeros((18, 3)), 0.104)
    assert np.all(rows[0].dot(x0) <= rows[1])
    x, r = allocate_within(fm[0], f, 6.0, 54.0, rows)
    assert np.array_equal(x, x0) and r == r0


@pytest.mark.parametrize("unipolar", [False, True])
def test_binding_sensor_limits_match_an_independent_qp(device, unipolar):
    """Targets of ~0.5-1.3 N that need currents beyond what keeps the chosen sensors within
    0.8 x 130 mT: the currents satisfy every bound (box, budget, G I <= h) and render the target
    at least as well as SLSQP (1e-6 relative), while the unconstrained answer breaks G I <= h."""
    fm, c = device
    rng = np.random.default_rng(3 + unipolar)
    bound = 0
    for k in range(12):
        f = rng.normal(size=3) * 0.3 + [0.0, 0.0, 0.9]
        if unipolar:
            f[2] = abs(f[2])
        tl = float(rng.choice([54.0, 20.0]))
        x0, _ = allocate(fm[k], f, 6.0, tl, unipolar=unipolar)
        # the sensors above the three most driven coils, and one at random
        sensors = sorted(set(np.argsort(-np.abs(x0))[:3].tolist() + [int(rng.integers(18))]))
        rest = rng.normal(scale=5e-3, size=(18, 3))
        rows = _sensor_rows(c, sensors, rest, 0.104)
        x, res = allocate_within(fm[k], f, 6.0, tl, rows, unipolar=unipolar)
        assert np.all(np.abs(x) <= 6.0 + 1e-9) and np.abs(x).sum() <= tl * (1 + 1e-12)
        assert unipolar is False or np.all(x >= -1e-12)
        assert np.all(rows[0].dot(x) <= rows[1] + 1e-9)
        r = fm[k].dot(x) - f
        assert res == pytest.approx(float(r.dot(r)), rel=1e-12, abs=1e-30)
        if np.all(rows[0].dot(x0) <= rows[1]):
            continue
        bound += 1
        ref = _reference(fm[k], f, 6.0, tl, rows, unipolar)
        assert res <= ref * (1 + 1e-6) + 1e-12 * float(f.dot(f)), (res, ref)
    assert bound >= 6, "too few problems where the sensor limits bind"


def test_the_allocator_passes_inequalities_and_keeps_its_warm_start(device):
    fm, c = device
    rows = _sensor_rows(c, [0, 4], np.zeros((18, 3)), 0.05)
    alloc = Allocator()
    f = np.array([0.1, 0.0, 0.8])
    x, _ = alloc(fm[1], f, 6.0, 54.0, inequalities=rows)
    xw, _ = allocate_within(fm[1], f, 6.0, 54.0, rows)
    np.testing.assert_allclose(x, xw, rtol=0, atol=1e-12)
    assert alloc.face is not None      # the solve without G warm-started it


@pytest.mark.parametrize("rows, name", [
    ((np.ones((2, 9)), np.array([1.0, -0.1])), "h >= 0"),
    ((np.ones((2, 8)), np.ones(2)), "inequalities"),
    ((np.ones((2, 9)), np.array([1.0, np.nan])), "finite"),
    (3.0, "inequalities"),
])
def test_bad_inequalities_are_named(device, rows, name):
    fm, _ = device
    with pytest.raises(BadInputError, match=name):
        allocate_within(fm[0], [0.0, 0.0, 2.0], 6.0, 54.0, rows)
