"""Pose: validation, scipy Rotation round trip, transforms of points, vectors and tensors."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from designkit.errors import BadInputError
from designkit.geometry.pose import Pose


def test_round_trip_and_transforms():
    rot = Rotation.from_rotvec([0.4, -0.3, 1.2])
    pose = Pose.from_rotation((1.0, 2.0, 3.0), rot)
    r = rot.as_matrix()
    pl = np.array([[0.1, 0.2, 0.3], [-1.0, 0.5, 2.0]])
    pg = pl @ r.T + [1.0, 2.0, 3.0]
    np.testing.assert_allclose(pose.to_local(pg), pl, atol=1e-15)
    np.testing.assert_allclose(pose.vectors_to_global(pl), pl @ r.T, atol=1e-15)
    g = np.arange(18.0).reshape(2, 3, 3)
    np.testing.assert_allclose(pose.tensors_to_global(g), r @ g @ r.T, atol=1e-13)


def test_from_axis_is_proper_rotation():
    for axis in ([0, 0, 1], [1, 0, 0], [0.3, -0.4, 0.5], [0.95, 0.1, 0]):
        m = Pose.from_axis((0, 0, 0), axis).matrix
        np.testing.assert_allclose(m[:, 2], np.asarray(axis) / np.linalg.norm(axis), atol=1e-15)
        assert abs(np.linalg.det(m) - 1) < 1e-14


def test_bad_poses():
    with pytest.raises(BadInputError, match="pose.rotation"):
        Pose((0, 0, 0), ((1, 0, 0), (0, 1, 0), (0, 0, -1)))  # reflection
    with pytest.raises(BadInputError, match="pose.position"):
        Pose((0, np.nan, 0))
    with pytest.raises(BadInputError, match="axis"):
        Pose.from_axis((0, 0, 0), (0, 0, 0))
