"""The cold fit's global search: :class:`GridSearch`.

At each candidate position c of a fixed grid the dipole's field is linear in the moment m and
in a uniform background b: f_k = D_ck m + T_k b per observation block k (a sensor, or a
subtracted pair with T_k = I - P_k). The weighted least-squares (m, b) at every candidate is a
3 x 3 solve after eliminating b (Schur complement), from sums over the blocks that are
matrix-vector products with tables precomputed once (D^T D, D^T T, D^T): the search costs a
few products of the grid's size per frame. Candidates whose best moment is far from the
model's |m| (below 1/4 or above 4x) rank last; the best few seed the nonlinear fit with
their position and moment direction. numpy only.
"""

from __future__ import annotations

import math

import numpy as np

from .magnet import MU0


def grid_points(lo, hi) -> np.ndarray:
    """Candidates (C, 3) m in the plausible box [lo, hi]: ~1.2 cm apart in x, y (a coarser grid
    can put every start in a wrong basin near the board), 7 heights denser near the board."""
    nx = max(int(round((hi[0] - lo[0]) / 0.012)), 5)
    ny = max(int(round((hi[1] - lo[1]) / 0.012)), 5)
    zs = lo[2] + np.array([0.004, 0.010, 0.018, 0.028, 0.042, 0.060, 0.085])
    g = np.stack(np.meshgrid(np.linspace(lo[0] + 0.005, hi[0] - 0.005, nx),
                             np.linspace(lo[1] + 0.005, hi[1] - 0.005, ny),
                             zs[zs < hi[2] - 0.002], indexing="ij"), -1)
    return g.reshape(-1, 3)


def dipole_basis(points: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """(C, n, 3, 3) T/(A m^2): the field at ``points`` (n, 3) of a unit dipole along each axis
    at each of ``positions`` (C, 3): mu0 / (4 pi) (3 r r^T / r^5 - I / r^3)."""
    r = points[None] - positions[:, None]
    rho2 = np.einsum("cni,cni->cn", r, r)
    inv3 = MU0 / (4 * math.pi) * rho2 ** -1.5
    d = (3.0 * inv3 / rho2)[..., None, None] * r[..., :, None] * r[..., None, :]
    d[..., [0, 1, 2], [0, 1, 2]] -= inv3[..., None]
    return d


_SYM = (0, 1, 2, 4, 5, 8)
"""Flat indices of a symmetric 3 x 3 matrix's six distinct entries (00, 01, 02, 11, 12, 22)."""
_SYM_ROWS = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])
_SYM_COLS = np.array([[0, 1, 2], [0, 1, 2], [0, 1, 2]])
"""Entry (i, j) of the symmetric matrix as its six-entry index, and j: (D v)_i = sum_j."""


