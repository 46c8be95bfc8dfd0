"""Solid-harmonic maths of the map's harmonic cells (numpy only).

Per cell and coil the map holds a potential psi, harmonic, as a polynomial of degree L in the
cell-local coordinates s = (p - centre) / r (r = half the cell's largest side): its free
monomials (:func:`harmonic_terms`), the rest from Laplace's equation
(:func:`harmonic_potential`). A's 8 rows are its first and second derivatives
(:func:`harmonic_rows`), harmonic polynomials of degree L - 1, evaluated on the L^2 real
regular solid harmonics (:func:`solid_harmonics`, a recurrence in z and one complex product per
degree) instead of the C(L + 2, 3) monomials. Units: s dimensionless; divide rows 0-2 by r and
rows 3-7 by r^2 for T/A and T/(m A).
"""

from __future__ import annotations

import functools

import numpy as np

def harmonic_terms(degree: int) -> list:
    """The potential's free monomials s_x^a s_y^b s_z^c, c in (0, 1), 1 <= a + b + c <=
    ``degree``, in file order: total degree ascending, then c, then a descending; K = (L + 1)^2
    - 1 of them. The coefficients stored are those of these monomials in psi; all others follow
    from Laplace's equation (:func:`harmonic_potential`)."""
    return [(a, n - c - a, c) for n in range(1, degree + 1) for c in (0, 1)
            for a in range(n - c, -1, -1)]


def monomial_exponents(degree: int) -> np.ndarray:
    """(M, 3) exponents (a, b, c) of the monomials s_x^a s_y^b s_z^c of total degree <=
    ``degree``, M = C(degree + 3, 3): total degree ascending, then a descending, then b
    descending (those of degree <= d are the first C(d + 3, 3): one order serves every
    degree)."""
    return np.array([(a, b, n - a - b) for n in range(degree + 1)
                     for a in range(n, -1, -1) for b in range(n - a, -1, -1)],
                    dtype=np.intp).reshape(-1, 3)


def harmonic_potential(degree: int) -> np.ndarray:
    """(K, M) float64: the monomial coefficients (:func:`monomial_exponents` order, degree <=
    L) of psi per unit free coefficient (:func:`harmonic_terms`): the free term
    s_x^a s_y^b s_z^c plus the z^(c + 2k) terms Laplace's equation requires,
    P_k = -Laplacian_xy(P_(k-1)) / ((c + 2k)(c + 2k - 1)), P_0 = s_x^a s_y^b."""
    index = {tuple(e): i for i, e in enumerate(monomial_exponents(degree).tolist())}
    terms = harmonic_terms(degree)
    out = np.zeros((len(terms), len(index)))
    for f, (a, b, c) in enumerate(terms):
        poly, k = {(a, b): 1.0}, 0
        while poly:
            for (i, j), val in poly.items():
                out[f, index[(i, j, c + 2 * k)]] += val
            k += 1
            div = (c + 2 * k) * (c + 2 * k - 1)
            nxt: dict = {}
            for (i, j), val in poly.items():
                if i >= 2:
                    nxt[(i - 2, j)] = nxt.get((i - 2, j), 0.0) - val * i * (i - 1) / div
                if j >= 2:
                    nxt[(i, j - 2)] = nxt.get((i, j - 2), 0.0) - val * j * (j - 1) / div
            poly = {key: val for key, val in nxt.items() if val != 0.0}
    return out


