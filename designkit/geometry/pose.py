"""Rigid poses of sources: position (m) and rotation, applied to points before a kernel."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import BadInputError
from ..support import validate as v

_IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


@dataclass(frozen=True)
class Pose:
    """Where a source sits: ``x_global = R @ x_local + position``.

    Parameters
    ----------
    position : tuple of 3 floats, m
        Origin of the source's local frame (the winding centre for a coil).
    rotation : 3x3 nested tuple
        Proper rotation matrix whose columns are the local axes in global coordinates;
        the local +z is the source's axis. Use :meth:`from_axis` or :meth:`from_rotation`.
    """

    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[tuple[float, float, float], ...] = field(default=_IDENTITY)

    def __post_init__(self):
        p = v.vector3("pose.position", self.position, "m")
        r = np.asarray(self.rotation, dtype=float)
        if r.shape != (3, 3) or not np.all(np.isfinite(r)):
            raise BadInputError("pose.rotation", "a finite 3x3 rotation matrix", self.rotation)
        if not (np.allclose(r.T @ r, np.eye(3), atol=1e-9) and np.linalg.det(r) > 0):
            raise BadInputError("pose.rotation", "a proper rotation (R^T R = I, det R = +1)",
                                self.rotation)
        object.__setattr__(self, "position", tuple(float(x) for x in p))
        object.__setattr__(self, "rotation", tuple(tuple(float(x) for x in row) for row in r))

    @classmethod
    def from_rotation(cls, position, rotation) -> "Pose":
        """From a scipy ``Rotation`` (or anything with ``as_matrix()``) or a 3x3 matrix."""
        mat = rotation.as_matrix() if hasattr(rotation, "as_matrix") else np.asarray(rotation)
        return cls(tuple(position), tuple(map(tuple, mat)))

    @classmethod
    def from_axis(cls, position, axis) -> "Pose":
        """Pose whose local +z points along ``axis`` (the rotation about it is arbitrary)."""
        a = v.vector3("axis", axis)
        n = np.linalg.norm(a)
        if n == 0:
            raise BadInputError("axis", "a non-zero 3-vector", axis)
        z = a / n
        helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(helper, z)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        return cls(tuple(position), tuple(map(tuple, np.column_stack([x, y, z]))))

    @property
    def matrix(self) -> np.ndarray:
        return np.asarray(self.rotation)

    @property
    def is_identity_rotation(self) -> bool:
        return self.rotation == _IDENTITY

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """Global points (n, 3) -> local frame (n, 3)."""
        d = points - np.asarray(self.position)
        return d if self.is_identity_rotation else d @ self.matrix

    def vectors_to_global(self, vec: np.ndarray) -> np.ndarray:
        """Local vectors (n, 3) -> global."""
        return vec if self.is_identity_rotation else vec @ self.matrix.T

    def tensors_to_global(self, g: np.ndarray) -> np.ndarray:
        """Local gradient tensors (n, 3, 3), G_ij = dB_i/dx_j -> global R G R^T."""
        if self.is_identity_rotation:
            return g
        r = self.matrix
        return np.einsum("ia,nab,jb->nij", r, g, r, optimize=True)
