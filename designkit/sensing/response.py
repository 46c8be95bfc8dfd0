"""What a Hall sensor at a site reads of a finger magnet in a pose, and how that changes with
the pose: field and Jacobian on the five degrees of freedom.

The pose of a magnet of known |m|: its centre c (m, array frame) and its moment's direction u.
The five coordinates are c (3) and two small rotations (rad) about the unit vectors e1, e2 that
complete u to a right-handed frame (:func:`tangent_frame`); a rotation by alpha about e1 tilts
u by alpha. Rotating the magnet by omega changes its field at r = site - c by
omega x B - G (omega x r) (G = dB/dr), moving it by dc changes it by -G dc: both exact from the
cylinder's analytic field and gradient (:func:`designkit.field.magnetized_cylinder_field`).

The cores magnetized by the magnet (:meth:`designkit.model.array.CoilArray.magnet_core_field`,
the coupled solve, the magnet as a point dipole of the same moment) add their field; it is
linear in the moment, so its orientation derivative is exact (the field of the moment e x m),
and its position derivative is a central difference of step ``step_m`` (truncation
~(step / d)^2 relative, d the magnet's distance to the nearest core end).
Fields in T, array frame; sites (n, 3) m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..field import magnetized_cylinder_field

DEFAULT_STEP_M = 1e-4
"""Central-difference step of the cores' term in the magnet's position, m."""


@dataclass(frozen=True)
class MagnetShape:
    """A uniformly axially magnetized cylinder: ``radius_m``, ``length_m``, ``moment_a_m2``
    (|m|, A m^2)."""

    radius_m: float
    length_m: float
    moment_a_m2: float

    @classmethod
    def of(cls, magnet) -> "MagnetShape":
        """From a :class:`designkit.design.MagnetSpec`."""
        return cls(magnet.radius_m, magnet.length_m, magnet.moment_a_m2)

    @property
    def magnetization_a_per_m(self) -> float:
        return self.moment_a_m2 / (np.pi * self.radius_m ** 2 * self.length_m)


@dataclass(frozen=True)
class Response:
    """Fields and Jacobians of magnet poses at sites.

    ``field_t`` (n_sites, n_poses, 3) T and ``jacobian`` (n_sites, n_poses, 3, 5) T per (m, m, m,
    rad, rad), array frame; ``tangents`` (n_poses, 3, 2): e1, e2 of each pose.
    """

    field_t: np.ndarray
    jacobian: np.ndarray
    tangents: np.ndarray


def tangent_frame(direction) -> np.ndarray:
    """(3, 3) rotation whose columns are e1, e2, u (u the unit ``direction``), right-handed;
    e1 is perpendicular to u and to x (to y when u is near x)."""
    u = np.asarray(direction, dtype=float)
    u = u / np.linalg.norm(u)
    a = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1)
    return np.c_[e1, np.cross(u, e1), u]


def cylinder_response(sites_m: np.ndarray, position_m: np.ndarray, direction,
                      shape: MagnetShape) -> tuple[np.ndarray, np.ndarray]:
    """Field (n, 3) T and Jacobian (n, 3, 5) of one magnet pose at the sites (exact cylinder)."""
    rot = tangent_frame(direction)
    r = np.asarray(sites_m, dtype=float) - position_m
    b_loc, g_loc = magnetized_cylinder_field(r @ rot, shape.radius_m, shape.length_m,
                                             shape.magnetization_a_per_m, gradient=True)
    b = b_loc @ rot.T
    g = np.einsum("ai,nij,bj->nab", rot, g_loc, rot)
    jac = np.empty((len(r), 3, 5))
    jac[:, :, :3] = -g
    for k in range(2):
        e = rot[:, k]
        jac[:, :, 3 + k] = np.cross(e, b) - np.einsum("nab,nb->na", g, np.cross(e, r))
    return b, jac


def magnet_response(sites_m, positions_m, directions, shape: MagnetShape, *, array=None,
                    step_m: float = DEFAULT_STEP_M) -> Response:
    """:class:`Response` of every pose (``positions_m`` (n_poses, 3) m, ``directions``
    (n_poses, 3)) at every site (n_sites, 3) m: the magnet's exact field plus, with ``array``
    (a :class:`designkit.model.array.CoilArray` with cores), the field of the cores it
    magnetizes."""
    sites = np.atleast_2d(np.asarray(sites_m, dtype=float))
    pos = np.atleast_2d(np.asarray(positions_m, dtype=float))
    dirs = np.broadcast_to(np.asarray(directions, dtype=float), pos.shape)
    field = np.empty((len(sites), len(pos), 3))
    jac = np.empty((len(sites), len(pos), 3, 5))
    tangents = np.empty((len(pos), 3, 2))
    for p, (c, u) in enumerate(zip(pos, dirs)):
        field[:, p], jac[:, p] = cylinder_response(sites, c, u, shape)
        tangents[p] = tangent_frame(u)[:, :2]
    system = None if array is None else array.coupled()
    if system is not None:
        b, j = core_response(system, sites, pos, dirs * shape.moment_a_m2
                             / np.linalg.norm(dirs, axis=1)[:, None], tangents, step_m)
        field += b
        jac += j
    return Response(field, jac, tangents)


def core_response(system, sites: np.ndarray, positions: np.ndarray, moments: np.ndarray,
                  tangents: np.ndarray, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Field (n_sites, n_poses, 3) and Jacobian (n_sites, n_poses, 3, 5) of the cores
    magnetized by point dipoles ``moments`` (n_poses, 3) A m^2 at ``positions`` (n_poses, 3) m
    (``system``: the array's coupled core solve)."""
    n = len(positions)
    # per pose: the pose itself, then +-step along x, y and z
    offsets = np.r_[np.zeros((1, 3)), np.repeat(np.eye(3), 2, axis=0)
                    * np.tile([step_m, -step_m], 3)[:, None]]
    pts = (positions[:, None, :] + offsets[None]).reshape(-1, 3)
    b = dipole_core_field(system, sites, pts, np.repeat(moments, len(offsets), axis=0))
    b = b.reshape(len(sites), n, len(offsets), 3)
    jac = np.empty((len(sites), n, 3, 5))
    for i in range(3):
        jac[..., i] = (b[:, :, 1 + 2 * i] - b[:, :, 2 + 2 * i]) / (2 * step_m)
    # orientation: the field of the moment's change e_j x m (the solve is linear in the moment)
    dm = np.cross(tangents.transpose(0, 2, 1), moments[:, None, :])  # (n, 2, 3)
    for j in range(2):
        jac[..., 3 + j] = dipole_core_field(system, sites, positions, dm[:, j])
    return b[:, :, 0], jac


CHUNK = 512
"""Sources solved at once by :func:`dipole_core_field` (bounds the solve's memory)."""


def dipole_core_field(system, sites: np.ndarray, positions: np.ndarray,
                      moments: np.ndarray) -> np.ndarray:
    """(n_sites, n_sources, 3) T: the field at ``sites`` of the cores magnetized by point
    dipoles ``moments`` (n_sources, 3) A m^2 at ``positions`` (n_sources, 3) m, one source at a
    time (the coupled solve, superposed over the moment's components)."""
    out = np.zeros((len(sites), len(positions), 3))
    for k, e in enumerate(np.eye(3)):
        rows = np.flatnonzero(moments[:, k])
        for a in range(0, len(rows), CHUNK):
            idx = rows[a:a + CHUNK]
            x = system.magnet_solution(positions[idx], e)
            out[:, idx] += np.moveaxis(system.core_field(sites, x), 1, -1) \
                * moments[idx, k][None, :, None]
    return out