def harmonic_rows(degree: int) -> np.ndarray:
    """(8, M, K) float64 with M = C(L + 2, 3): row r of A (:data:`ROWS`: the derivatives
    d/ds_x, d/ds_y, d/ds_z, d2/ds_x2, d2/ds_x ds_y, d2/ds_x ds_z, d2/ds_y2, d2/ds_y ds_z of psi)
    as monomial coefficients of degree <= L - 1 per unit free coefficient. In metres: divide
    rows 0-2 by r and rows 3-7 by r^2."""
    e = monomial_exponents(degree)
    index = {tuple(x): i for i, x in enumerate(e.tolist())}
    m_low = len(monomial_exponents(degree - 1))
    pot = harmonic_potential(degree).T  # (M_L, K)

    def diff(coef: np.ndarray, axis: int) -> np.ndarray:
        out = np.zeros_like(coef)
        for i, x in enumerate(e.tolist()):
            if x[axis] >= 1:
                y = list(x)
                y[axis] -= 1
                out[index[tuple(y)]] += x[axis] * coef[i]
        return out

    dx, dy, dz = (diff(pot, a) for a in range(3))
    rows = [dx, dy, dz, diff(dx, 0), diff(dx, 1), diff(dx, 2), diff(dy, 1), diff(dy, 2)]
    return np.stack([r[:m_low] for r in rows])


def monomials(s: np.ndarray, degree: int, out: np.ndarray | None = None) -> np.ndarray:
    """(M, n) monomials of degree <= ``degree`` (:func:`monomial_exponents` order) of local
    coordinates s (n, 3), built degree by degree (3 products per degree: x times the previous
    degree's block, y times its x-free part, z times its last)."""
    n = len(s)
    if out is None:
        out = np.empty((len(monomial_exponents(degree)), n), s.dtype)
    out[0] = 1.0
    x, y, z = s[:, 0], s[:, 1], s[:, 2]
    start, size = 0, 1  # the previous degree's block
    for d in range(1, degree + 1):
        new = start + size
        prev = out[start:new]
        np.multiply(prev, x, out=out[new:new + size])
        np.multiply(prev[size - d:], y, out=out[new + size:new + size + d])
        np.multiply(prev[size - 1:], z, out=out[new + size + d:new + size + d + 1])
        start, size = new, size + d + 1
    return out