class GridSearch:
    """The global search over ``points`` (n, 3) m with observation blocks ``op`` (k, 3, n, 3)
    (None: one block a sensor), the box [lo, hi], the model's |m| ``moment`` (A m^2) and the
    background's observable directions ``basis`` (3, j) (the subtraction sees fewer)."""

    def __init__(self, points: np.ndarray, op: np.ndarray | None, lo, hi, moment: float,
                 basis: np.ndarray):
        self.candidates = grid_points(np.asarray(lo, float), np.asarray(hi, float))
        d = dipole_basis(np.asarray(points, float), self.candidates)      # (C, n, 3, 3)
        n = len(points)
        self.moment = moment
        self.isotropic = op is None
        if op is None:
            # one block a sensor, T = I: D is symmetric, so D^T D = D D and D^T T = D, six
            # distinct entries each
            # (the tables entry-major, row k C + c: the per-candidate sums come out as (6, C)
            # and (3, C), contiguous rows for the batched 3 x 3 solve)
            c = len(d)
            self.qa = np.ascontiguousarray(np.einsum("cnij,cnjl->cnil", d, d).reshape(
                c, n, 9)[..., _SYM].transpose(2, 0, 1).reshape(6 * c, n))
            self.qe = np.ascontiguousarray(d.reshape(c, n, 9)[..., _SYM].transpose(
                2, 0, 1).reshape(6 * c, n))
            # the leave-one-out pass's coarse candidates (every other one in x and y) and the
            # rows of its tables
            g = self.candidates
            xs, ys = np.unique(g[:, 0]), np.unique(g[:, 1])
            keep = np.isin(g[:, 0], xs[::2]) & np.isin(g[:, 1], ys[::2])
            self.coarse = np.flatnonzero(keep)
            coarse6 = (np.arange(6)[:, None] * c + self.coarse).reshape(-1)
            # their rows of the tables, gathered once (D^T, row i C + c: (3 C', n, 3))
            self.dt_coarse = np.ascontiguousarray(d[self.coarse].transpose(3, 0, 1, 2).reshape(
                3 * len(self.coarse), n, 3))
            self.qa_coarse = np.ascontiguousarray(self.qa[coarse6])
            self.qe_coarse = np.ascontiguousarray(self.qe[coarse6])
            return
        d = np.einsum("kisj,csjl->ckil", op, d)
        t = op.sum(axis=2) @ basis                                        # (k, 3, j)
        c, k = d.shape[:2]
        self.t = t
        self.qa = np.ascontiguousarray(np.einsum("ckji,ckjl->cilk", d, d).reshape(c * 9, k))
        self.qe = np.ascontiguousarray(np.einsum("ckji,kjl->cilk", d, t).reshape(
            c * 3 * t.shape[2], k))
        self.dt = np.ascontiguousarray(np.einsum("ckji->cikj", d).reshape(c * 3, k * 3))

    def starts(self, data: np.ndarray, weights: np.ndarray, background: bool,
               keep: int = 3) -> list:
        """The best ``keep`` (position (3,), moment (3,)) for the frame: ``data`` (k, 3) T with
        0 where unusable, ``weights`` (k,) 1/sigma^2 (0 where unusable)."""
        wd = data * weights[:, None]
        base = float(np.einsum("ki,ki->", wd, data))
        if self.isotropic:
            # D's six entries times (w d_x, w d_y, w d_z, w): one pass over the table, (6, C, 4);
            # rhs = D w d (3, C) component-major, E = sum w D (6, C)
            x = (self.qe @ np.concatenate((wd, weights[:, None]), axis=1)).reshape(6, -1, 4)
            rhs = x[_SYM_ROWS, :, _SYM_COLS].sum(axis=1)
            e = np.ascontiguousarray(x[:, :, 3]) if background else None
            m, base = self._isotropic(weights, wd, rhs, base, e)
            cost = base - np.einsum("ic,ic->c", rhs, m)
            size = np.sqrt(np.einsum("ic,ic->c", m, m)) / self.moment
            m = m.T
        else:
            rhs = (self.dt @ wd.reshape(-1)).reshape(-1, 3)
            m, base = self._general(weights, wd, rhs, base, background)
            cost = base - np.einsum("ci,ci->c", rhs, m)
            size = np.sqrt(np.einsum("ci,ci->c", m, m)) / self.moment
        cost = np.where(np.isfinite(cost), cost, np.inf)
        # a moment far from the magnet's: a wrong basin (ranked after every plausible one)
        cost = cost + np.where((size > 0.25) & (size < 4.0), 0.0, 1e300)
        k = min(keep, len(cost))
        best = np.argpartition(cost, k - 1)[:k]
        best = best[np.argsort(cost[best])]
        return [(self.candidates[j].copy(), m[j].copy()) for j in best]

    def leave_one_out(self, data: np.ndarray, weights: np.ndarray,
                      background: bool) -> int | None:
        """The block whose removal fits the frame best (one block a sensor only), or None: the
        search once per block left out, in one pass over every other candidate in x and y
        (the coarse grid tells the liar; the full search without it then gives the start). A
        single gross fault drags every start and the full search; without the liar the others
        agree, so its removal lowers the best cost the most. Each left-out sum is the full one
        minus that block's term: a batch of 3 x 3 solves over candidates x blocks."""
        if not self.isotropic or int(np.count_nonzero(weights)) < 4:
            return None
        sub = self.coarse
        c, n = len(sub), len(weights)
        wd = data * weights[:, None]
        # per block: the candidates' right-hand sides D^T w d (C, 3, b) and A's entries (6, C, b)
        # per block: the candidates' right-hand sides D^T w d (3, C, b) and A's entries (6, C, b)
        per = np.einsum("xka,ka->xk", self.dt_coarse, wd).reshape(3, c, n)
        rhs = per.sum(axis=2, keepdims=True) - per
        a_blk = (self.qa_coarse * weights).reshape(6, c, n)
        a = a_blk.sum(axis=2, keepdims=True) - a_blk
        base = float(np.einsum("ki,ki->", wd, data)) - np.einsum("ki,ki->k", wd, data)
        if background:
            e_blk = (self.qe_coarse * weights).reshape(6, c, n)
            e = e_blk.sum(axis=2, keepdims=True) - e_blk
            wt = np.maximum(float(weights.sum()) - weights, 1e-300)
            rb = wd.sum(axis=0)[:, None] - wd.T                          # (3, b)
            ee, er = _background_terms(e, rb)
            a = a - ee / wt
            rhs = rhs - er / wt
            base = base - np.einsum("ib,ib->b", rb, rb) / wt
        m = _solve_sym3(a, rhs)                                          # (3, C, b)
        cost = base - np.einsum("icb,icb->cb", rhs, m)
        size = np.sqrt(np.einsum("icb,icb->cb", m, m)) / self.moment
        cost = np.where(np.isfinite(cost) & (size > 0.25) & (size < 4.0) & (weights > 0),
                        cost, np.inf)
        best = cost.min(axis=0)
        j = int(np.argmin(best))
        return j if np.isfinite(best[j]) else None

    def _isotropic(self, weights, wd, rhs, base, e):
        """The moments (3, C) and the candidate-independent cost part, T = I, from rhs (3, C):
        with the background eliminated (``e``: E's six entries (6, C), None: no background),
        M = A - E E / W and rhs -= E rb / W (W = sum w, rb = sum w d), in the six distinct
        entries of the symmetric matrices (rhs is updated in place)."""
        a = (self.qa @ weights).reshape(6, -1)
        if e is not None:
            wt = float(weights.sum())
            rb = wd.sum(axis=0)
            ee, er = _background_terms(e, rb)
            a = a - ee / wt
            rhs -= er / wt
            base -= float(rb @ rb) / wt
        return _solve_sym3(a, rhs), base

    def _general(self, weights, wd, rhs, base, background):
        """The same for general blocks (subtracted pairs): the batched 3 x 3 Schur complement."""
        c = len(self.candidates)
        a = (self.qa @ weights).reshape(c, 3, 3)
        if background and self.t.shape[2]:
            f = np.einsum("k,kji,kjl->il", weights, self.t, self.t)
            rb = np.einsum("kji,kj->i", self.t, wd)
            finv = np.linalg.inv(f)
            e = (self.qe @ weights).reshape(c, 3, -1)
            ef = e @ finv
            a = a - ef @ np.swapaxes(e, 1, 2)
            rhs -= ef @ rb
            base -= float(rb @ finv @ rb)
        a = 0.5 * (a + np.swapaxes(a, 1, 2)).reshape(c, 9)[:, _SYM].T
        return _solve_sym3(a, rhs.T).T, base


