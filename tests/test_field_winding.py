"""Thick winding (uniform current density) against independent references.

References: mpmath quadrature over the radius of the textbook K, E, Pi current-sheet field
(designkit.field.reference.winding_textbook, itself checked against a 2-D mpmath quadrature of
textbook loops), the on-axis closed form in mpmath, the dipole far away, a brute-force sum of
loops and magpylib's nested magnetized shells (both converging to the uniform-density model).
"""

import numpy as np
import pytest

from designkit.design import MU0
from designkit.field import dipole_field, loop_field, winding_field
from designkit.field import reference as ref

RI, RO, L, N, I = 0.012, 0.019, 0.100, 1429, 1.3  # the thesis winding
J = N * I / ((RO - RI) * L)


def _ref_cart(point, dps=20):
    rho = float(np.hypot(point[0], point[1]))
    r = ref.winding_textbook(RI, RO, L, rho, point[2], gradient=True, dps=dps)
    b, g = ref.rz_to_cartesian(point, r[0], r[1], (r[2], r[3], r[4], r[5], r[6]))
    return MU0 * J * b, MU0 * J * g


def _rel(a, b):
    return np.linalg.norm(np.asarray(a) - np.asarray(b)) / np.linalg.norm(b)


def _at(rho, z, phi=0.7):
    return np.array([rho * np.cos(phi), rho * np.sin(phi), z])


OUTSIDE = [
    (_at(0.030, 0.060), "above and outside"),
    (_at(0.005, 0.020), "in the bore"),
    (_at(0.025, 0.050), "level with the end face, outside"),
    (_at(0.0, 0.07, 0.0), "on the axis above"),
    (_at(0.0155, 0.052), "2 mm above the end face"),
    pytest.param(_at(0.0155, 0.0501), "0.1 mm above the end face", marks=pytest.mark.slow),
    pytest.param(_at(0.0190001, 0.03), "0.1 um outside the outer face", marks=pytest.mark.slow),
    pytest.param(_at(0.0119, -0.0499), "0.1 mm inside the bore by a corner",
                 marks=pytest.mark.slow),
]
INSIDE = [
    (_at(0.016, -0.02), "inside"),
    pytest.param(_at(0.0189, 0.0499), "inside, 0.1 mm from a corner", marks=pytest.mark.slow),
    pytest.param(_at(0.015, 0.0), "inside, mid-plane", marks=pytest.mark.slow),
]


def _matches_mpmath(point, why, tol):
    b_ref, g_ref = _ref_cart(point)
    b, g = winding_field(point, RI, RO, L, N, I, gradient=True, rtol=1e-10)
    assert _rel(b, b_ref) <= tol, why
    assert _rel(g, g_ref) <= tol, why
    return b_ref


@pytest.mark.parametrize("point,why", OUTSIDE)
def test_winding_outside_matches_mpmath_to_1e_10(point, why):
    b_ref = _matches_mpmath(point, why, 1e-10)
    b_only = winding_field(point, RI, RO, L, N, I, rtol=1e-10)
    assert _rel(b_only, b_ref) <= 1e-10, why


@pytest.mark.parametrize("point,why", INSIDE)
def test_winding_inside_matches_mpmath_to_1e_8(point, why):
    _matches_mpmath(point, why, 1e-8)


@pytest.mark.slow
def test_reference_itself_agrees_with_2d_loop_quadrature():
    for rho, z in [(0.03, 0.06), (0.016, -0.02)]:
        a = ref.winding_textbook(RI, RO, L, rho, z)
        b = ref.winding_loops_2d(RI, RO, L, rho, z)
        np.testing.assert_allclose(a, b, rtol=1e-12)


def test_on_axis_closed_form_including_far_away():
    z = np.concatenate([np.linspace(-0.2, 0.2, 41), [1.0, 10.0, 1e2, 1e3, -1e3]])
    pts = np.stack([0 * z, 0 * z, z], axis=1)
    b = winding_field(pts, RI, RO, L, N, I)
    bz_ref = np.array([MU0 * J * ref.winding_axis_bz(RI, RO, L, zz) for zz in z])
    np.testing.assert_allclose(b[:, 2], bz_ref, rtol=1e-12, atol=0)
    assert np.all(b[:, :2] == 0)


def test_far_field_converges_to_dipole_without_cancellation():
    # m = N I <pi a^2> over a uniform radial distribution: (pi/(Ro-Ri)) int a^2 da
    m = N * I * np.pi * (RI**2 + RI * RO + RO**2) / 3
    import mpmath as mp

    m_quad = N * I * float(mp.pi * mp.quad(lambda a: a * a, [RI, RO]) / (RO - RI))
    assert abs(m / m_quad - 1) < 1e-15
    d = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    errs = []
    radii = [1.0, 10.0, 100.0, 1e3]
    for R in radii:
        b, g = winding_field(R * d, RI, RO, L, N, I, gradient=True)
        bd, gd = dipole_field(R * d, [0, 0, m], gradient=True)
        errs.append((_rel(b, bd), _rel(g, gd)))
    errs = np.array(errs)
    # the next multipole (l = 3) falls as (size / R)^2 relative to the dipole
    for k in range(1, len(radii) - 1):
        ratio = errs[k] / errs[k - 1]
        assert np.all(np.abs(ratio / 1e-2 - 1) < 0.02)
    assert np.all(errs[-1] < 1e-8)
    # at 1e3 m the relative error is the octupole's ~(0.05/1e3)^2, not cancellation noise:
    # compare with a 45-digit reference there
    b_ref, g_ref = _ref_cart(1e3 * d, dps=45)
    b, g = winding_field(1e3 * d, RI, RO, L, N, I, gradient=True, rtol=1e-12)
    assert _rel(b, b_ref) < 1e-12 and _rel(g, g_ref) < 1e-12


