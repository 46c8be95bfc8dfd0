"""The coupled cores' system split by the array's symmetry: smaller LU factorizations.

When identical cores sit in a symmetric layout (any point group about a vertical axis:
:mod:`.symmetry`), the block system M of :class:`designkit.cores.coupled.ArraySystem` commutes
with the group's action U(g) on the unknowns (core k -> core sigma(k), its modes turned by
:func:`designkit.cores.coupled.mode_transform` of g's local action on core k,
:meth:`.symmetry.PlacementGroup.local_actions`). In an orthonormal basis Q adapted to the
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


def _classes(mats: list) -> np.ndarray:
    """Conjugacy class label of each element of a group given by its faithful orthogonal
    matrices ``mats`` (3, 3)."""
    label = -np.ones(len(mats), int)
    for a in range(len(mats)):
        if label[a] >= 0:
            continue
        for h in mats:
            conj = h @ mats[a] @ h.T
            b = next(i for i, m in enumerate(mats) if np.allclose(m, conj, atol=1e-9))
            label[b] = a
    return label


def _small_rep(perms: list, actions: np.ndarray, t_small) -> list:
    """The group's matrices on the small space (core, component): D(g) has the block
    ``t_small(actions[g, k])`` (r, r) at (perm_g[k], k)."""
    out = []
    for e, perm in enumerate(perms):
        blocks = [np.atleast_2d(t_small(h)) for h in actions[e]]
        r = blocks[0].shape[0]
        d = np.zeros((len(perm) * r, len(perm) * r))
        for k, (j, blk) in enumerate(zip(perm, blocks)):
            d[j * r:(j + 1) * r, k * r:(k + 1) * r] = blk
        out.append(d)
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
    def layout(system, group, rotation_of):
        """The split of ``system``'s unknowns (an ArraySystem), or None when its cores are not
        all of one model or the group is trivial: (parts, sels, twin) -- per mode order its
        rows and V_m, per block the columns of each V_m it takes, and the blocks whose matrix
        is another's (``twin``: block -> that block). ``group``: (matrices (n_g, 3, 3), core
        permutations (n_g, n_cores), local actions (n_g, n_cores, 2, 2)), identity first;
        ``rotation_of(m, h)``: the (2, 2) action of a local action h on (cos, sin) of mode
        order m >= 1."""
        models = system.models
        mats, perms, actions = group
        if len(models) < 2 or any(m is not models[0] for m in models) or len(mats) < 2:
            return None
        model = models[0]
        label = _classes(list(mats))
        w = np.random.default_rng(20261127).uniform(1.0, 2.0, len(mats))[label]
        mirror = next((k for k, g in enumerate(mats) if np.linalg.det(g) < 0), None)
        turns = [(abs(np.arctan2(g[1, 0], g[0, 0])), k) for k, g in enumerate(mats)
                 if np.linalg.det(g) > 0 and k > 0]
        step = min(turns)[1] if turns else None  # the smallest rotation: the twins' generator
        reps = [(0, _small_rep(perms, actions, lambda h: np.eye(1)))]
        reps += [(m, _small_rep(perms, actions, lambda h, m=m: rotation_of(m, h)))
                 for m in range(1, model.m_max + 1)]
        parts, keys, unpaired = [], [], set()
        for m, ds in reps:
            vec, key, bad = _adapted_basis(sum(wi * d for wi, d in zip(w, ds)),
                                           None if mirror is None else ds[mirror],
                                           None if step is None else ds[step])
            parts.append((_rows(system, model, m), vec))
            keys.append(key)
            unpaired |= bad
        names = sorted(set(k for key in keys for k in key))
        sels = [[np.flatnonzero([k == name for k in key]) for key in keys] for name in names]
        if sum(len(r) for r, _ in parts) != system.n_unknowns:
            return None
        # the reflection's -1 half of a 2-dimensional type's component is the image of its
        # +1 half under (U(r) - U(r)^T) / |.| (r the smallest rotation), vector by vector:
        # the same block (M commutes with every U(g))
        twin = {i: names.index((lam, 1.0)) for i, (lam, sgn) in enumerate(names)
                if sgn < 0 and step is not None and lam not in unpaired
                and (lam, 1.0) in names}
        return parts, sels, twin

    @classmethod
    def from_orbits(cls, system, group, rotation_of, self_block: np.ndarray, reps: dict,
                    pairs: list) -> "SymmetricLU | None":
        """The split factorization without assembling M: its core blocks are ``self_block``
        on the diagonal and, for the cores j != i, T(h_j) reps[key] T(h_i)^T with
        (j, i, key, h_j, h_i) in ``pairs`` (h: 2 x 2 local actions, T(h) = R_m(h) (x) I per
        mode order m, ``rotation_of``; None: the identity). Each block Q_s^T M Q_s is summed
        over the few distinct placements ``reps`` with coefficients on the small space,
        never over the n^2 entries of M. None as :meth:`layout`."""
        n = system.n_unknowns
        lay = cls.layout(system, group, rotation_of)
        if lay is None:
            return None
        parts, sels, twin = lay
        model = system.models[0]
        n_cores = len(system.models)
        local = [np.arange(model.n0)] + [model.n0 + 2 * (m - 1) * model.n1
                                         + np.arange(2 * model.n1)
                                         for m in range(1, model.m_max + 1)]
        eye2 = np.eye(2)

        def t(m, h):
            return np.eye(1) if m == 0 else rotation_of(m, eye2 if h is None else h)

        # T(h)^T V_m seen from each side of each pair: (P, r_small, r_m) per mode order
        vs = [v.reshape(n_cores, -1, v.shape[1]) for _, v in parts]
        terms = {None: [(j, j, None, None) for j in range(n_cores)]}
        for j, i, key, hj, hi in pairs:
            terms.setdefault(key, []).append((j, i, hj, hi))
        w = {}
        for key, lst in terms.items():
            w[key] = [(np.array([t(m, hj).T @ vs[m][j] for j, _, hj, _ in lst]),
                       np.array([t(m, hi).T @ vs[m][i] for _, i, _, hi in lst]))
                      for m in range(len(parts))]
        mats = {**reps, None: self_block}
        lus = {}
        with one_blas_thread():
            for b, sel in enumerate(sels):
                if b in twin:
                    continue
                sizes = [len(s) * len(loc) // vs[m].shape[1]
                         for m, (s, loc) in enumerate(zip(sel, local))]
                edges = np.r_[0, np.cumsum(sizes)]
                blk = np.zeros((edges[-1], edges[-1]))
                for mr, mc in np.ndindex(len(parts), len(parts)):
                    if not sizes[mr] or not sizes[mc]:
                        continue
                    acc = 0.0
                    for key in terms:
                        if key is None and mr != mc:
                            continue  # the self blocks are mode-diagonal
                        c = np.einsum("psa,ptb->satb", w[key][mr][0][..., sel[mr]],
                                      w[key][mc][1][..., sel[mc]])
                        sub = mats[key][np.ix_(local[mr], local[mc])]
                        sub = sub.reshape(c.shape[0], -1, c.shape[2], sub.shape[1] // c.shape[2])
                        acc = acc + np.einsum("satb,sptq->apbq", c, sub, optimize=True)
                    blk[edges[mr]:edges[mr + 1], edges[mc]:edges[mc + 1]] = \
                        acc.reshape(sizes[mr], sizes[mc])
                lus[b] = lu_factor(blk, overwrite_a=True)
        res = cls(parts, [(sel, lus[twin.get(b, b)]) for b, sel in enumerate(sels)], n)

        def turn(x, h, transpose=False):  # T(h) x (T(h)^T x) on one core's unknowns
            out = x.copy()
            for m in range(1, len(parts)):
                r = t(m, h)
                out[local[m]] = ((r.T if transpose else r) @ x[local[m]].reshape(2, -1)).ravel()
            return out

        def matvec(x):
            y = np.zeros_like(x)
            off = system.offsets
            for j in range(n_cores):
                y[off[j]:off[j + 1]] = self_block @ x[off[j]:off[j + 1]]
            for j, i, key, hj, hi in pairs:
                y[off[j]:off[j + 1]] += turn(mats[key] @ turn(x[off[i]:off[i + 1]], hi, True),
                                             hj)
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


def _adapted_basis(z: np.ndarray, mirror, step=None) -> tuple[np.ndarray, list, set]:
    """Orthonormal eigenvectors (r, r) of the central element ``z`` (a different scalar on each
    isotypic component), each component split further by the eigenvalue +-1 of the
    reflection ``mirror`` (r, r) (commuting with M, it halves a 2-dimensional irreducible
    type's component), each vector's block key (eigenvalue, reflection sign), and the
    eigenvalues whose -1 half could not be made the image of the +1 half under
    (``step`` - ``step``^T) / |.| (``step`` (r, r) a rotation of the group; on a
    2-dimensional type's component it is a multiple of an orthogonal map that commutes with
    M and swaps the reflection's eigenspaces)."""
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
        if step is not None and plus.shape[1] and plus.shape[1] == minus.shape[1]:
            turned = (step - step.T) @ plus
            norm = np.linalg.norm(turned[:, 0])
            turned = turned / norm if norm > 1e-9 else turned
            if (norm > 1e-9 and np.abs(mirror @ turned + turned).max() < 1e-10
                    and np.abs(turned.T @ turned - np.eye(turned.shape[1])).max() < 1e-10):
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