@functools.lru_cache(maxsize=None)
def solid_harmonic_betas(degree: int) -> tuple:
    """Per degree l <= ``degree`` (a tuple, cached) the (2l - 3, 1) factors
    beta_l^m = ((l - 1)^2 - m^2) / ((2l - 1)(2l - 3)) of the z-recurrence of
    :func:`solid_harmonics` (rows m = 0, 1, 1, 2, 2, ...; empty for l < 2)."""
    out = []
    for ell in range(degree + 1):
        m = np.array([(j + 1) // 2 for j in range(max(0, 2 * ell - 3))], float)
        out.append((((ell - 1) ** 2 - m * m) / ((2 * ell - 1) * (2 * ell - 3)))[:, None])
    return tuple(out)


def solid_harmonic_coefficients(degree: int) -> np.ndarray:
    """(M, (degree + 1)^2) float64: the monomial coefficients (:func:`monomial_exponents`
    order, M = C(degree + 3, 3)) of the basis :func:`solid_harmonics` evaluates, exact (the
    same recurrence run on coefficient vectors)."""
    e = monomial_exponents(degree)
    index = {tuple(x): i for i, x in enumerate(e.tolist())}
    up = [np.array([index.get(tuple(x + np.eye(3, dtype=np.intp)[a]), -1) for x in e])
          for a in range(3)]

    def times(v, a):  # v times s_a (v of degree < ``degree``)
        out = np.zeros_like(v)
        nz = np.flatnonzero(v)
        out[up[a][nz]] = v[nz]
        return out

    betas = solid_harmonic_betas(degree)
    cols = [np.eye(len(e))[0]]
    for ell in range(1, degree + 1):
        b, b1, b2 = ell * ell, (ell - 1) ** 2, max(ell - 2, 0) ** 2
        for j in range(2 * ell - 1):
            v = times(cols[b1 + j], 2)
            if j < 2 * ell - 3:
                r2 = sum(times(times(cols[b2 + j], a), a) for a in range(3))
                v = v - betas[ell][j, 0] * r2
            cols.append(v)
        c = cols[b - 2] if ell > 1 else cols[0]
        s = cols[b - 1] if ell > 1 else np.zeros(len(e))
        cols += [times(c, 0) - times(s, 1), times(c, 1) + times(s, 0)]
    return np.stack(cols, axis=1)


def solid_harmonics(s: np.ndarray, degree: int, out: np.ndarray | None = None,
                    work: np.ndarray | None = None, spans=None) -> np.ndarray:
    """((degree + 1)^2, n) the real regular solid harmonics of degree <= ``degree`` at local
    coordinates ``s`` (3, n) (rows x, y, z), a basis of the harmonic polynomials of that degree
    (A's rows in a cell are such polynomials: their L^2 coefficients instead of the
    C(L + 2, 3) monomials' halve a batch's multiply-adds). Block l (rows l^2 .. (l + 1)^2 - 1)
    holds G_l^0, then the cos and sin parts of G_l^m, m = 1..l:
    G_l^l = Re, Im (s_x + i s_y)^l (from G_(l-1)^(l-1) by one complex product) and, for m < l,
    G_l^m = s_z G_(l-1)^m - beta_l^m |s|^2 G_(l-2)^m (:func:`solid_harmonic_betas`; r^l P_l^m
    of the associated Legendre functions up to a factor per (l, m)). ``work``: scratch of
    shape (2 degree + 4, n) or more; both buffers take the dtype of ``s``. ``spans``: per
    degree l a range (a, b) of the columns that need it (nested: each within the one of l - 1);
    the other columns of block l are left unset."""
    n = s.shape[1]
    if out is None:
        out = np.empty(((degree + 1) ** 2, n), s.dtype)
    if work is None:
        work = np.empty((2 * degree + 4, n), s.dtype)
    if spans is None:
        spans = [(0, n)] * (degree + 1)
    a, b = spans[0]
    out[0, a:b] = 1.0
    if degree == 0:
        return out
    a, b = spans[1]
    x, y, z = s[:, a:b]
    out[1, a:b], out[2, a:b], out[3, a:b] = z, x, y
    r2, xx, ym = work[0, a:b], work[1:3, a:b], work[3:5, a:b]
    np.multiply(x, x, out=r2)
    r2 += y * y
    r2 += z * z
    xx[0], xx[1], ym[0], ym[1] = x, x, y, y
    np.negative(ym[0], out=ym[0])
    a1 = a
    betas = solid_harmonic_betas(degree)
    for ell in range(2, degree + 1):
        a, b = spans[ell]
        o = a - a1  # this degree's columns within the work rows
        z_, r2_, xx_, ym_ = z[o:o + b - a], r2[o:o + b - a], xx[:, o:o + b - a], ym[:, o:o + b - a]
        tmp = work[5:, a:b]
        c, c1, c2 = ell * ell, (ell - 1) ** 2, (ell - 2) ** 2
        k = 2 * ell - 3
        np.multiply(out[c1:c, a:b], z_, out=out[c:c + k + 2, a:b])
        t = tmp[:k]
        np.multiply(out[c2:c1, a:b], r2_, out=t)
        t *= betas[ell]
        out[c:c + k, a:b] -= t
        sec = out[c + k + 2:c + k + 4, a:b]
        np.multiply(out[c - 2:c, a:b], xx_, out=sec)
        np.multiply(out[c - 1:c - 3:-1, a:b], ym_, out=tmp[:2])
        sec += tmp[:2]
    return out


def rows_on_harmonics(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """(8, H, K) float64: :func:`harmonic_rows` of a potential of degree ``degree`` on the
    H = degree^2 :func:`solid_harmonics` of degree <= degree - 1 (every row is harmonic, so it
    lies in their span: checked to rounding), and (M, H) their monomial coefficients."""
    got = _ROWS_H.get(degree)
    if got is None:
        ops = harmonic_rows(degree)  # (8, M, K)
        hc = solid_harmonic_coefficients(degree - 1)  # (M, H)
        ops_h = np.linalg.pinv(hc) @ ops
        resid = np.abs(hc @ ops_h - ops).max()
        if not resid <= 1e-9 * np.abs(ops).max():  # pragma: no cover - a bug, not bad input
            raise AssertionError(f"rows of degree {degree} off the harmonic span ({resid})")
        got = _ROWS_H[degree] = (ops_h, hc)
    return got


_ROWS_H: dict = {}
