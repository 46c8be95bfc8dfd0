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
component; the same scalar for the same irreducible type at every m). Each block Q_s^T M Q_s
is summed from the coupling blocks of the few distinct core placements (M is never formed).
Reference: J.-P. Serre, Linear Representations of Finite Groups, section 2.6 (the canonical
decomposition).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lu_factor, lu_solve

from ..support.blas import one_blas_thread

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
    """LU factors of M per symmetry block; :meth:`solve` as ``lu_solve`` of M.

    Per mode order m the unknowns are (core, cos / sin, panel) and the group acts on the
    first two alone, so the adapted basis is V_m (x) I_panels with V_m (r_m, r_m) orthogonal
    on the small space: every change of basis is a few dense products, never a sparse one.
    """

    def __init__(self, parts: list, blocks: list, n: int):
        self.parts = parts    # [(rows (r_m n_p,) in (small, panel) order, V_m (r_m, r_m))]
        self.blocks = blocks  # [([columns of V_m in the block, per part], LU factors)]
        self.n = n

    @staticmethod
    def layout(system, d4, rotation_of, n: int):
        """The split of ``system``'s n unknowns (an ArraySystem), or None when the cores are
        not identical and upright or the group is trivial: (parts, sels, twin) -- per mode
        order its rows and V_m, per block the columns of each V_m it takes, and the blocks
        whose matrix is another's (``twin``: block -> that block). ``d4``: the candidate
        2 x 2 matrices; ``rotation_of(m, g)``: the (2, 2) action on (cos, sin) of mode order
        m >= 1."""
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
        mirror = next((k for k, (g, _) in enumerate(group) if np.linalg.det(g) < 0), None)
        quarter = next((k for k, (g, _) in enumerate(group)
                        if np.linalg.det(g) > 0 and abs(g[0, 0]) < 0.5), None)
        reps = [(0, _small_rep(group, lambda g: np.eye(1)))]
        reps += [(m, _small_rep(group, lambda g, m=m: rotation_of(m, g)))
                 for m in range(1, model.m_max + 1)]
        parts, keys, unpaired = [], [], set()
        for m, mats in reps:
            vec, key, bad = _adapted_basis(sum(wi * d for wi, d in zip(w, mats)),
                                           None if mirror is None else mats[mirror],
                                           None if quarter is None else mats[quarter])
            parts.append((_rows(system, model, m), vec))
            keys.append(key)
            unpaired |= bad
        names = sorted(set(k for key in keys for k in key))
        sels = [[np.flatnonzero([k == name for k in key]) for key in keys] for name in names]
        if sum(len(r) for r, _ in parts) != n:
            return None
        # the reflection's -1 half of the 2-dimensional type's component is the quarter turn
        # of its +1 half, vector by vector: the same block (M commutes with the turn)
        twin = {i: names.index((lam, 1.0)) for i, (lam, sgn) in enumerate(names)
                if sgn < 0 and quarter is not None and lam not in unpaired
                and (lam, 1.0) in names}
        return parts, sels, twin

    @classmethod
    def from_orbits(cls, system, d4, rotation_of, self_block: np.ndarray, reps: dict,
                    pairs: list) -> "SymmetricLU | None":
        """The split factorization without assembling M: its core blocks are ``self_block``
        on the diagonal and, for the cores j != i, T(g) reps[key] T(g)^T with (j, i, key, k)
        in ``pairs``, g = ([identity] + ``d4``)[k] (T(g) = R_m(g) (x) I per mode order m,
        ``rotation_of``). Each block
        Q_s^T M Q_s is summed over the few distinct placements ``reps`` with coefficients on
        the small space, never over the n^2 entries of M. None as :meth:`layout`."""
        n = system.n_unknowns
        lay = cls.layout(system, d4, rotation_of, n)
        if lay is None:
            return None
        parts, sels, twin = lay
        model = system.models[0]
        n_cores = len(system.models)
        local = [np.arange(model.n0)] + [model.n0 + 2 * (m - 1) * model.n1
                                         + np.arange(2 * model.n1)
                                         for m in range(1, model.m_max + 1)]
        gs = [np.eye(2)] + [g for g in d4]
        rot = [[np.eye(1) if m == 0 else rotation_of(m, g) for g in gs]
               for m in range(len(parts))]
        # R_m(g)^T V_m seen from each core: (n_g, cores, n_s, r_m) per mode order
        w = [np.einsum("gts,kta->gksa", np.array(rot[m]), v.reshape(n_cores, -1, v.shape[1]))
             for m, (_, v) in enumerate(parts)]
        terms = {None: (np.arange(n_cores), np.arange(n_cores), np.zeros(n_cores, int))}
        for key in reps:
            terms[key] = tuple(np.array(t) for t in zip(*[(j, i, k) for j, i, kk, k in pairs
                                                           if kk == key]))
        mats = {**reps, None: self_block}
        lus = {}
        with one_blas_thread():
            for b, sel in enumerate(sels):
                if b in twin:
                    continue
                sizes = [len(s) * len(loc) // w[m].shape[2]
                         for m, (s, loc) in enumerate(zip(sel, local))]
                edges = np.r_[0, np.cumsum(sizes)]
                blk = np.zeros((edges[-1], edges[-1]))
                for mr, mc in np.ndindex(len(parts), len(parts)):
                    if not sizes[mr] or not sizes[mc]:
                        continue
                    acc = 0.0
                    for key, (jj, ii, gg) in terms.items():
                        if key is None and mr != mc:
                            continue  # the self blocks are mode-diagonal
                        c = np.einsum("psa,ptb->satb", w[mr][gg, jj][..., sel[mr]],
                                      w[mc][gg, ii][..., sel[mc]])
                        sub = mats[key][np.ix_(local[mr], local[mc])]
                        sub = sub.reshape(c.shape[0], -1, c.shape[2], sub.shape[1] // c.shape[2])
                        acc = acc + np.einsum("satb,sptq->apbq", c, sub, optimize=True)
                    blk[edges[mr]:edges[mr + 1], edges[mc]:edges[mc + 1]] = \
                        acc.reshape(sizes[mr], sizes[mc])
                lus[b] = lu_factor(blk, overwrite_a=True)
        res = cls(parts, [(sel, lus[twin.get(b, b)]) for b, sel in enumerate(sels)], n)

        def turn(x, g):  # T(g) x on one core's unknowns
            out = x.copy()
            for m in range(1, len(parts)):
                out[local[m]] = (rotation_of(m, g) @ x[local[m]].reshape(2, -1)).ravel()
            return out

        def matvec(x):
            y = np.zeros_like(x)
            off = system.offsets
            for j in range(n_cores):
                y[off[j]:off[j + 1]] = self_block @ x[off[j]:off[j + 1]]
            for j, i, key, k in pairs:
                g = gs[k]
                y[off[j]:off[j + 1]] += turn(mats[key] @ turn(x[off[i]:off[i + 1]], g.T), g)
            return y

        return res if res.solves(matvec) else None

    def solves(self, matvec) -> bool:
        """Whether the split solves M (``matvec``: x -> M x) on a random vector: exact when
        the components are right."""
        rhs = np.random.default_rng(1).standard_normal(self.n)
        return bool(np.linalg.norm(matvec(self.solve(rhs)) - rhs) <= 1e-9 * np.linalg.norm(rhs))

    def solve(self, rhs: np.ndarray, transpose: bool = False) -> np.ndarray:
        """M^-1 rhs (M^-T rhs with ``transpose``: Q is orthogonal, so M^T = Q B^T Q^T)."""
        b = np.asarray(rhs, float).reshape(self.n, -1)
        k = b.shape[1]
        out = np.empty_like(b)
        with one_blas_thread():
            y = [(v.T @ b[r].reshape(len(v), -1)).reshape(len(v), -1, k)
                 for r, v in self.parts]  # Q^T b per part, (r_m, n_p, k)
            x = [np.empty_like(a) for a in y]
            for sel, lu in self.blocks:
                xs = lu_solve(lu, np.concatenate([a[s].reshape(-1, k) for a, s in zip(y, sel)]),
                              trans=int(transpose))
                start = 0
                for a, s in zip(x, sel):
                    size = len(s) * a.shape[1]
                    a[s] = xs[start:start + size].reshape(len(s), a.shape[1], k)
                    start += size
            for (r, v), a in zip(self.parts, x):
                out[r] = (v @ a.reshape(len(v), -1)).reshape(-1, k)
        return out.reshape(np.shape(rhs))


def _adapted_basis(z: np.ndarray, mirror, quarter=None) -> tuple[np.ndarray, list, set]:
    """Orthonormal eigenvectors (r, r) of the central element ``z`` (a different scalar on each
    isotypic component), each component split further by the eigenvalue +-1 of the
    reflection ``mirror`` (r, r) (commuting with M, it halves the 2-dimensional irreducible
    type's component), each vector's block key (eigenvalue, reflection sign), and the
    eigenvalues whose -1 half could not be made the quarter turn ``quarter`` (r, r) of the +1
    half (where both halves exist and a quarter turn is given, it is made so)."""
    lam, vec = np.linalg.eigh(0.5 * (z + z.T))
    lam = np.round(lam, 6)
    cols, keys, bad = [], [], set()
    for value in np.unique(lam):
        u = vec[:, lam == value]
        if mirror is None:
            cols.append(u)
            keys += [(float(value), 0.0)] * u.shape[1]
            continue
        sgn, w = np.linalg.eigh(u.T @ (0.5 * (mirror + mirror.T)) @ u)
        u = u @ w
        sgn = np.round(sgn)
        plus, minus = u[:, sgn > 0], u[:, sgn < 0]
        if quarter is not None and plus.shape[1] and plus.shape[1] == minus.shape[1]:
            turned = quarter @ plus
            if np.abs(mirror @ turned + turned).max() < 1e-10:
                minus = turned
            else:
                bad.add(float(value))
        cols += [plus, minus]
        keys += [(float(value), 1.0)] * plus.shape[1] + [(float(value), -1.0)] * minus.shape[1]
    return np.concatenate(cols, axis=1), keys, bad


def _rows(system, model, m: int) -> np.ndarray:
    """The unknowns of mode order ``m`` of every core, (r n_p,) in (core, cos / sin, panel)
    order: the rows the small space's matrices act on, panel by panel."""
    off = system.offsets[:-1]
    if m == 0:
        return (off[:, None] + np.arange(model.n0)[None]).ravel()
    base = model.n0 + 2 * (m - 1) * model.n1
    c = np.arange(2)[None, :, None] * model.n1 + np.arange(model.n1)[None, None]
    return (off[:, None, None] + base + c).ravel()
