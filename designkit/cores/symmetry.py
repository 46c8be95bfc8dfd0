"""The symmetry group of placed axisymmetric bodies (coils, cores) about a vertical axis, found
from their poses, and body frames in which the group acts simply.

A symmetry is an orthogonal G (3, 3) that keeps z -- a rotation about the vertical axis through
the bodies' centroid (x, y) or a reflection in a vertical plane through it -- and maps every
body onto a body of the same kind: position to position, axis to axis (within
:data:`TOL_M` m and 1e-9). The candidates are exhaustive: a symmetry maps the body farthest
from the axis (the reference) onto a body at the same distance, so the rotations by the angles
between them and the reflections in the planes that bisect them are the only ones to test; a
layout whose bodies all lie on the axis gets the square's candidates (D4). A hexagonal array
has C6v, a tilted ring of n coils Cnv, a 4 x 4 grid D4, a 2 x 3 grid D2, a free layout usually
the identity alone. Lengths in m. Reference: M. Tinkham, Group Theory and Quantum Mechanics,
ch. 4 (point groups); J.-P. Serre, Linear Representations of Finite Groups (what the group is
used for: :mod:`.symmetric_solve`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

TOL_M = 1e-9
"""Two positions (bodies, map points) closer than this (m) are the same."""
TOL_AXIS = 1e-9
"""Two unit axes closer than this are the same."""


@dataclass(frozen=True)
class Symmetry:
    """One group element: ``g`` (3, 3) about the vertical axis through the group's centre,
    ``perm`` (n,) body k -> body perm[k]."""

    g: np.ndarray
    perm: np.ndarray

    @property
    def proper(self) -> bool:
        """A rotation (det +1), not a reflection."""
        return bool(np.linalg.det(self.g) > 0)


@dataclass(frozen=True)
class PlacementGroup:
    """The symmetries (identity first) of n bodies about the vertical axis through
    ``centre_xy`` (2,) m."""

    centre_xy: np.ndarray
    elements: tuple

    def __len__(self) -> int:
        return len(self.elements)

    def apply(self, s: Symmetry, points: np.ndarray) -> np.ndarray:
        """G p about the group's axis, points (n, 3) m."""
        c = np.r_[self.centre_xy, 0.0]
        return (np.asarray(points, float) - c) @ s.g.T + c

    def subgroup(self, keep) -> "PlacementGroup":
        """The elements s with ``keep(index, s)`` true; the caller's predicate must select a
        subgroup (a closed set: e.g. the elements that fix a vector, or a box)."""
        return PlacementGroup(self.centre_xy, tuple(s for e, s in enumerate(self.elements)
                                                    if e == 0 or keep(e, s)))

    def local_actions(self, frames: np.ndarray) -> np.ndarray:
        """(n_elements, n, 2, 2): how each element maps body k's local x, y (columns of
        ``frames`` (n, 3, 3), the third the body's axis) onto body perm[k]'s: the upper-left
        block of R_perm[k]^T G R_k (a rotation, or a reflection for an improper G)."""
        f = np.asarray(frames, float)
        out = np.empty((len(self.elements), len(f), 2, 2))
        for e, s in enumerate(self.elements):
            h = np.einsum("kba,bc,kcd->kad", f[s.perm], s.g, f)
            out[e] = h[:, :2, :2]
        return out

    def keeping_grids(self, actions: np.ndarray, n_azimuths, bodies=None) -> "PlacementGroup":
        """The elements whose local actions (:meth:`local_actions`) on ``bodies`` (indices;
        None: all) map the azimuth grids of ``n_azimuths`` points (each entry n: phi_j =
        2 pi j / n, or shifted by half a step) onto themselves, so that quadratures on them
        give the same values at images: a rotation by a, or the reflection phi -> a - phi,
        with a n / 2 pi whole. A subgroup (the grids' own symmetries form a group)."""
        sel = slice(None) if bodies is None else np.asarray(bodies, int)

        def ok(e, s):
            a = np.arctan2(actions[e, sel, 1, 0], actions[e, sel, 0, 0])
            return all(np.allclose(np.round(a * n / (2 * math.pi)), a * n / (2 * math.pi),
                                   rtol=0.0, atol=1e-9) for n in n_azimuths)

        return self.subgroup(ok)


