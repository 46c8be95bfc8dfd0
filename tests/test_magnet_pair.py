"""The force and torque between finger magnets (firmware_io.magnet_pair, firmware_io.magnet_charges)
against magpylib's getFT (its own meshing of the target in the source's exact field) and exact
cylinder field, Newton's third law, the two-dipole limit far apart, the run-time charge model
within its proven bound, and the refusal of overlapping magnets."""

import magpylib as magpy
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from firmware_io.constants import MU0
from firmware_io.cylinder_magnet import CylinderMagnet, check_apart
from firmware_io.errors import BadInputError
from firmware_io.magnet_charges import AxialCharges, PairBound, axial_moments, charge_forces
from firmware_io.magnet_pair import PAIR_TOL, MagnetPairs, pair_force_torque, pair_forces

RADIUS, LENGTH, M = 0.005, 0.010, 1.1579e6
MOMENT = M * np.pi * RADIUS**2 * LENGTH

CASES = [  # (centre a, axis a, centre b, axis b), m
    ((0, 0, 0), (0, 0, -1), (0.02, 0, 0), (0, 0, -1)),             # side by side, 20 mm
    ((0, 0, 0), (0, 0, -1), (0.03, 0, 0.01), (0, 0, 1)),           # opposite, offset
    ((0, 0, 0), (0, 0.6, -0.8), (0.02, 0.01, 0.005), (0.3, 0, -0.953939201416945)),  # tilted
    ((0.01, -0.02, 0.04), (1, 0, 0), (0.01, -0.02, 0.057), (0, 0, -1)),  # crossed, 2 mm apart
]


def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _pair(case):
    pa, ua, pb, ub = case
    return (CylinderMagnet(pa, MOMENT * _unit(ua), RADIUS, LENGTH),
            CylinderMagnet(pb, MOMENT * _unit(ub), RADIUS, LENGTH))


def _magpy(position, moment, radius=RADIUS, length=LENGTH):
    """magpylib's cylinder of a magnet (polarization mu0 M along its moment)."""
    rot = Rotation.align_vectors([_unit(moment)], [[0.0, 0.0, 1.0]])[0]
    mag = np.linalg.norm(moment) / (np.pi * radius**2 * length)
    return magpy.magnet.Cylinder(dimension=(2 * radius, length),
                                 polarization=(0.0, 0.0, MU0 * mag), position=position,
                                 orientation=rot)


def cylinder(m):
    return _magpy(m.position_m, m.moment_a_m2, m.radius_m, m.length_m)


@pytest.mark.parametrize("case", CASES)
def test_force_and_torque_match_magpylib(case):
    a, b = _pair(case)
    f, t = pair_force_torque(a, b)
    f_ref, t_ref = magpy.getFT(cylinder(a), cylinder(b), meshing=(48, 12, 12))
    scale = np.linalg.norm(f_ref)
    # magpylib's cell meshing is good to ~3e-4 at this meshing, 2e-3 with the faces 2 mm
    # apart (it converges to ours as its cells shrink); a 1 % factor or a sign fails
    assert np.linalg.norm(f - f_ref) < 2e-3 * scale
    assert np.linalg.norm(t - t_ref) < 3e-3 * max(np.linalg.norm(t_ref), scale * 0.01)


@pytest.mark.parametrize("case", CASES)
def test_newton_and_converged(case):
    a, b = _pair(case)
    f_ab, _ = pair_force_torque(a, b)
    f_ba, _ = pair_force_torque(b, a)
    assert np.linalg.norm(f_ab + f_ba) < 1e-7 * np.linalg.norm(f_ab)
    fine, _ = pair_force_torque(a, b, tol=1e-12)
    assert np.linalg.norm(pair_force_torque(a, b, tol=1e-3)[0] - fine) < 1e-3 * np.linalg.norm(fine)


def test_far_apart_the_pair_is_two_dipoles():
    # F on b = grad(m_b . B_a) for point dipoles, closed form
    ma, mb = MOMENT * _unit((0, 0.6, -0.8)), MOMENT * _unit((1, 0, 0))
    r = np.array([0.3, -0.2, 0.5])
    a = CylinderMagnet((0, 0, 0), ma, RADIUS, LENGTH)
    b = CylinderMagnet(r, mb, RADIUS, LENGTH)
    d = np.linalg.norm(r)
    rh = r / d
    f_dip = 3 * MU0 / (4 * np.pi * d**4) * ((ma @ rh) * mb + (mb @ rh) * ma + (ma @ mb) * rh
                                            - 5 * (ma @ rh) * (mb @ rh) * rh)
    f, _ = pair_force_torque(a, b)
    # finite-size corrections fall like (size / distance)^2 ~ 1e-3 here
    assert np.linalg.norm(f - f_dip) < 2e-3 * np.linalg.norm(f_dip)


