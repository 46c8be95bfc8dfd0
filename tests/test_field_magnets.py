"""Magnetized cylinder vs magpylib Cylinder (the N52 finger magnet, a core-like rod); dipole vs
its closed form and the magnet's far field."""

import numpy as np
import pytest

from designkit.design import MU0, MagnetSpec
from designkit.field import dipole_field, magnetized_cylinder_field
from designkit.field import reference as ref


def _points(radius, length, n=3000, seed=11):
    rng = np.random.default_rng(seed)
    rho = np.concatenate([rng.uniform(0, 3 * radius, n // 2), 10 ** rng.uniform(-12, 2, n // 2)])
    z = np.concatenate([rng.uniform(-2 * length, 2 * length, n // 2),
                        rng.normal(0, 1, n // 2) * 10 ** rng.uniform(-3, 2, n // 2)])
    # within 5 sizes: farther out magpylib's own closed form cancels (eps R^3 / (a^2 L); we
    # measured 5e-3 at 1e4 lengths, where designkit matches mpmath to 2e-16, see below)
    big = 5 * max(radius, length)
    keep = np.hypot(rho, z) < big
    rho, z = rho[keep], z[keep]
    n = rho.size
    phi = rng.uniform(0, 2 * np.pi, n)
    # keep 1e-4 away from the surface: there magpylib (B on the surface = 0) and the
    # conditioning of rho = hypot(x, y) both limit the comparison
    p = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], 1)
    far = (np.abs(np.hypot(p[:, 0], p[:, 1]) - radius) > 1e-4 * radius) & (
        np.abs(np.abs(z) - length / 2) > 1e-4 * length)
    return p[far]


@pytest.mark.parametrize("radius,length,m", [(MagnetSpec().radius_m, MagnetSpec().length_m,
                                               MagnetSpec().magnetization_a_per_m),
                                              (0.012, 0.110, -3.3e5)])
def test_cylinder_matches_magpylib(radius, length, m):
    import magpylib as magpy

    p = _points(radius, length)
    # B / mu0 = H + M: independent of the mu0 each library uses
    b_mp = magpy.func.cylinder_field("B", p, (2 * radius, length), (0, 0, magpy.mu_0 * m))
    b_dk = magnetized_cylinder_field(p, radius, length, m)
    rel = np.linalg.norm(b_dk / MU0 - b_mp / magpy.mu_0, axis=1) / np.linalg.norm(b_mp / magpy.mu_0, axis=1)
    assert rel.max() < 1e-10


def test_n52_magnet_axis_closed_form_and_far_field():
    mag = MagnetSpec()
    a, ln, m = mag.radius_m, mag.length_m, mag.magnetization_a_per_m
    z = np.array([0.0, 0.001, 0.004, ln / 2 + 1e-3, 0.03, 0.1, 1.0])
    b = magnetized_cylinder_field(np.stack([0 * z, 0 * z, z], 1), a, ln, m)
    # axis: Bz = mu0 M / 2 [(z + h)/sqrt((z+h)^2 + a^2) - (z - h)/sqrt((z-h)^2 + a^2)]
    # (in mpmath: in float64 the difference cancels far away)
    import mpmath as mp

    mp.mp.dps = 30
    h = mp.mpf(ln) / 2
    bz = [float(MU0 * m / 2 * ((zz + h) / mp.sqrt((zz + h) ** 2 + a**2)
                              - (zz - h) / mp.sqrt((zz - h) ** 2 + a**2))) for zz in map(mp.mpf, z)]
    np.testing.assert_allclose(b[:, 2], bz, rtol=1e-14)
    # far field: dipole of moment M V (~0.909 A m^2)
    p = np.array([[3.0, -2.0, 5.0]])
    np.testing.assert_allclose(magnetized_cylinder_field(p, a, ln, m),
                               dipole_field(p, [0, 0, mag.moment_a_m2]), rtol=1e-5)
    assert abs(mag.moment_a_m2 - 0.909) < 0.001


def test_dipole_closed_form_and_gradient():
    rng = np.random.default_rng(2)
    mvec = np.array([0.3, -0.2, 0.9])
    p = rng.normal(size=(20, 3)) * 10 ** rng.uniform(-3, 3, (20, 1))
    b, g = dipole_field(p, mvec, gradient=True)
    for pi, bi, gi in zip(p, b, g):
        r = np.linalg.norm(pi)
        ref = 1e-7 * (3 * pi * (mvec @ pi) / r**5 - mvec / r**3)
        np.testing.assert_allclose(bi, ref, rtol=1e-13, atol=1e-16 * np.abs(ref).max())
        # finite differences (relative step) of the closed form
        h = 1e-6 * r
        fd = np.stack([(dipole_field(pi + h * e, mvec) - dipole_field(pi - h * e, mvec)) / (2 * h)
                       for e in np.eye(3)], 1)
        np.testing.assert_allclose(gi, fd, rtol=0, atol=1e-8 * np.abs(gi).max())
        # div B = 0 and curl B = 0 of the field values themselves (through the differences)
        assert abs(np.trace(fd)) <= 1e-8 * np.abs(gi).max()
        np.testing.assert_allclose(fd, fd.T, rtol=0, atol=1e-8 * np.abs(gi).max())


def test_cylinder_far_away_matches_mpmath_without_cancellation():
    mag = MagnetSpec()
    a, ln, m = mag.radius_m, mag.length_m, mag.magnetization_a_per_m
    for rho, z in [(0.00287, -147.3), (3e-7, 105.4), (50.0, 20.0), (2e3, -1e3)]:
        r = ref.sheet_textbook(a, ln / 2, rho, z, dps=40)
        b = magnetized_cylinder_field([rho, 0, z], a, ln, m)
        assert np.linalg.norm(b - MU0 * m * np.array([r[0], 0, r[1]])) <= 1e-14 * np.linalg.norm(b)
