"""The array's symmetries about a vertical axis, and sampling only one point per orbit.

A symmetry is an orthogonal G that keeps z (a rotation by a multiple of 90 degrees about the
vertical axis through ``centre`` (x, y) m, or a reflection in a vertical plane through it) and
maps every coil onto a coil of the same type (upright coils, axisymmetric windings and cores).
Then, coil sigma(k) being the image of coil k, the actuation and the bias force obey (exactly,
for linear cores; the coupled model's azimuthal rules are symmetric too)

    B_sigma(k)(G p) = G B_k(p),    grad B_sigma(k)(G p) = G grad B_k(p) G^T,
    F0(G p) = G F0(p)   (magnet moment along z: the force is quadratic in the moment);

under a reflection B is a pseudovector (-G B) and the mirrored winding circulates the other
way (-1 A): the two signs cancel. A point set
closed under the group is evaluated at one representative per orbit (:class:`Orbits`) and the
other points filled by these relations: up to 8x fewer evaluations for a square array.
Lengths in m; A rows as :data:`designkit.model.array.ROWS`. Reference: the group D4, e.g.
M. Tinkham, Group Theory and Quantum Mechanics, ch. 4.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..cores.symmetric_solve import SQUARE_GROUP, TOL_M
from ..geometry.pose import Pose
from ..model.array import CoilArray, g5_from_gradient, gradient_from_g5



@dataclass(frozen=True)
class Symmetry:
    """One group element: G (3, 3), the coil permutation ``perm`` (coil k -> perm[k])."""

    g: np.ndarray
    perm: np.ndarray


def _apply(g: np.ndarray, centre: np.ndarray, pts: np.ndarray) -> np.ndarray:
    c = np.r_[centre, 0.0]
    return (pts - c) @ g.T + c


def array_symmetries(arr: CoilArray, centre) -> list[Symmetry]:
    """The group elements (identity first) that map the array onto itself about the vertical
    axis through ``centre`` (2,) m; only the identity when a coil is not upright."""
    centre = np.asarray(centre, float)
    eye = Symmetry(np.eye(3), np.arange(arr.n_coils))
    if not all(c.pose.is_identity_rotation for c in arr.coils):
        return [eye]
    pos = arr.positions()
    kinds = [dataclasses.replace(c, pose=Pose()) for c in arr.coils]
    tree = cKDTree(pos)
    out = []
    for g2 in SQUARE_GROUP:
        g = np.eye(3)
        g[:2, :2] = g2
        dist, idx = tree.query(_apply(g, centre, pos))
        if (np.all(dist < TOL_M) and len(set(idx.tolist())) == arr.n_coils
                and all(kinds[j] == kinds[k] for k, j in enumerate(idx))):
            out.append(Symmetry(g, idx.astype(int)))
    return out


def random_orbits(lower, upper, n: int, group, centre, rng) -> tuple[np.ndarray, "Orbits"]:
    """``n`` random points (n, 3) m of the box [lower, upper] and their :class:`Orbits`:
    uniform base points (the first ones, the representatives) followed by their images under
    each element of ``group`` that maps the box onto itself about ``centre`` (2,) m, so that
    only about n / |group| of them need evaluating (uniform images of a uniform sample)."""
    lower, upper, centre = (np.asarray(a, float) for a in (lower, upper, centre))
    half = 0.5 * (upper[:2] - lower[:2])
    keep = [s for s in group if np.allclose(centre, 0.5 * (lower[:2] + upper[:2]), rtol=0,
                                            atol=TOL_M)
            and np.allclose(np.abs(s.g[:2, :2]) @ half, half, rtol=0, atol=TOL_M)] or \
        [group[0]]
    nb = -(-n // len(keep))
    base = rng.uniform(lower, upper, (nb, 3))
    pts = np.concatenate([_apply(s.g, centre, base) for s in keep])[:n]
    orbits = Orbits(np.arange(min(nb, n)), np.tile(np.arange(nb), len(keep))[:n],
                    np.repeat(np.arange(len(keep)), nb)[:n], tuple(keep))
    return np.clip(pts, lower, upper), orbits


@dataclass(frozen=True)
class Orbits:
    """A point set split into orbits of a group: ``reps`` (r,) the indices evaluated; every
    point i is ``G[elem[i]]`` applied to point ``reps[rep[i]]``."""

    reps: np.ndarray
    rep: np.ndarray
    elem: np.ndarray
    group: tuple

    @classmethod
    def of(cls, pts: np.ndarray, group, centre) -> "Orbits":
        """The orbits of ``pts`` (n, 3) m under the elements of ``group`` that map the set
        onto itself (the others are dropped; at least the identity stays)."""
        pts = np.asarray(pts, float)
        tree = cKDTree(pts)
        keep, images = [], []
        for s in group:
            dist, idx = tree.query(_apply(s.g, centre, pts))
            if np.all(dist < TOL_M):
                keep.append(s)
                images.append(idx)
        n = len(pts)
        rep = [-1] * n
        elem = [0] * n
        reps = []
        images = [img.tolist() for img in images]  # Python lists: the loop indexes scalars
        for i in range(n):  # plain loop: n ~ 1e4, cheap next to one evaluation
            if rep[i] >= 0:
                continue
            r = len(reps)
            reps.append(i)
            rep[i], elem[i] = r, 0  # the identity (first): duplicates find only one copy
            for e, img in enumerate(images):
                j = img[i]
                if rep[j] < 0:
                    rep[j], elem[j] = r, e
        return cls(np.asarray(reps, int), np.asarray(rep, int), np.asarray(elem, int),
                   tuple(keep))

    def expand_actuation(self, a_reps: np.ndarray) -> np.ndarray:
        """A at every point (n, 8, n_coils) from A at the representatives (r, 8, n_coils)."""
        out = np.empty((len(self.rep),) + a_reps.shape[1:])
        for e, s in enumerate(self.group):
            sel = np.flatnonzero(self.elem == e)
            if not len(sel):
                continue
            a = a_reps[self.rep[sel]]  # (m, 8, nc), column k = coil k
            b = np.einsum("ij,mjk->mik", s.g, a[:, :3])
            grad = gradient_from_g5(np.moveaxis(a[:, 3:], 1, -1))  # (m, nc, 3, 3)
            grad = np.einsum("ij,mkjl,nl->mkin", s.g, grad, s.g)
            res = np.concatenate([b, np.moveaxis(g5_from_gradient(grad), -1, 1)], axis=1)
            block = np.empty_like(res)
            block[:, :, s.perm] = res  # coil k's column becomes coil perm[k]'s
            out[sel] = block
        return out

    def expand_force(self, f_reps: np.ndarray) -> np.ndarray:
        """F0 at every point (n, 3) from F0 at the representatives (r, 3) (moment along z)."""
        out = np.empty((len(self.rep), 3))
        for e, s in enumerate(self.group):
            sel = np.flatnonzero(self.elem == e)
            out[sel] = f_reps[self.rep[sel]] @ s.g.T
        return out
