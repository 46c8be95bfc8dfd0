"""Coil.field: winding (+ core) in the coil's pose."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from designkit import Coil
from designkit.design import default_design
from designkit.field import dipole_field, winding_field
from designkit.geometry.pose import Pose

RI, RO, L, N = 0.012, 0.019, 0.100, 1429


def test_air_coil_in_identity_pose_is_the_winding():
    coil = Coil(inner_radius=RI, outer_radius=RO, length=L, turns=N)
    p = np.array([[0.01, 0.02, 0.07], [0, 0, 0], [0.015, 0, 0.01]])
    b, g = coil.field(p, 3.0, gradient=True)
    bw, gw = winding_field(p, RI, RO, L, N, 3.0, gradient=True)
    assert np.array_equal(b, bw) and np.array_equal(g, gw)
    assert coil.field(p[0], 3.0).shape == (3,)


def test_translated_and_rotated_coil_far_field_is_its_dipole():
    rot = Rotation.from_euler("xyz", [0.3, -1.1, 2.0])
    pos = np.array([0.1, -0.2, 0.05])
    coil = Coil(inner_radius=RI, outer_radius=RO, length=L, turns=N,
                pose=Pose.from_rotation(pos, rot))
    p = pos + np.array([[40.0, 30.0, -20.0]])
    m = coil.dipole_moment_per_amp * 2.0 * rot.as_matrix()[:, 2]
    b, g = coil.field(p, 2.0, gradient=True)
    bd, gd = dipole_field(p - pos, m, gradient=True)
    assert np.linalg.norm(b - bd) < 1e-5 * np.linalg.norm(bd)
    assert np.linalg.norm(g - gd) < 1e-5 * np.linalg.norm(gd)


def test_from_axis_points_local_z_along_axis():
    coil = Coil(inner_radius=RI, outer_radius=RO, length=L, turns=N,
                pose=Pose.from_axis((0, 0, 0), (1.0, 0, 0)))
    b = coil.field([0.2, 0, 0], 1.0)
    bw = winding_field([0, 0, 0.2], RI, RO, L, N, 1.0)
    np.testing.assert_allclose(b, [bw[2], 0, 0], rtol=1e-14, atol=1e-20)


def test_design_coil_with_core_is_winding_plus_core():
    coil = Coil.from_design(default_design())
    if coil.core is None:
        pytest.skip("default design has no core")
    p = np.array([[0.0, 0.0, 0.03], [0.01, 0.005, 0.02]])
    b, g = coil.field(p, 1.0, gradient=True)
    bw, gw = coil.field(p, 1.0, gradient=True, include="winding")
    bc, gc = coil.field(p, 1.0, gradient=True, include="core")
    np.testing.assert_allclose(b, bw + bc, rtol=1e-14)
    np.testing.assert_allclose(g, gw + gc, rtol=1e-14)
    # the air-core part alone is the winding of the same coil, shifted to its pose
    local = p - np.asarray(coil.pose.position)
    np.testing.assert_allclose(bw, winding_field(local, coil.inner_radius, coil.outer_radius,
                                                 coil.length, coil.turns, 1.0), rtol=1e-15)
