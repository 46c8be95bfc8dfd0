"""The array as one magnetic system (designkit.cores.coupled): independent references.

References: the image method (dipole above a wide high-mu slab, closed form), the first-order
(Born) volume integral of M = chi H0 for mu_r -> 1, reciprocity and energy conservation
(properties the collocation solve does not build in), the 3 x 3 array's mirror symmetry, and a
3-D GetDP FEM (designkit.fem.fem3d, slow).
"""

import numpy as np
import pytest

from designkit import Coil, Pose, default_design
from designkit.model.array import CoilArray, g5_from_gradient
from designkit.cores import ArraySystem, Core
from designkit.design import MU0, GridLayout
from designkit.errors import DesignRuleError
from designkit.field import dipole_field

D = default_design()
M_DESIGN = np.array([0.0, 0.0, D.magnet.moment_a_m2])


@pytest.fixture(scope="module")
def arr(thesis_array):
    return thesis_array  # the default design's array: one coupled solve per session


def _two(pitch=0.05, mu_r=1000.0):
    d = D.replace(array=GridLayout(rows=1, columns=2, pitch_m=pitch),
                  core=D.core.__class__(relative_permeability=mu_r))
    return CoilArray.from_design(d)


# ---------------------------------------------------------------------------- image method
SLAB_R, SLAB_MU = 0.06, 1000.0


@pytest.fixture(scope="module")
def slab():
    # a wide (R = L = 60 mm) mu_r 1000 cylinder, top face at z = 0
    R, L = SLAB_R, SLAB_R
    coil = Coil(R, R + 0.002, L, 10, Core(R, L, relative_permeability=SLAB_MU),
                Pose((0, 0, -L / 2)))
    return CoilArray((coil,)), ArraySystem(CoilArray((coil,)), m_max=1, refine=4)


def test_image_method_wide_slab(slab):
    # a point dipole 10 mm above the centre of the slab sees (to the slab's finite size) the
    # image dipole kappa (-mx, -my, mz) at the mirror point
    h, mu = 0.01, SLAB_MU
    s = slab[1]
    rng = np.random.default_rng(5)
    for _ in range(2):
        m = rng.normal(size=3)
        p = np.array([0.0, 0.0, h])
        x = s.magnet_solution(p[None], m)
        b, g = s.core_field_pointwise(p[None], x, gradient=True)
        kap = (mu - 1) / (mu + 1)
        bi, gi = dipole_field(p - [0, 0, -h], kap * np.array([-m[0], -m[1], m[2]]),
                              gradient=True)
        np.testing.assert_allclose(g[0].T @ m, gi.T @ m, atol=0.015 * np.abs(gi.T @ m).max())
        np.testing.assert_allclose(np.cross(m, b[0]), np.cross(m, bi),
                                   atol=0.015 * np.abs(np.cross(m, bi)).max())


def test_finite_magnet_image_force(slab):
    # the 10 x 10 mm magnet (exact cylinder source, face-charge force) 5 mm above the slab:
    # the image method for the finite magnet (fem3d.image_force_z, exact cylinder fields)
    from designkit.fem.fem3d import image_force_z

    arr1, s = slab
    object.__setattr__(arr1, "_system", s)  # reuse the refined solve for the array API
    a, L = D.magnet.radius_m, D.magnet.length_m
    mag = D.magnet.magnetization_a_per_m
    for gap in (0.005, 0.01):
        f = arr1.bias_force([0.0, 0.0, gap + L / 2], M_DESIGN, magnet_size_m=(a, L))
        ref = image_force_z(a, L, mag, gap, SLAB_MU)
        assert abs(f[2] / ref - 1) < 0.02, (gap, f, ref)
        # the point dipole at the magnet's centre: not the same at this range
        fd = arr1.bias_force([0.0, 0.0, gap + L / 2], M_DESIGN)
        assert abs(fd[2] / ref - 1) > 0.03


