"""The coupled cores' system split by the array's symmetry: smaller LU factorizations.

When identical upright cores sit on a square's or a rectangle's lattice, the block system M of
:class:`designkit.cores.coupled.ArraySystem` commutes with the group's action U(g) on the
unknowns (core k -> core sigma(k), its modes turned by
:func:`designkit.cores.coupled.mode_transform`). In an orthonormal basis Q adapted to the
isotypic components of U (the parts of the space carrying one irreducible representation each)
Q^T M Q is block-diagonal, so one LU per component replaces the LU of M: for the 3 x 3 array
(D4) the largest component is about half the unknowns, an eighth of the factorization's cost.

U acts alike on every panel of a mode order m, so the components are found once per m on the
small space of (core, cos / sin): they are the eigenspaces of a random class-weighted sum of
the group's matrices (a central element of the group algebra, a different scalar on each
component; the same scalar for the same irreducible type at every m). Reference: J.-P. Serre,
Linear Representations of Finite Groups, section 2.6 (the canonical decomposition).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.linalg import lu_factor, lu_solve

from .._blas import one_blas_thread

TOL_M = 1e-9
"""Two positions (cores, map points) closer than this (m) are the same."""

SQUARE_GROUP = [np.array(g, float) for g in (
    [[1, 0], [0, 1]], [[0, -1], [1, 0]], [[-1, 0], [0, -1]], [[0, 1], [-1, 0]],
    [[-1, 0], [0, 1]], [[1, 0], [0, -1]], [[0, 1], [1, 0]], [[0, -1], [-1, 0]])]
"""The symmetry group of the square (D4), identity first: (2, 2) x, y parts; z is kept."""


def _group(system, d4) -> list:
    """[(g (2, 2), perm (n_cores,))] of the elements of ``d4`` (and the identity) that map
    the cores onto each other about the vertical axis through their centroid."""
    pos = np.array([np.asarray(p.position, float) for p in system.poses])
    c = pos[:, :2].mean(axis=0)
    out = [(np.eye(2), np.arange(len(pos)))]
    for g in d4:
        img = np.c_[(pos[:, :2] - c) @ g.T + c, pos[:, 2]]
        dist = np.linalg.norm(img[:, None] - pos[None], axis=2)
        perm = dist.argmin(axis=1)
        if np.all(dist[np.arange(len(pos)), perm] < TOL_M) and len(set(perm)) == len(pos):
            out.append((g, perm))
    return out


def _classes(group) -> np.ndarray:
    """Conjugacy class label of each element of ``group`` ([(g, perm)], 2 x 2 parts)."""
    mats = [g for g, _ in group]
    label = -np.ones(len(mats), int)
    for a in range(len(mats)):
        if label[a] >= 0:
            continue
        for h in mats:
            conj = h @ mats[a] @ h.T
            b = next(i for i, m in enumerate(mats) if np.allclose(m, conj))
            label[b] = a
    return label


def _small_rep(group, t_small) -> list:
    """The group's matrices on the small space (core, component) with ``t_small(g)`` the
    per-core action (r, r): D(g) = P(g) kron t_small(g)."""
    out = []
    for g, perm in group:
        p = np.zeros((len(perm), len(perm)))
        p[perm, np.arange(len(perm))] = 1.0
        out.append(np.kron(p, t_small(g)))
    return out


class SymmetricLU:
    """LU factors of M per isotypic component; :meth:`solve` as ``lu_solve`` of M."""

    def __init__(self, q: sparse.csr_matrix, blocks: list):
        self.q = q
        self.blocks = blocks  # [(column slice of Q, LU factors)]

    @classmethod
    def build(cls, mat: np.ndarray, system, d4, rotation_of) -> "SymmetricLU | None":
        """The split factorization of ``mat`` for ``system`` (an ArraySystem), or None when
        the cores are not identical and upright or the group is trivial. ``d4``: the
        candidate 2 x 2 matrices; ``rotation_of(m, g)``: the (2, 2) action on (cos, sin) of
        mode order m >= 1."""
        models = system.models
        if len(models) < 2 or any(m is not models[0] for m in models) or \
                not all(p.is_identity_rotation for p in system.poses):
            return None
        group = _group(system, d4)
        if len(group) < 2:
            return None
        model = models[0]
        label = _classes(group)
        w = np.random.default_rng(20261127).uniform(1.0, 2.0, len(group))[label]
        parts = [(0, _small_rep(group, lambda g: np.eye(1)))]
        parts += [(m, _small_rep(group, lambda g, m=m: rotation_of(m, g)))
                  for m in range(1, model.m_max + 1)]
        cols = {}  # eigenvalue key -> list of (global row indices, values) per column
        for m, mats in parts:
            z = sum(wi * d for wi, d in zip(w, mats))
            lam, vec = np.linalg.eigh(0.5 * (z + z.T))
            for lam_k, v in zip(lam, vec.T):
                key = round(float(lam_k), 6)
                cols.setdefault(key, []).extend(_embed(system, model, m, v))
        keys = sorted(cols)
        rows, cc, vals, blocks, start = [], [], [], [], 0
        for key in keys:
            for r, v in cols[key]:
                rows.append(r)
                cc.append(np.full(len(r), start))
                vals.append(v)
                start += 1
            blocks.append(slice(start - len(cols[key]), start))
        n = mat.shape[0]
        if start != n:
            return None
        q = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                      np.concatenate(cc))), shape=(n, n))
        qt = q.T.tocsr()
        out = []
        # the blocks are a fraction of the whole: on a busy machine BLAS threads would spin
        # longer than they compute
        with one_blas_thread():
            for sl in blocks:
                qs = q[:, sl]
                d = np.asarray(qt[sl] @ mat)  # Q_s^T M, (n_s, n)
                b = np.ascontiguousarray(np.asarray(qs.T @ d.T).T)  # Q_s^T M Q_s
                out.append((sl, lu_factor(b, overwrite_a=True)))
        res = cls(q, out)
        # the split is exact when the components are right: check it on a random vector
        rhs = np.random.default_rng(1).standard_normal(n)
        if not np.linalg.norm(mat @ res.solve(rhs) - rhs) <= 1e-9 * np.linalg.norm(rhs):
            return None
        return res

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        y = np.asarray(self.q.T @ rhs)
        x = np.empty_like(y)
        with one_blas_thread():
            for sl, lu in self.blocks:
                x[sl] = lu_solve(lu, y[sl])
        return np.asarray(self.q @ x)


def _embed(system, model, m: int, v: np.ndarray) -> list:
    """One basis vector of the small space (core, component) of mode order ``m`` on every
    panel: [(global indices, values)] (one column per panel)."""
    n_cores = len(system.models)
    r = len(v) // n_cores
    vv = v.reshape(n_cores, r)
    keep = np.abs(vv) > 1e-14
    off = system.offsets[:-1]
    out = []
    if m == 0:
        for p in range(model.n0):
            idx = off + p
            out.append((idx[keep[:, 0]], vv[keep[:, 0], 0]))
        return out
    base = model.n0 + 2 * (m - 1) * model.n1
    for p in range(model.n1):
        idx = np.stack([off + base + c * model.n1 + p for c in range(2)], axis=1)
        out.append((idx[keep], vv[keep]))
    return out