def test_overlap():
    a = CylinderMagnet((0, 0, 0), (0, 0, -MOMENT), RADIUS, LENGTH)
    assert a.overlaps(CylinderMagnet((0.009, 0, 0), (0, 0, -MOMENT), RADIUS, LENGTH))
    assert not a.overlaps(CylinderMagnet((0.011, 0, 0), (0, 0, -MOMENT), RADIUS, LENGTH))
    assert not a.overlaps(CylinderMagnet((0.0, 0, 0.0101), (0, 0, -MOMENT), RADIUS, LENGTH))


# ------------------------------------------------------------------ the run-time path
SIZES = np.array([(RADIUS, LENGTH), (RADIUS, LENGTH), (0.004, 0.006)])  # (radius, length) m


def _moments(dirs):
    vol = np.pi * SIZES[:, 0] ** 2 * SIZES[:, 1]
    return np.array([_unit(d) for d in dirs]) * (M * vol)[:, None]


def _magpy_forces(pos, mom):
    """Force and torque (about each centre) on each magnet from all the others: magpylib."""
    src = [_magpy(p, m, *s) for p, m, s in zip(pos, mom, SIZES)]
    f, t = np.zeros((len(pos), 3)), np.zeros((len(pos), 3))
    for j in range(len(pos)):
        for k in range(len(pos)):
            if k != j:
                fk, tk = magpy.getFT(src[k], src[j], meshing=(48, 12, 12), pivot=pos[j])
                f[j] += fk
                t[j] += tk
    return f, t


@pytest.mark.parametrize("scale", [1.0, 1.6])
def test_magnet_pairs_of_tilted_magnets_match_magpylib(scale):
    # three magnets of two sizes, each tilted its own way; at scale 1 the first pair is
    # closer than the charges' switch distance (the face quadrature), the others farther (the
    # charges); at 1.6 all pairs run on the charges
    pos = np.array([[0.0, 0.0, 0.04], [0.02, 0.005, 0.045], [-0.01, 0.035, 0.03]]) * scale
    mom = _moments([(0.3, -0.2, -1.0), (-0.5, 0.4, -0.8), (0.2, 0.9, 0.3)])
    pairs = MagnetPairs(SIZES[:, 0], SIZES[:, 1])
    d = np.linalg.norm(pos[:, None] - pos[None], axis=-1)
    close = (d < pairs.switch_distance_m)[np.triu_indices(3, 1)]
    assert close.tolist() == ([True, False, False] if scale == 1.0 else [False] * 3)
    f, t = pairs.forces(pos, mom)
    f_ref, t_ref = _magpy_forces(pos, mom)
    # measured 7.2e-4 / 6.3e-4 / 2e-5 (1.6 x: 3.0e-4 / 2.6e-4 / 1e-5), magpylib's cell
    # meshing error near the 21 mm pair; a sign or a 1 % factor fails
    for j in range(3):
        fs = np.linalg.norm(f_ref[j])
        assert np.linalg.norm(f[j] - f_ref[j]) < 1e-3 * fs, (j, f[j], f_ref[j])
        assert np.linalg.norm(t[j] - t_ref[j]) < 4e-3 * max(np.linalg.norm(t_ref[j]),
                                                          0.01 * fs), (j, t[j], t_ref[j])
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-9 * np.abs(f).max())
    f2, t2 = pair_forces(pos, mom, SIZES[:, 0], SIZES[:, 1])
    np.testing.assert_allclose(f2, f, rtol=0, atol=1e-15)