def _outside_points():
    rng = np.random.default_rng(3)
    rho = rng.uniform(0, 0.05, 40)
    z = rng.uniform(L / 2 + 0.003, 0.12, 40) * rng.choice([-1, 1], 40)
    phi = rng.uniform(0, 2 * np.pi, 40)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)



def _central_differences(pts, h=1e-6):
    """dB_i/dx_j by central differences of B (step h, m), shape (n, 3, 3)."""
    fd = np.empty((len(pts), 3, 3))
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        fd[:, :, j] = (winding_field(pts + e, RI, RO, L, N, I)
                       - winding_field(pts - e, RI, RO, L, N, I)) / (2 * h)
    return fd


def test_gradient_equals_finite_differences_and_b_is_div_and_curl_free_outside():
    pts = _outside_points()
    b, g = winding_field(pts, RI, RO, L, N, I, gradient=True)
    gn = np.linalg.norm(g, axis=(1, 2))
    fd = _central_differences(pts)
    assert np.all(np.linalg.norm(fd - g, axis=1) <= 1e-7 * gn[:, None])
    # the kernels build G traceless and symmetric; the differences of B test B itself
    assert np.all(np.abs(np.trace(fd, axis1=1, axis2=2)) <= 1e-6 * gn)
    assert np.all(np.linalg.norm(fd - fd.transpose(0, 2, 1), axis=(1, 2)) <= 1e-6 * gn)


def test_inside_curl_is_mu0_j_and_finite_differences_include_it():
    rng = np.random.default_rng(4)
    rho = rng.uniform(RI + 1e-3, RO - 1e-3, 30)
    z = rng.uniform(-L / 2 + 1e-3, L / 2 - 1e-3, 30)
    phi = rng.uniform(0, 2 * np.pi, 30)
    pts = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)
    b, g = winding_field(pts, RI, RO, L, N, I, gradient=True)
    gn = np.linalg.norm(g, axis=(1, 2))
    fd = _central_differences(pts)
    assert np.all(np.linalg.norm(fd - g, axis=1) <= 1e-6 * gn[:, None])
    # Ampere and Gauss on the field values (through the differences), not on G's construction
    curl = np.stack([fd[:, 2, 1] - fd[:, 1, 2], fd[:, 0, 2] - fd[:, 2, 0],
                     fd[:, 1, 0] - fd[:, 0, 1]], 1)
    j_vec = MU0 * J * np.stack([-np.sin(phi), np.cos(phi), 0 * phi], 1)
    assert np.all(np.linalg.norm(curl - j_vec, axis=1) <= 1e-5 * gn)
    assert np.all(np.abs(np.trace(fd, axis1=1, axis2=2)) <= 1e-5 * gn)


def _loop_sum(pts, n):
    """Midpoint rule with n x n filament loops over the section (the brute-force model)."""
    a = RI + (np.arange(n) + 0.5) * (RO - RI) / n
    zc = -L / 2 + (np.arange(n) + 0.5) * L / n
    b = np.zeros((len(pts), 3))
    for aa in a:
        for zz in zc:
            b += loop_field(pts - [0, 0, zz], aa, N * I / n**2)
    return b


def test_loop_sum_converges_to_uniform_density_at_second_order():
    pts = _outside_points()[:10]
    exact = winding_field(pts, RI, RO, L, N, I, rtol=1e-12)
    ns = [4, 8, 16, 32]
    err = [np.max(np.linalg.norm(_loop_sum(pts, n) - exact, axis=1)
                  / np.linalg.norm(exact, axis=1)) for n in ns]
    slope = np.polyfit(np.log(ns), np.log(err), 1)[0]
    assert -2.2 < slope < -1.8, (err, slope)


def _magpylib_shells(pts, k):
    """Nested-shell construction in magpylib: M_z(r) = J (Ro - r) in the winding, J (Ro - Ri)
    in the bore (curl M = J phi), made piecewise constant on k CylinderSegment shells plus a
    Cylinder for the bore. Returns B / mu0_magpylib = H + M (independent of mu0)."""
    import magpylib as magpy

    edges = np.linspace(RI, RO, k + 1)
    mid = 0.5 * (edges[1:] + edges[:-1])
    m_shell = J * (RO - mid)
    dims = np.stack([edges[:-1], edges[1:], np.full(k, L), np.zeros(k), np.full(k, 360.0)], 1)
    obs = np.repeat(pts[None], k, axis=0).reshape(-1, 3)
    pol = np.zeros((k, 3))
    pol[:, 2] = magpy.mu_0 * m_shell
    b = magpy.func.cylinder_segment_field("B", obs, np.repeat(dims, len(pts), axis=0),
                                          np.repeat(pol, len(pts), axis=0))
    b = b.reshape(k, len(pts), 3).sum(axis=0)
    b += magpy.func.cylinder_field("B", pts, (2 * RI, L), (0, 0, magpy.mu_0 * J * (RO - RI)))
    return b / magpy.mu_0


def test_magpylib_nested_shells_converge_to_uniform_density():
    pts = _outside_points()[:20]
    exact = winding_field(pts, RI, RO, L, N, I, rtol=1e-12) / MU0
    ks = [4, 8, 16, 32]
    err = [np.max(np.linalg.norm(_magpylib_shells(pts, k) - exact, axis=1)
                  / np.linalg.norm(exact, axis=1)) for k in ks]
    slope = np.polyfit(np.log(ks), np.log(err), 1)[0]
    assert -2.2 < slope < -1.8, (err, slope)
    assert err[-1] < 1e-3
