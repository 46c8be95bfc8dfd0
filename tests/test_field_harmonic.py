"""Exterior harmonic expansion of the thick winding: its bound holds, it is refused near the
winding, and it agrees with independent references (on-axis closed form, 30-digit mpmath)."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from designkit.field import harmonic as hm
from designkit.field import reference as ref
from designkit.field import winding_field
from designkit.field.winding import winding_rz

TABLE = Path(__file__).resolve().parent / "data" / "winding_refs.json"


def _geometries(seed, n):
    rng = np.random.default_rng(seed)
    out = [(0.012, 0.019, 0.05)]  # the thesis winding (half-length)
    for _ in range(n):
        ro = 0.01 * 10 ** rng.uniform(-1, 1)
        ri = ro * 10 ** rng.uniform(math.log10(1e-4), math.log10(0.99))
        length = ro * 10 ** rng.uniform(-3, 3)
        out.append((ri, ro, length / 2))
    # the domain's corners
    out += [(1e-4 * 0.01, 0.01, 0.5e-3 * 0.01), (0.99 * 0.01, 0.01, 0.5e3 * 0.01),
            (0.99 * 0.01, 0.01, 0.5e-3 * 0.01), (1e-4 * 0.01, 0.01, 0.5e3 * 0.01)]
    return out


def _points(s, rng, n, t_lo, t_hi):
    t = rng.uniform(t_lo, t_hi, n)
    cos = rng.uniform(-1, 1, n)
    cos[:4] = [1.0, -1.0, 0.0, 1e-9]  # axis and equator
    r = s / t
    return r * np.sqrt(1 - cos**2), r * cos


def test_tail_sums_are_the_series():
    for t in (0.1, 0.5, 0.9):
        k = np.arange(0, 4000, dtype=float)
        for m in (2, 7, 40):
            assert hm.tail_k(m, t) == pytest.approx(np.sum((k * t**k)[m:]), rel=1e-13)
            assert hm.tail_kk(m, t) == pytest.approx(np.sum((k * (k + 1) * t**k)[m:]),
                                                     rel=1e-13)


def test_axis_matches_the_closed_form():
    # on the axis the expansion's Bz against the elementary closed form (log terms)
    ri, ro, h = 0.012, 0.019, 0.05
    s = math.hypot(ro, h)
    z = np.array([1.2, 1.5, 3.0, 10.0]) * s
    done, val = hm.harmonic_rz(ri, ro, h, np.zeros(4), z, False, 1e-10)

    def f(u):
        return u * np.log((ro + np.hypot(ro, u)) / (ri + np.hypot(ri, u)))

    exact = 0.5 * (f(z + h) - f(z - h))
    assert done.all()
    np.testing.assert_allclose(val[1], exact, rtol=1e-10)
    assert np.all(val[0] == 0.0)


@pytest.mark.parametrize("rtol", [1e-4, 1e-6, 1e-8, 1e-10])
def test_bound_holds_on_random_geometries(rtol):
    # reference: the exact path at rtol 1e-12 (checked against mpmath in
    # tests/test_field_winding_random.py); every point the expansion takes meets rtol
    rng = np.random.default_rng(int(-math.log10(rtol)))
    taken = 0
    for ri, ro, h in _geometries(5, 8):
        s = math.hypot(ro, h)
        rho, z = _points(s, rng, 300, 0.02, 0.95)
        for gradient in (False, True):
            done, val = hm.harmonic_rz(ri, ro, h, rho, z, gradient, rtol)
            r_ = winding_rz(ri, ro, h, rho, z, gradient=gradient, rtol=1e-12)
            eb = np.hypot(val[0] - r_[0], val[1] - r_[1]) / np.hypot(r_[0], r_[1])
            assert np.all(eb[done] <= rtol), (ri, ro, h, gradient, eb[done].max() / rtol)
            if gradient:
                # (br_over_rho, dbr_dz, dbz_dz) against the reference's components
                g_ref = np.array([r_[6], r_[3], r_[5]])
                d = val[2:] - g_ref
                full = lambda a: np.sqrt((a[2] + a[0]) ** 2 + a[0] ** 2 + 2 * a[1] ** 2
                                         + a[2] ** 2)
                eg = full(d) / full(g_ref)
                assert np.all(eg[done] <= 10 * rtol), (ri, ro, h, eg[done].max() / rtol)
            taken += int(done.sum())
    assert taken > 1000  # the cheap path is actually exercised


def test_refused_inside_the_enclosing_sphere():
    # near-field points (closer than s / T_MAX to the centre: beside, above and inside the
    # winding, in the bore) never take the expansion, whatever rtol
    rng = np.random.default_rng(3)
    for ri, ro, h in _geometries(9, 6):
        s = math.hypot(ro, h)
        rho, z = _points(s, rng, 400, 1.0 / hm.T_MAX + 1e-9, 50.0)
        rho = np.concatenate([rho, [0.5 * (ri + ro), ro * 1.001, 0.0, 0.5 * ri]])
        z = np.concatenate([z, [0.0, h, h * 1.001, 0.0]])
        for rtol in (1e-2, 1e-8):
            done, _ = hm.harmonic_rz(ri, ro, h, rho, z, False, rtol)
            assert not done.any()


def test_mpmath_table_points_taken_meet_rtol():
    # the 30-digit references of tests/data/winding_refs.json (charge picture, independent)
    data = json.loads(TABLE.read_text())
    cases = ref.sample_cases(data["seed"], data["n_geometries"])
    n_taken = 0
    for case, d in zip(cases, data["cases"]):
        ri, ro, h = case["ri"], case["ro"], case["length"] / 2
        p = np.asarray(case["point"], dtype=float)
        rho, z = np.array([math.hypot(p[0], p[1])]), np.array([p[2]])
        b_ref = np.array(d["b"])
        for rtol in (1e-4, 1e-8, 1e-11):
            done, val = hm.harmonic_rz(ri, ro, h, rho, z, False, rtol)
            if done[0]:
                n_taken += 1
                b = np.array([val[0, 0] * p[0] / rho[0] if rho[0] else 0.0,
                              val[0, 0] * p[1] / rho[0] if rho[0] else 0.0, val[1, 0]])
                assert np.linalg.norm(b - b_ref) <= rtol * np.linalg.norm(b_ref)
    assert n_taken >= 10


def test_public_function_takes_it_for_many_points_and_stays_within_rtol():
    ri, ro, length = 0.012, 0.019, 0.1
    rng = np.random.default_rng(0)
    n = 6000
    rho = 0.04 * np.sqrt(rng.uniform(0, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    z = length / 2 + rng.uniform(0.003, 0.08, n)
    pts = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)
    b_ref, g_ref = winding_field(pts, ri, ro, length, 1429, 1.0, gradient=True, rtol=1e-12)
    for rtol in (1e-4, 1e-8):
        b, g = winding_field(pts, ri, ro, length, 1429, 1.0, gradient=True, rtol=rtol)
        eb = np.linalg.norm(b - b_ref, axis=1) / np.linalg.norm(b_ref, axis=1)
        eg = np.linalg.norm(g - g_ref, axis=(1, 2)) / np.linalg.norm(g_ref, axis=(1, 2))
        assert eb.max() <= rtol and eg.max() <= 10 * rtol
    assert hm.is_cached(ri, ro, length / 2)