# ---------------------------------------------------------------------------- mu_r -> 1
def _born_core_field(array, k, pts, chi, nr=10, nphi=24, nz=60):
    """First order in chi: B of M = chi H_winding_k over every core volume (dipole sum)."""
    xr, wr = np.polynomial.legendre.leggauss(nr)
    xz, wz = np.polynomial.legendre.leggauss(nz)
    total = np.zeros((len(pts), 3))
    src = array.coils[k]
    for c in array.coils:
        core = c.core
        s = 0.5 * (xr + 1)
        r = core.radius * np.sqrt(s)  # area coordinate
        wra = 0.5 * wr * np.pi * core.radius ** 2 / nphi  # r dr dphi = R^2/2 ds dphi
        z = core.offset + 0.5 * core.length * xz
        wzz = 0.5 * core.length * wz
        ph = 2 * np.pi * np.arange(nphi) / nphi
        Rr, Pp, Zz = np.meshgrid(r, ph, z, indexing="ij")
        W = (wra[:, None, None] * np.ones(nphi)[None, :, None] * wzz[None, None, :]).ravel()
        loc = np.c_[(Rr * np.cos(Pp)).ravel(), (Rr * np.sin(Pp)).ravel(), Zz.ravel()]
        glob = c.pose.position + loc
        h0 = src.field(glob, 1.0, include="winding") / MU0
        mvol = chi * h0 * W[:, None]  # dipole moments of the cells, A m^2
        for i in range(0, len(pts)):
            d = pts[i] - glob
            r2 = np.einsum("ij,ij->i", d, d)
            inv = 1 / np.sqrt(r2)
            mr = np.einsum("ij,ij->i", mvol, d)
            total[i] += 1e-7 * np.sum(3 * d * (mr * inv ** 5)[:, None]
                                      - mvol * (inv ** 3)[:, None], axis=0)
    return total


def test_weak_cores_match_first_order_volume_integral():
    chi = 1e-3
    a2 = _two(mu_r=1.0 + chi)
    air = CoilArray(tuple(c.replace(core=None) for c in a2.coils))
    rng = np.random.default_rng(2)
    pts = np.c_[rng.uniform(-0.06, 0.06, 6), rng.uniform(-0.03, 0.03, 6),
                rng.uniform(0.015, 0.06, 6)]
    a = a2.actuation_matrix(pts)
    a_air = air.actuation_matrix(pts)
    for k in range(2):
        born = _born_core_field(a2, k, pts, chi)
        core_part = a[:, :3, k] - a_air[:, :3, k]
        # O(chi^2) (demagnetization ~ N chi) and quadrature: 1 % of the largest value
        np.testing.assert_allclose(core_part, born, atol=0.01 * np.abs(born).max())
    # mu_r = 1 exactly: the air answer
    a1 = _two(mu_r=1.0).actuation_matrix(pts)
    np.testing.assert_allclose(a1, a_air, rtol=1e-12, atol=1e-18)


# ---------------------------------------------------------------------------- reciprocity
def test_reciprocity_between_two_magnets(arr):
    # m2 . B_ind(p2; m1 at p1) = m1 . B_ind(p1; m2 at p2) (symmetric Green's function of the
    # linear iron; the collocation solve is not symmetric by construction)
    s = arr.coupled()
    rng = np.random.default_rng(11)
    for _ in range(4):
        p1, p2 = (np.r_[rng.uniform(-0.07, 0.07, 2), rng.uniform(0.012, 0.07)] for _ in range(2))
        m1, m2 = rng.normal(size=3), rng.normal(size=3)
        b12 = arr.magnet_core_field(p2, p1, m1)
        b21 = arr.magnet_core_field(p1, p2, m2)
        lhs, rhs = m2 @ b12, m1 @ b21
        scale = np.linalg.norm(m1) * np.linalg.norm(m2) * max(np.abs(b12).max() /
                                                                np.linalg.norm(m1), 1e-12)
        assert abs(lhs - rhs) <= 5e-3 * max(abs(lhs), abs(rhs)) + 1e-4 * scale
    assert s is arr.coupled()  # built once, cached on the array


def test_bias_force_is_the_energy_gradient(arr):
    # U(p) = -1/2 m . B_ind(p; p) for a rigid dipole in linear iron; F0 = -grad U. The 1/2 and
    # the identity F0 = (m . grad) B_ind hold only if the solve is reciprocal.
    rng = np.random.default_rng(4)
    for _ in range(3):
        p = np.r_[rng.uniform(-0.06, 0.06, 2), rng.uniform(0.015, 0.06)]
        m = rng.normal(size=3) * 0.5
        f = arr.bias_force(p, m)
        h = 2e-4

        def w(q):
            return 0.5 * m @ arr.magnet_core_field(q, q, m)

        fd = np.array([(w(p + h * e) - w(p - h * e)) / (2 * h) for e in np.eye(3)])
        np.testing.assert_allclose(f, fd, atol=3e-3 * np.abs(f).max())


