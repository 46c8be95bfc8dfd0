"""The coupled cores' field at a requested rtol (CoreModel.field(rtol=...), the ring rules of
designkit.cores.tolerance) against the reference rules and the fine panel rules, on random
core geometries, physical unknowns (a uniform field and a nearby dipole solved through the
core's own equations) and point classes from inside the core to far away."""

from __future__ import annotations

import math

import numpy as np
import pytest

from designkit.cores.core_model import RINGS_MIN_POINTS, RTOL_RINGS_MIN, core_model

RTOLS = (1e-2, 1e-3, 1e-4)


def _dipole_h(p, src, m):
    d = p - src
    r2 = np.einsum("...i,...i->...", d, d)
    inv3 = 1.0 / (4.0 * math.pi) / (r2 * np.sqrt(r2))
    return (3.0 * (d @ m)[..., None] * d / r2[..., None] - m) * inv3[..., None]


def _case(seed):
    """A random core type and two unknown columns solved from its own equations."""
    rng = np.random.default_rng(seed)
    radius = rng.uniform(2e-3, 8e-3)
    length = radius * rng.uniform(2.0, 12.0)
    ri = radius * rng.uniform(1.05, 1.5)
    key = (ri, ri * rng.uniform(1.5, 3.0), length * rng.uniform(0.6, 1.2), 200)
    model = core_model(radius, length, rng.uniform(-0.2, 0.2) * length,
                       float(rng.uniform(50.0, 3000.0)), key)
    ring = model.ring_points(16)  # (nr, 16, 3)
    src = np.array([2.5 * radius, 0.5 * radius, model.z_hi + radius])
    cols = [np.broadcast_to([0.3, 0.0, 1.0], ring.shape) * 1e3,
            _dipole_h(ring, src, np.array([0.2, -0.5, 1.0]) * 1e-3)]
    rhs = np.stack([model.project(h) for h in cols], axis=1)
    xs = np.linalg.solve(model.self_block(), model.factors()[:, None] * rhs)
    return rng, model, xs


def _points(rng, model, n=150):
    """Near (0.2 - 5 mm off the surface), mid (1 - 3 lengths), far (5 - 20 lengths), the axis,
    inside the core and on its surface."""
    a, lo, hi = model.radius, model.z_lo, model.z_hi
    length = hi - lo
    phi = rng.uniform(0, 2 * np.pi, n)
    out = []
    d = rng.uniform(2e-4, 5e-3, n)
    top = rng.uniform(size=n) < 0.5
    r = np.where(top, rng.uniform(0, a, n), a + d)
    z = np.where(top, hi + d, rng.uniform(lo, hi, n))
    out.append(np.c_[r * np.cos(phi), r * np.sin(phi), z])
    for lo_f, hi_f in ((1.0, 3.0), (5.0, 20.0)):
        u = rng.normal(size=(n, 3))
        u /= np.linalg.norm(u, axis=1)[:, None]
        out.append(u * (length * rng.uniform(lo_f, hi_f, n))[:, None]
                   + [0, 0, 0.5 * (lo + hi)])
    out.append(np.c_[np.zeros(20), np.zeros(20), np.linspace(hi + 1e-4, hi + 5 * length, 20)])
    out.append(np.c_[0.5 * a * np.cos(phi[:20]), 0.5 * a * np.sin(phi[:20]),
                     rng.uniform(lo, hi, 20)])
    out.append(np.c_[a * np.cos(phi[:20]), a * np.sin(phi[:20]), rng.uniform(lo, hi, 20)])
    return np.concatenate(out)


def _ratio(val, ref, rtol):
    """Largest |val - ref| / (rtol |ref|) per point and column (norm over components)."""
    n, k = len(ref), ref.shape[-1]
    e = np.linalg.norm((val - ref).reshape(n, -1, k), axis=1)
    return float(np.max(e / (rtol * np.linalg.norm(ref.reshape(n, -1, k), axis=1))))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_ring_rules_meet_rtol_against_the_reference_rules(seed):
    rng, model, xs = _case(seed)
    pts = _points(rng, model)
    h0, g0 = model.field(pts, xs, gradient=True)
    for rtol in RTOLS:
        h, g = model.field(pts, xs, gradient=True, rtol=rtol)
        assert np.all(np.isfinite(h)) and np.all(np.isfinite(g))
        assert _ratio(h, h0, rtol) <= 1.0
        assert _ratio(g, g0, rtol) <= 10.0
        hb = model.field(pts, xs, rtol=rtol)
        np.testing.assert_allclose(hb, h, rtol=0, atol=1e-12 * np.max(np.abs(h)))
        # the ring rules really serve points (the uniform field's column: most of them)
        served = np.any(model.field(pts, xs[:, :1], rtol=rtol) != h0[..., :1], axis=(1, 2))
        assert np.mean(served) > 0.5


@pytest.mark.parametrize("seed", [4, 5])
def test_ring_rules_against_the_fine_panel_rules(seed):
    """An independent reference: every unknown's field by the fine panel and charge rules."""
    rng, model, xs = _case(seed)
    pts = _points(rng, model, n=200)
    length = model.z_hi - model.z_lo
    mid = 0.5 * (model.z_lo + model.z_hi)
    # outside the core by a radius (the fine rules' own accuracy holds there)
    off = np.maximum.reduce([np.abs(pts[:, 2] - mid) - 0.5 * length,
                             np.hypot(pts[:, 0], pts[:, 1]) - model.radius])
    pts = pts[off > model.radius]
    ref = np.einsum("npu,uk->npk", model.basis_field(pts, fine=True), xs)
    for rtol in (1e-2, 1e-3):
        assert _ratio(model.field(pts, xs, rtol=rtol), ref, rtol) <= 1.0


def test_pointwise_columns_and_own_column():
    rng, model, xs = _case(6)
    pts = _points(rng, model, n=60)
    cols = xs[:, rng.integers(0, 2, len(pts))]
    h, g = model.field(pts, cols, gradient=True, pointwise=True, rtol=1e-3)
    h0, g0 = model.field(pts, cols, gradient=True, pointwise=True)
    # each point's own column chooses its rules (bounds per column): within rtol of it
    assert _ratio(h[..., None], h0[..., None], 1e-3) <= 1.0
    assert _ratio(g.reshape(-1, 9, 1), g0.reshape(-1, 9, 1), 1e-3) <= 10.0
    assert np.any(h != h0)
    # the own column through the single-core rules where the ring rules do not serve
    ho = model.field(pts, xs, own_col=0, rtol=1e-3)
    h0 = model.field(pts, xs, own_col=0)
    assert _ratio(ho, h0, 1e-3) <= 1.0


def test_tighter_requests_and_small_calls_take_the_reference_rules():
    rng, model, xs = _case(7)
    pts = _points(rng, model, n=60)
    np.testing.assert_array_equal(model.field(pts, xs, rtol=0.5 * RTOL_RINGS_MIN),
                                  model.field(pts, xs))
    few = pts[:RINGS_MIN_POINTS - 1]
    np.testing.assert_array_equal(model.field(few, xs, rtol=1e-2), model.field(few, xs))
