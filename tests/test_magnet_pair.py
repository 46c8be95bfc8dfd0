"""The force and torque between two finger magnets (firmware_io.magnet_pair) against magpylib's
getFT (its own meshing of the target in the source's exact field), Newton's third law and the
two-dipole limit far apart."""

import magpylib as magpy
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from firmware_io.constants import MU0
from firmware_io.magnet_pair import CylinderMagnet, pair_force_torque

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


@pytest.mark.parametrize("case", CASES)
def test_force_and_torque_match_magpylib(case):
    def cylinder(m):
        rot = Rotation.align_vectors([_unit(m.moment_a_m2)], [[0.0, 0.0, 1.0]])[0]
        return magpy.magnet.Cylinder(dimension=(2 * RADIUS, LENGTH),
                                     polarization=(0.0, 0.0, MU0 * M),
                                     position=m.position_m, orientation=rot)

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