# ---------------------------------------------------------------------------- symmetry
def test_mirror_symmetry_of_the_3x3_array(arr):
    # mirror x -> -x maps coil (row, col) to (row, 2 - col); B -> (-Bx, By, Bz) for the
    # mirrored point (B is a pseudovector, coils' currents reverse sense: B' = -(P B) with
    # P = diag(-1, 1, 1)... checked against the air array, which is exact)
    rng = np.random.default_rng(7)
    pts = np.c_[rng.uniform(-0.07, 0.07, (5, 2)), rng.uniform(0.01, 0.08, 5)]
    mir = pts * [-1, 1, 1]
    a = arr.actuation_matrix(pts)
    am = arr.actuation_matrix(mir)
    perm = [3 * (k // 3) + 2 - k % 3 for k in range(9)]
    # same sign pattern as the (exact) air array
    air = CoilArray(tuple(c.replace(core=None) for c in arr.coils))
    sa = np.sign(np.round(air.actuation_matrix(pts)[:, :, :] /
                          np.where(air.actuation_matrix(mir)[:, :, perm] == 0, 1,
                                   air.actuation_matrix(mir)[:, :, perm]), 6))
    sgn = np.array([-1, 1, 1, 1, -1, -1, 1, 1])  # Bx,By,Bz,dBx/dx,dBx/dy,dBx/dz,dBy/dy,dBy/dz
    assert np.all((sa == 0) | (sa == sgn[None, :, None]))
    np.testing.assert_allclose(a, sgn[None, :, None] * am[:, :, perm],
                               atol=1e-9 * np.abs(a).max())


def test_coupling_effects_have_the_known_size(arr):
    # sanity against an independent 3-D volume-integral solve quoted in issue 12 (linear
    # mu_r 1000): +12 % dBz/dz at the design point; Bz changes sign above a neighbour
    p = np.array([[0.0, 0.0, 0.03], [0.05, 0.0, 0.03]])
    a = arr.actuation_matrix(p)
    au = arr.uncoupled_actuation_matrix(p)
    gzz = -(a[0, 3, 4] + a[0, 6, 4])
    gzz_u = -(au[0, 3, 4] + au[0, 6, 4])
    assert 1.09 < gzz / gzz_u < 1.15
    assert au[1, 2, 4] > 0 > a[1, 2, 4]


def test_magnet_pull_and_sensor_field(arr):
    # independent 3-D solve (issue 12): ~ -62 mN at 30 mm, 4.0 mT / 0.74 mT at the sensors
    f0 = arr.bias_force([0.0, 0.0, 0.03], M_DESIGN)
    assert abs(f0[0]) < 1e-9 and abs(f0[1]) < 1e-9
    assert -0.066 < f0[2] < -0.058
    s = arr.sensor_positions_m()
    assert s.shape == (2, 9, 3)
    np.testing.assert_allclose(s[0, 4], [0, 0, 0.014])
    np.testing.assert_allclose(s[1, 4], [0, 0, -0.114])
    b = arr.magnet_core_field(s.reshape(-1, 3), [0.0, 0.0, 0.03], M_DESIGN).reshape(2, 9, 3)
    assert 3.8e-3 < b[0, 4, 2] < 4.2e-3
    assert 0.68e-3 < b[1, 4, 2] < 0.80e-3
    # torque: zero for an upright magnet on the axis; m x B for a tilted one
    t = arr.bias_torque([[0.0, 0.0, 0.03]], M_DESIGN)
    assert np.abs(t).max() < 1e-12
    mt = np.array([0.3, 0.0, 0.85])
    bi = arr.magnet_core_field([0.01, 0.0, 0.03], [0.01, 0.0, 0.03], mt)
    np.testing.assert_allclose(arr.bias_torque([0.01, 0.0, 0.03], mt), np.cross(mt, bi),
                               rtol=1e-10, atol=1e-15)


def test_no_cores_no_coupling():
    air = CoilArray.from_design(D.replace(core=None))
    assert air.coupled() is None
    np.testing.assert_array_equal(air.bias_force([[0, 0, 0.03]], M_DESIGN), np.zeros((1, 3)))
    b, g = air.magnet_core_field([[0, 0, 0.01]], [0, 0, 0.03], M_DESIGN, gradient=True)
    assert b.shape == (1, 3) and g.shape == (1, 3, 3) and not b.any()


@pytest.mark.slow
def test_higher_modes_converge(arr):
    # m = 4 changes the cores' field by < 5e-4 of its largest value over the default m_max 3
    pts = np.array([[0.0, 0.0, 0.03], [0.05, 0.0, 0.03], [0.025, 0.025, 0.02]])
    s2 = arr.coupled()
    assert s2.m_max == 3
    s3 = ArraySystem(arr, m_max=4)
    b2 = s2.core_field(pts, s2.coil_solution())
    b3 = s3.core_field(pts, s3.coil_solution())
    assert np.abs(b3 - b2).max() < 5e-4 * np.abs(b2).max()


# ---------------------------------------------------------------------------- bad input
def test_cores_touching_a_neighbour_are_named():
    c = Coil.from_design(D)
    # cores longer than the winding, neighbour's winding touching the protruding core
    core = Core(0.012, 0.11)
    a = Coil(0.012, 0.019, 0.1, 100, core, Pose((0, 0, -0.05)))
    b = Coil(0.012, 0.019, 0.1, 100, None, Pose((0.031, 0, -0.05 - 0.1 - 0.005)))
    with pytest.raises(DesignRuleError, match=r"core of coil 0.*winding of coil 1"):
        CoilArray((a, b))
    # a winding resting on the protruding core's top face: error too
    lid = Coil(0.02, 0.03, 0.01, 100, None, Pose((0.0, 0.0, 0.010)))
    with pytest.raises(DesignRuleError, match=r"core of coil 0.*winding of coil 1"):
        CoilArray((a, lid))
    CoilArray((a, lid.moved((0.0, 0.0, 0.0101))))  # 0.1 mm of air: fine
    CoilArray((c, c.moved((0.05, 0, -0.05))))  # the default pitch: fine


# ---------------------------------------------------------------------------- 3-D FEM
@pytest.mark.slow
@pytest.mark.skipif(__import__("shutil").which("getdp") is None, reason="GetDP not installed")
def test_two_cores_against_3d_fem():
    # designkit.fem.fem3d (GetDP, vector potential, issue 11): two cores side by side at the
    # 50 mm pitch, coil 0 energized at 1 A; coarse mesh (B within ~2-4 % on one coil)
    from designkit.fem import fem3d

    pts = np.array([[0.0, 0.0, 0.03], [0.05, 0.0, 0.03], [0.025, 0.01, 0.02],
                    [0.05, 0.0, 0.015], [-0.02, 0.015, 0.04], [0.07, 0.02, 0.03]])
    bf, _, _ = fem3d.two_cores_case(pts, level=-2)
    a2 = _two()
    # fem3d puts coil 0 at the origin, the design's 1 x 2 array at x = -25 / +25 mm
    q = pts + [-0.025, 0.0, 0.0]
    got = a2.actuation_matrix(q)[:, :3, 0]
    unc = a2.uncoupled_actuation_matrix(q)[:, :3, 0]
    scale = np.linalg.norm(bf, axis=1)
    err = np.linalg.norm(got - bf, axis=1) / scale
    err_u = np.linalg.norm(unc - bf, axis=1) / scale
    assert err.max() < 0.06, err
    # beside the neighbour the uncoupled model is far off; the coupled one is not
    assert err_u[[1, 3]].min() > 0.5 and err[[1, 3]].max() < 0.03


@pytest.mark.slow
@pytest.mark.skipif(__import__("shutil").which("getdp") is None, reason="GetDP not installed")
def test_magnet_pull_on_one_core_against_3d_fem():
    # fem3d (GetDP 3-D, exact 10 x 10 mm magnet, coarse level -2): the pull at 20, 30, 50 mm
    from designkit.fem import fem3d

    h, fz = fem3d.magnet_pull_case(level=-2)
    a1 = CoilArray.from_design(D.replace(array=GridLayout(rows=1, columns=1)))
    size = (D.magnet.radius_m, D.magnet.length_m)
    got = np.array([a1.bias_force([0.0, 0.0, q], M_DESIGN, magnet_size_m=size)[2] for q in h])
    # measured +5 %, +6 %, +7 % against this coarse mesh (the FEM force is a difference of
    # two solves; finer levels: studies/fem3d_array.py)
    np.testing.assert_allclose(got, fz, rtol=0.09)


@pytest.mark.slow
@pytest.mark.skipif(__import__("shutil").which("getdp") is None, reason="GetDP not installed")
def test_saturation_factor_against_axisymmetric_fem():
    # nonlinear (1010 steel) GetDP axisymmetric FEM at 6 A vs the linear mu_r 1000 FEM at 1 A,
    # dBz/dz at the design point: the factor designkit tabulates
    import dataclasses

    from designkit.cores import saturation_table
    from designkit.fem.runner import solve

    coil = Coil.from_design(D)
    z = coil.length / 2 + 0.03
    lin = solve(coil, 1.0, level=0).axis.fit([z])["dbz_dz"][0]
    nl = solve(dataclasses.replace(coil, core=dataclasses.replace(coil.core, bh="steel1010")),
               6.0, level=0).axis.fit([z])["dbz_dz"][0]
    s = saturation_table(coil, 0.03, [0.0, 6.0])["factor"]
    assert abs(s[1] - nl / (6.0 * lin)) < 0.01
    assert s[1] < 0.95  # saturation is visible at 6 A
