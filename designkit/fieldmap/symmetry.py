"""The array's symmetries the map may sample with, and sampling only one point per orbit.

The array's group (:meth:`designkit.model.array.CoilArray.symmetries`: rotations about the
vertical axis through its coils' centroid and reflections in vertical planes through it that
map every coil onto an identical coil, found from the poses) gives, coil sigma(k) being the
image of coil k under G (exactly, for linear cores),

    B_sigma(k)(G p) = G B_k(p),    grad B_sigma(k)(G p) = G grad B_k(p) G^T,
    F0(G p) = G F0(p)   when G m = +-m (the force is quadratic in the magnet's moment m);

under a reflection B is a pseudovector (-G B) and the mirrored winding circulates the other
way (-1 A): the two signs cancel. The coupled model's discrete rules obey these relations only
for the elements that map each core's azimuth grids onto themselves
(:func:`sampling_group`). A point set closed under the group is evaluated at one representative
per orbit (:class:`Orbits`) and the other points filled by these relations: up to 8x fewer
evaluations for a square array, 4x for a hexagonal array's rectangular box. Lengths in m; A
rows as :data:`designkit.model.array.ROWS`. Reference: M. Tinkham, Group Theory and Quantum
Mechanics, ch. 4.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..cores.coupled import FIELD_AZIMUTHS, N_PHI_MAGNET, coupled_cores, solve_symmetry
from ..cores.symmetry import TOL_M, PlacementGroup
from ..model.array import CoilArray, g5_from_gradient, gradient_from_g5


def sampling_group(arr: CoilArray, moment=None) -> PlacementGroup:
    """The elements of the array's group whose relations above hold for the coupled model's
    values, not only for the fields: for coupled cores, those that map the cores' field rules'
    and the magnet's projection's azimuth grids onto themselves in the solve's frames
    (:meth:`designkit.cores.symmetry.PlacementGroup.keeping_grids`; the solve's own group
    keeps its collocation rings); with ``moment`` (3,) A m^2, also G m = +-m (for F0)."""
    cores = coupled_cores(arr)
    group = arr.symmetries()
    if cores:  # the solve's group and frames (solve_symmetry), without solving
        group, frames = solve_symmetry(arr, cores)
        group = group.keeping_grids(group.local_actions(frames),
                                    FIELD_AZIMUTHS + (N_PHI_MAGNET,), cores)
    if moment is None:
        return group
    m = np.asarray(moment, float)
    m = m / max(np.linalg.norm(m), 1e-300)
    return group.subgroup(lambda e, s: abs(abs(float(m @ s.g @ m)) - 1.0) < 1e-12)


def random_orbits(lower, upper, n: int, group: PlacementGroup,
                  rng) -> tuple[np.ndarray, "Orbits"]:
    """``n`` random points (n, 3) m of the box [lower, upper] and their :class:`Orbits`:
    uniform base points (the first ones, the representatives) followed by their images under
    each element of ``group`` that maps the box onto itself, so that only about n / |group|
    of them need evaluating (uniform images of a uniform sample)."""
    lower, upper = (np.asarray(a, float) for a in (lower, upper))
    corners = np.array([[x, y, z] for x in (lower[0], upper[0]) for y in (lower[1], upper[1])
                        for z in (lower[2], upper[2])])
    tree = cKDTree(corners)
    keep = group.subgroup(lambda e, s: bool(np.all(tree.query(group.apply(s, corners))[0]
                                                   < TOL_M)))
    nb = -(-n // len(keep))
    base = rng.uniform(lower, upper, (nb, 3))
    pts = np.concatenate([keep.apply(s, base) for s in keep.elements])[:n]
    orbits = Orbits(np.arange(min(nb, n)), np.tile(np.arange(nb), len(keep))[:n],
                    np.repeat(np.arange(len(keep)), nb)[:n], keep.elements)
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
    def of(cls, pts: np.ndarray, group: PlacementGroup) -> "Orbits":
        """The orbits of ``pts`` (n, 3) m under the elements of ``group`` that map the set
        onto itself (the others are dropped; at least the identity stays)."""
        pts = np.asarray(pts, float)
        tree = cKDTree(pts)
        keep, images = [], []
        for s in group.elements:
            dist, idx = tree.query(group.apply(s, pts))
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
        """F0 at every point (n, 3) from F0 at the representatives (r, 3) (a group that keeps
        the moment's line: :func:`sampling_group`)."""
        out = np.empty((len(self.rep), 3))
        for e, s in enumerate(self.group):
            sel = np.flatnonzero(self.elem == e)
            out[sel] = f_reps[self.rep[sel]] @ s.g.T
        return out