def find_symmetries(positions, axes, kinds) -> PlacementGroup:
    """The symmetry group of bodies at ``positions`` (n, 3) m with unit ``axes`` (n, 3) and
    ``kinds`` (n hashables: bodies of different kinds are never swapped), about the vertical
    axis through the positions' centroid (x, y); identity first (module docstring)."""
    pos = np.asarray(positions, float).reshape(-1, 3)
    ax = np.asarray(axes, float).reshape(-1, 3)
    kinds = list(kinds)
    centre = pos[:, :2].mean(axis=0)
    rel = pos[:, :2] - centre
    radius = np.hypot(rel[:, 0], rel[:, 1])
    found = [Symmetry(np.eye(3), np.arange(len(pos)))]
    seen = {_key(np.eye(3))}
    for g in _candidates(rel, radius, kinds):
        if _key(g) in seen:
            continue
        perm = _permutation(g, pos, ax, kinds, centre)
        if perm is not None:
            seen.add(_key(g))
            found.append(Symmetry(g, perm))
    return PlacementGroup(centre, tuple(found))


def _key(g: np.ndarray) -> tuple:
    return tuple(np.round(g[:2, :2].ravel(), 9) + 0.0)


def _about_z(g2: np.ndarray) -> np.ndarray:
    g = np.eye(3)
    g[:2, :2] = g2
    return g


def _rotation(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return _about_z(np.array([[c, -s], [s, c]]))


def _reflection(line_angle: float) -> np.ndarray:
    """The reflection in the vertical plane through the axis at ``line_angle`` (rad)."""
    c, s = math.cos(2 * line_angle), math.sin(2 * line_angle)
    return _about_z(np.array([[c, s], [s, -c]]))


def _candidates(rel: np.ndarray, radius: np.ndarray, kinds: list):
    """The only rotations and reflections that can map the reference body (the farthest from
    the axis) onto a body of its kind at its distance; D4 when every body is on the axis."""
    if radius.max() <= TOL_M:
        for q in range(1, 4):
            yield _rotation(q * math.pi / 2)
        for q in range(4):
            yield _reflection(q * math.pi / 4)
        return
    r = int(np.argmax(radius))
    a0 = math.atan2(rel[r, 1], rel[r, 0])
    for b in range(len(rel)):
        if kinds[b] != kinds[r] or abs(radius[b] - radius[r]) > TOL_M:
            continue
        ab = math.atan2(rel[b, 1], rel[b, 0])
        yield _rotation(ab - a0)
        yield _reflection(0.5 * (ab + a0))


def _permutation(g, pos, ax, kinds, centre):
    """perm with g (body k) = body perm[k] (position, axis, kind), or None."""
    c = np.r_[centre, 0.0]
    img = (pos - c) @ g.T + c
    img_ax = ax @ g.T
    d = np.linalg.norm(img[:, None, :] - pos[None, :, :], axis=2)
    perm = d.argmin(axis=1)
    k = np.arange(len(pos))
    if not np.all(d[k, perm] < TOL_M) or len(set(perm.tolist())) != len(pos):
        return None
    if not np.all(np.linalg.norm(img_ax - ax[perm], axis=1) < TOL_AXIS):
        return None
    if any(kinds[j] != kinds[i] for i, j in enumerate(perm)):
        return None
    return perm


def adapted_frames(group: PlacementGroup, frames: np.ndarray) -> np.ndarray:
    """Body frames (n, 3, 3) (proper rotations, the same axes as ``frames``) in which every
    element acts on a body off the group's axis as the identity or the reflection y -> -y,
    and on a body on the axis as G itself, measured from a mirror plane when there is one
    (:meth:`PlacementGroup.local_actions`): each orbit's first body takes its local x in a
    mirror plane of its stabilizer (if any), every other body of the orbit the image of that
    frame (times diag(1, -1, 1) for a reflection). Frames of a group without mirrors or of
    bodies without a mirror in their stabilizer keep their x axis."""
    f = np.array(frames, float)
    n = len(f)
    out = f.copy()
    done = np.zeros(n, bool)
    for r in range(n):
        if done[r]:
            continue
        a = f[r][:, 2]
        mirror = next((s for s in group.elements if s.perm[r] == r and not s.proper), None)
        if mirror is not None:
            w, v = np.linalg.eigh(0.5 * (mirror.g + mirror.g.T))
            normal = v[:, np.argmin(w)]  # the mirror plane's normal (eigenvalue -1)
            x = np.cross(normal, a)
            x /= np.linalg.norm(x)
            out[r] = np.column_stack([x, np.cross(a, x), a])
        for s in group.elements:
            j = s.perm[r]
            if not done[j]:
                rj = s.g @ out[r]
                out[j] = rj if s.proper else rj @ np.diag([1.0, -1.0, 1.0])
                done[j] = True
    return out