def _solve_sym3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve A x = b for symmetric A given by its six distinct entries a (6, ...) (00, 01, 02,
    11, 12, 22) and b (3, ...), component first; x (3, ...), by the adjugate (zero where
    singular)."""
    a00, a01, a02, a11, a12, a22 = a
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    ok = np.abs(det) > 0
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    b0, b1, b2 = b
    x = np.empty(b.shape)
    x[0] = c00 * b0 + c01 * b1 + c02 * b2
    x[1] = c01 * b0 + c11 * b1 + c12 * b2
    x[2] = c02 * b0 + c12 * b1 + c22 * b2
    x *= inv
    return x


def _background_terms(e, rb):
    """E E and E rb for the symmetric E given by its six distinct entries ``e`` (00, 01, 02, 11,
    12, 22; each of any shape) and ``rb`` (3, ...): E E in the same six-entry order, E rb (3,
    ...) component first -- what eliminating a uniform background takes from the moment's
    normal equations."""
    e00, e01, e02, e11, e12, e22 = e
    ee = np.stack([e00 * e00 + e01 * e01 + e02 * e02,
                   e00 * e01 + e01 * e11 + e02 * e12,
                   e00 * e02 + e01 * e12 + e02 * e22,
                   e01 * e01 + e11 * e11 + e12 * e12,
                   e01 * e02 + e11 * e12 + e12 * e22,
                   e02 * e02 + e12 * e12 + e22 * e22])
    er = np.stack([e00 * rb[0] + e01 * rb[1] + e02 * rb[2],
                   e01 * rb[0] + e11 * rb[1] + e12 * rb[2],
                   e02 * rb[0] + e12 * rb[1] + e22 * rb[2]])
    return ee, er
