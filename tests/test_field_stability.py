"""No NaN/Inf anywhere; exact physical scaling of coils from 1e-6 m to 1e3 m."""

import numpy as np
import pytest

from designkit.design import MU0
from designkit.field import (dipole_field, loop_field, magnetized_cylinder_field,
                             winding_field)

RI, RO, L, N = 0.012, 0.019, 0.100, 1429


def _adversarial(ri, ro, length, a_loop):
    h = length / 2
    rho = [0.0, 1e-300, 1e-200, 1e-15 * ri, ri, ro, 0.5 * (ri + ro), ri * (1 - 1e-12),
           ro * (1 + 1e-15), a_loop, a_loop * (1 + 1e-16), 1e6, 1e3]
    z = [0.0, 1e-300, h, -h, h * (1 + 1e-15), h * (1 - 1e-15), 0.3 * h, 1e6, -1e6, 5 * h]
    R, Z = np.meshgrid(rho, z)
    phi = np.linspace(0, 2 * np.pi, R.size)
    return np.stack([R.ravel() * np.cos(phi), R.ravel() * np.sin(phi), Z.ravel()], 1)


def test_no_nonfinite_values_at_adversarial_points():
    pts = _adversarial(RI, RO, L, 0.0155)
    for b, g in [winding_field(pts, RI, RO, L, N, 6.0, gradient=True),
                 loop_field(pts, 0.0155, 6.0, gradient=True),
                 loop_field(pts, RI, 6.0, gradient=True),
                 magnetized_cylinder_field(pts, RI, L, 1e6, gradient=True),
                 dipole_field(np.vstack([pts, [[0, 0, 0]]]), [0, 0, 1.0], gradient=True)]:
        assert np.all(np.isfinite(b)) and np.all(np.isfinite(g))
    for b in [winding_field(pts, RI, RO, L, N, 6.0, rtol=r) for r in (1e-4, 1e-8, 1e-12)]:
        assert np.all(np.isfinite(b))


def test_documented_values_on_the_wire_and_at_the_dipole():
    b, g = loop_field([[0.0155, 0, 0], [0, -0.0155, 0]], 0.0155, 1.0, gradient=True)
    assert np.all(b == 0) and np.all(g == 0)
    b, g = dipole_field([0, 0, 0], [0, 0, 1.0], gradient=True)
    assert np.all(b == 0) and np.all(g == 0)


def test_winding_on_its_surfaces_is_the_limit_from_both_sides():
    # B is continuous across a volume-current boundary: 1 nm away on either side it changes by
    # at most |G| x 1 nm, |G| ~ mu0 J (1 + |ln d|) at edges and corners (log-singular there)
    mu0j = 4e-7 * np.pi * N * 1.0 / ((RO - RI) * L)
    for rho, z in [(0.0155, L / 2), (RO, 0.01), (RI, -0.02), (RO, L / 2), (RI, -L / 2)]:
        on, g_on = winding_field([rho, 0, z], RI, RO, L, N, 1.0, gradient=True)
        assert np.all(np.isfinite(g_on))
        for d in ([1e-9, 0, 0], [-1e-9, 0, 0], [0, 0, 1e-9], [0, 0, -1e-9]):
            near = winding_field(np.add([rho, 0, z], d), RI, RO, L, N, 1.0)
            assert np.linalg.norm(near - on) <= 1e-9 * mu0j * (1 + abs(np.log(1e-9 / RI)))


@pytest.mark.parametrize("scale", [1e-6, 1e-3, 1.0, 1e3 / RO])
def test_scaled_coils_scale_exactly(scale):
    # same turns and current, geometry x s: B ~ 1/s, G ~ 1/s^2 (at the scaled points)
    rng = np.random.default_rng(5)
    pts = rng.uniform(-0.1, 0.1, (50, 3))
    pts[:5, :2] = 0.0
    b1, g1 = winding_field(pts, RI, RO, L, N, 2.0, gradient=True)
    bs, gs = winding_field(pts * scale, RI * scale, RO * scale, L * scale, N, 2.0,
                           gradient=True)
    np.testing.assert_allclose(bs * scale, b1, rtol=1e-12, atol=1e-14 * np.abs(b1).max())
    np.testing.assert_allclose(gs * scale**2, g1, rtol=1e-11, atol=1e-13 * np.abs(g1).max())
    lb, lg = loop_field(pts, 0.0155, 2.0, gradient=True)
    lbs, lgs = loop_field(pts * scale, 0.0155 * scale, 2.0, gradient=True)
    np.testing.assert_allclose(lbs * scale, lb, rtol=1e-13, atol=1e-15 * np.abs(lb).max())
    np.testing.assert_allclose(lgs * scale**2, lg, rtol=1e-13, atol=1e-15 * np.abs(lg).max())


def test_far_away_1e6_m_is_the_dipole():
    m = N * 1.0 * np.pi * (RI**2 + RI * RO + RO**2) / 3
    p = np.array([[1e6, 0, 0], [0, 0, 1e6], [3e5, -4e5, 6e5]])
    b, g = winding_field(p, RI, RO, L, N, 1.0, gradient=True)
    bd, gd = dipole_field(p, [0, 0, m], gradient=True)
    # per point, in norm: the octupole is (0.05 / 1e6)^2 ~ 3e-15 of the dipole
    assert np.all(np.linalg.norm(b - bd, axis=1) <= 1e-13 * np.linalg.norm(bd, axis=1))
    assert np.all(np.linalg.norm(g - gd, axis=(1, 2)) <= 1e-13 * np.linalg.norm(gd, axis=(1, 2)))
    # the loop at 1e6 radii: m = I pi a^2
    lb = loop_field(p, 0.01, 1.0)
    np.testing.assert_allclose(lb, dipole_field(p, [0, 0, np.pi * 1e-4]), rtol=1e-11,
                               atol=1e-15 * np.abs(lb).max())
    assert MU0 == 4e-7 * np.pi


def test_subnormal_offsets_from_the_axis_keep_a_unit_direction():
    # hypot(5e-324, 5e-324) rounds to 5e-324: x / rho and y / rho would both be 1 (found by
    # hypothesis); G must stay traceless and equal its on-axis value
    for p in [(5e-324, 5e-324, 0.25), (1e-310, -3e-310, 0.1)]:
        b, g = winding_field(p, RI, RO, L, N, 1.0, gradient=True)
        b0, g0 = winding_field((0, 0, p[2]), RI, RO, L, N, 1.0, gradient=True)
        np.testing.assert_allclose(g, g0, rtol=1e-14, atol=1e-14 * np.abs(g0).max())
        np.testing.assert_allclose(b, b0, rtol=1e-14, atol=1e-14 * np.abs(b0).max())