def test_axial_moments_give_the_cylinders_exact_axial_field():
    # the multipole series on the axis, B_z = mu0 sum (l + 1) C_l / z^(l + 2), against
    # magpylib's exact cylinder field, for a long and a flat cylinder (C_3 large)
    for radius, length in ((0.003, 0.018), (0.008, 0.004)):
        r0 = np.hypot(radius, length / 2)
        c = axial_moments(radius, length, 119)
        mom = M * np.pi * radius**2 * length
        z = r0 * np.array([1.15, 1.5, 3.0])
        ls = np.arange(1, 120, 2)
        bz = MU0 * mom * ((ls + 1) * c / z[:, None] ** (ls + 2)).sum(axis=1)
        ref = _magpy((0, 0, 0), (0, 0, mom), radius, length).getB(np.c_[0 * z, 0 * z, z])[:, 2]
        np.testing.assert_allclose(bz, ref, rtol=1e-7)
        dip = MU0 * mom * 2 * c[0] / z**3
        assert np.abs(dip / ref - 1).max() > 0.01  # the higher moments matter there


def test_charges_hold_their_proven_bound_against_the_exact_pair():
    # just beyond the switch distance, random tilts: the charges' error against the exact
    # face quadrature is within the bound (relative to the dipole scales); a single charge
    # pair (dipole and nothing else) is not
    rng = np.random.default_rng(7)
    geo = AxialCharges(RADIUS, LENGTH), AxialCharges(0.004, 0.006)
    dipole = AxialCharges(RADIUS, LENGTH, fractions=(0.5,)), AxialCharges(0.004, 0.006,
                                                                           fractions=(0.5,))
    bound = PairBound(*geo)
    r_s = bound.switch_distance_m(PAIR_TOL)
    for _ in range(6):
        dist = r_s * rng.uniform(1.0, 1.3)
        pos = np.array([[0.0, 0.0, 0.0], dist * _unit(rng.normal(size=3))])
        dirs = [_unit(rng.normal(size=3)) for _ in range(2)]
        mom = np.array(dirs) * (M * np.pi * SIZES[[0, 2], 0] ** 2 * SIZES[[0, 2], 1])[:, None]
        a = CylinderMagnet(pos[0], mom[0], RADIUS, LENGTH)
        b = CylinderMagnet(pos[1], mom[1], 0.004, 0.006)
        f_ex, t_ex = pair_force_torque(a, b, tol=1e-10)
        fs = 3 * MU0 * np.prod(np.linalg.norm(mom, axis=1)) / (4 * np.pi * dist**4)
        ts = 2 * MU0 * np.prod(np.linalg.norm(mom, axis=1)) / (4 * np.pi * dist**3)
        f, t = charge_forces(pos, mom, list(geo))
        ef, et = bound.relative(dist)
        assert np.linalg.norm(f[1] - f_ex) <= ef * fs and ef <= PAIR_TOL
        assert np.linalg.norm(t[1] - t_ex) <= et * ts and et <= PAIR_TOL
        fd, _ = charge_forces(pos, mom, list(dipole))
        assert np.linalg.norm(fd[1] - f_ex) > PAIR_TOL * fs


def test_overlapping_magnets_and_bad_input_are_refused():
    pairs = MagnetPairs(SIZES[:, 0], SIZES[:, 1], names=["thumb", "index", "middle"])
    mom = _moments([(0, 0, -1)] * 3)
    pos = np.array([[0.0, 0.0, 0.03], [0.008, 0.0, 0.03], [0.05, 0.0, 0.03]])
    with pytest.raises(BadInputError, match="thumb.*index.*overlap"):
        pairs.forces(pos, mom)
    with pytest.raises(BadInputError, match="positions_m"):
        pairs.forces(pos[:2], mom[:2])
    with pytest.raises(BadInputError, match="positions_m"):
        pairs.forces(np.where(pos == 0.05, np.nan, pos), mom)
    with pytest.raises(BadInputError, match="radii_m"):
        MagnetPairs([RADIUS, -1.0], [LENGTH, LENGTH])
    with pytest.raises(BadInputError, match="tol"):
        MagnetPairs([RADIUS], [LENGTH], tol=0.0)
    mags = [CylinderMagnet(p, m, *s) for p, m, s in zip(pos, mom, SIZES)]
    with pytest.raises(BadInputError, match="magnet positions"):
        check_apart(mags)
    check_apart(mags[::2])  # 50 mm apart: fine
    f, t = MagnetPairs([RADIUS], [LENGTH]).forces([[0.0, 0.0, 0.03]], [[0.0, 0.0, -1.0]])
    assert not f.any() and not t.any()  # one magnet: nothing pulls on it
