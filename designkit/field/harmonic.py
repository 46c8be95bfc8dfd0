"""Exterior zonal harmonic expansion of a thick winding's field, with a rigorous error bound.

Outside the sphere of radius s = sqrt(ro^2 + h^2) about the winding's centre, B = -grad Phi
per unit mu0 J, Phi = sum_l g_l P_l(cos theta) / r^(l+1). With t = s / r < 1, x = cos theta,
g^_l = g_l / s^(l+3) and C_l = C_l^(3/2) = P'_(l+1) (on-axis generating functions):
  Bz = s t sum g^_l (l+1) t^(l+1) P_(l+1),   B_r(spherical) = s t sum g^_l (l+1) t^(l+1) P_l,
  Brho = (B_r - x Bz) / sin theta  (or Brho / rho = sum g^_l t^(l+3) C_l near the axis),
  dBz/dz = -sum g^_l (l+1)(l+2) t^(l+3) P_(l+2),
  dBrho/dz = (dBz/dr - x dBz/dz) / sin theta  (or -(rho/s) sum g^_l (l+1) t^(l+4) C_(l+1)).
(l+1) g^_l = 1/2 int int a^2 R0^(l-1) C_(l-1)(z0 / R0) da dz0 over the section (lengths in s):
polynomials, integrated exactly by Gauss-Legendre up to degree lc.
Truncation after degree L, per term: |B_l| <= s |g^_l| (l+1) t^(l+2) and
|G_l|_F <= 2.2 |g^_l| (l+1)(l+2) t^(l+3) (|P_l| <= 1, |P_l^1| <= sqrt(l(l+1)/2) by the
addition theorem); beyond lc, |g^_l| <= I_(lc+1) / (2 sqrt 2), I_m = int int R0^m (decreasing
in m). The tail sums are tabulated per degree on a grid of t (monotone: the next grid value is
an upper bound). With a rounding bound (a few ulps per degree of the sum of all term bounds,
times 1 / sin theta, 1 / sin^2 theta for G, through the spherical components), a point is taken
only where bound <= rtol (|B_computed| - bound) (the same for |G|): then the bound holds against
the exact value. Cost per point ~ L (a three-term recurrence and a matrix-vector product).
Reference: Jackson, Classical Electrodynamics, 3rd ed., sections 3.3 and 5.5;
docs/field_winding.md ("Exterior harmonic expansion").
"""

from __future__ import annotations

import math
import threading

import numpy as np

T_MAX = 0.9
"""Largest s / r tried (beyond it the series needs hundreds of terms: the exact path wins)."""
L_BUCKETS = (3, 5, 7, 9, 11, 13, 15, 17, 21, 25, 29, 33, 39, 47, 55, 65, 77, 91, 107, 127)
"""Truncation degrees (odd: the even coefficients of a winding centred at z = 0 vanish)."""
L_MAX = L_BUCKETS[-1]
LC = L_MAX + 42
"""Degree up to which the coefficients are computed (odd: I_(LC+1) is a polynomial)."""
NT = 1024
"""Grid of t for the tabulated tail bounds."""
LOG_Y = (math.log(1e-30), math.log(1e3), 0.1)
"""Grid (start, stop, step) of log(allowed error / (s t)) for the degree lookup table."""
G_FROB = 2.2
"""Frobenius norm of one degree's gradient terms over g^_l (l+1)(l+2) t^(l+3) (<= sqrt 4.83)."""
EPS = float(np.finfo(float).eps)
ROUND = 16.0 * EPS
"""Rounding of the recurrences and products, per degree, relative to the term bounds."""
B_FRACTION = 1.0
G_FRACTION = 1.0
SIN_SPHERICAL = 1e-11
"""Points with sin theta >= min(0.2, this / rtol) (its square root with the gradient) take Brho
from the spherical components (rounding amplified by 1 + 2 / sin theta, in the bound)."""
_CACHE: dict = {}
_CACHE_SIZE = 64
_BUFFERS = threading.local()


def _buffer(name, rows, n):
    """A (rows, n) scratch array reused between calls of this thread (no page faults)."""
    if rows * n > 1 << 22:  # > 32 MB: not kept
        return np.empty((rows, n))
    buf = getattr(_BUFFERS, name, None)
    if buf is None or buf.size < rows * n:
        buf = np.empty(max(rows * n, 1 << 16))
        setattr(_BUFFERS, name, buf)
    return buf[: rows * n].reshape(rows, n)


def is_cached(ri, ro, h) -> bool:
    """Are the coefficients of this winding already computed?"""
    return (float(ri), float(ro), float(h)) in _CACHE


def coefficients(ri: float, ro: float, h: float):
    """Cached :func:`compute_coefficients` (the last ``_CACHE_SIZE`` windings)."""
    key = (float(ri), float(ro), float(h))
    if key not in _CACHE:
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = compute_coefficients(*key)
    return _CACHE[key]


def compute_coefficients(ri: float, ro: float, h: float, lc: int = LC):
    """Expansion of the winding ri..ro, -h..h (m): dict with s (m), g (g^_0 .. g^_lc, g^_0 = 0),
    the tail tables tb[i, j] >= sum_{l > L_i} |g^_l| (l+1) t_j^(l+1) and
    tg[i, j] >= sum_{l > L_i} |g^_l| (l+1)(l+2) t_j^(l+1) (t_j = j / NT; row -1: all l >= 1)."""
    s = math.hypot(ro, h)
    na = lc // 2 + 3
    nz = lc // 2 + 2
    xa, wa = np.polynomial.legendre.leggauss(na)
    xz, wz = np.polynomial.legendre.leggauss(nz)
    a = (0.5 * (ro + ri) + 0.5 * (ro - ri) * xa) / s
    z0 = (h * xz) / s
    w = np.outer(0.5 * (ro - ri) * wa, h * wz).ravel() / s**2
    A, Z = np.meshgrid(a, z0, indexing="ij")
    A, Z = A.ravel(), Z.ravel()
    R2 = A * A + Z * Z
    wa2 = 0.5 * w * A * A
    g = np.zeros(lc + 1)
    # D_n = R0^n C_n(z0 / R0): n D_n = (2n + 1) z0 D_(n-1) - (n + 1) R0^2 D_(n-2)
    d_prev = np.ones_like(A)
    d_cur = 3.0 * Z
    g[1] = wa2 @ d_prev / 2.0
    g[2] = wa2 @ d_cur / 3.0
    for n in range(2, lc):
        d_prev, d_cur = d_cur, ((2 * n + 1) * Z * d_cur - (n + 1) * R2 * d_prev) / n
        g[n + 1] = wa2 @ d_cur / (n + 2)
    g[2::2] = 0.0  # odd in z0 over a section symmetric about z = 0: exactly zero
    # |g^_l| <= I_(l+1) / (2 sqrt 2) for l > lc; R0^(lc+1) is a polynomial, integrated exactly
    g_hi = (w @ R2 ** ((lc + 1) // 2)) / (2.0 * math.sqrt(2.0))
    # rounding of the sums: the recurrence's values reach C_n(1) ~ n^2 / 2 times the terms
    g_abs = 2.0 * h * (ro - ri) / s**2 / (2.0 * math.sqrt(2.0))
    lv = np.arange(lc + 1)
    mag = np.abs(g) + 4.0 * EPS * (lv + 1.0) ** 2 * g_abs
    mag[0] = 0.0
    tj = np.arange(NT + 1) / NT
    tj[-1] = 1.0 - 1e-9
    pw = tj[:, None] ** (lv + 1.0)[None, :]  # (NT+1, lc+1)
    kb = mag * (lv + 1.0)
    kg = kb * (lv + 2.0)
    rows = list(L_BUCKETS) + [0]
    tb = np.empty((len(rows), NT + 1))
    tg = np.empty((len(rows), NT + 1))
    for i, L in enumerate(rows):
        tb[i] = pw[:, L + 1:] @ kb[L + 1:] + g_hi * tail_k(lc + 2, tj)
        tg[i] = pw[:, L + 1:] @ kg[L + 1:] + g_hi * tail_kk(lc + 2, tj)
    # degree lookup: first bucket whose B tail at t_j is <= y_q (conservative: y rounded down)
    yq = np.exp(np.arange(*LOG_Y))
    deg = np.zeros((NT + 1, yq.size), dtype=np.int8)
    deg_g = np.zeros((NT + 1, yq.size), dtype=np.int8)
    for i in range(len(L_BUCKETS)):
        deg += (tb[i][:, None] > yq[None, :]).astype(np.int8)
        deg_g += (tg[i][:, None] > yq[None, :]).astype(np.int8)
    return dict(s=s, g=g, tb=tb, tg=tg, deg=deg, deg_g=deg_g)


def tail_k(m, t):
    """sum_{k >= m} k t^k (t < 1)."""
    return t**m * (m - (m - 1) * t) / (1.0 - t) ** 2


def tail_kk(m, t):
    """sum_{k >= m} k (k + 1) t^k (t < 1)."""
    return t**m * (m * (m + 1) - 2.0 * (m - 1) * (m + 1) * t + (m - 1) * m * t * t) / (
        1.0 - t) ** 3


def _estimate(ri, ro, h, rho, z, gradient=False):
    """|B| per mu0 J of the two end faces as point poles (chooses L only; not a bound); with
    ``gradient`` also |G| ~ 2 |B| / (distance to the nearer pole)."""
    q = (ro**3 - 3 * ro * ri**2 + 2 * ri**3) / 6.0 + 0.5 * ri**2 * (ro - ri)  # int M r dr / J
    p2 = rho * rho
    d1 = (z - h) ** 2 + p2
    d2 = (z + h) ** 2 + p2
    r1 = 1.0 / (d1 * np.sqrt(d1))
    r2 = 1.0 / (d2 * np.sqrt(d2))
    br = rho * (r1 - r2)
    bz = (z - h) * r1 - (z + h) * r2
    est = 0.5 * q * np.sqrt(br * br + bz * bz)
    if not gradient:
        return est
    return est, 2.0 * est / np.sqrt(np.minimum(d1, d2))


def _lookup(table, j, y):
    """Degree bucket of the tail table ``table`` at t-grid index j for tails <= y."""
    with np.errstate(divide="ignore"):
        q = (np.log(np.maximum(y, 1e-300)) - LOG_Y[0]) * (1.0 / LOG_Y[2])
    q = np.clip(q, 0, table.shape[1] - 1)
    return table[j, q.astype(np.intp)].astype(np.int16)


def _recurrence(out, xt, t2, first, second, a, b, need):
    """Rows out[m] = kappa_m^-1 v_m of v_(m+1) = a(m) xt v_m - b(m) t2 v_(m-1), kappa_(m+1) =
    a(m) kappa_m (so each step is two products and one scaled difference), in place from v_0,
    v_1; column i only up to row need[i] (need sorted ascending; the rest of a row is 0).
    Returns kappa (multiply the coefficients by it)."""
    rows = out.shape[0]
    kappa = np.ones(rows)
    kappa[1] = 1.0
    out[0] = first
    out[1] = second
    tmp = np.empty_like(xt)
    starts = np.searchsorted(need, np.arange(rows), side="left")
    for m in range(1, rows - 1):
        kappa[m + 1] = a(m) * kappa[m]
        c = b(m) * kappa[m - 1] / kappa[m + 1]
        k = starts[m + 1]
        out[m + 1, :k] = 0.0
        row, tk = out[m + 1, k:], tmp[k:]
        np.multiply(xt[k:], out[m, k:], out=row)
        np.multiply(t2[k:], out[m - 1, k:], out=tk)
        tk *= c
        row -= tk
    return kappa


def _partial(coef, M, last, need):
    """sum over rows m <= last[i] of coef[m] M[m, i] (rows past last[i], up to need[i], are
    filled by the recurrence and subtracted here)."""
    full = coef @ M
    for d in range(1, int((need - last).max(initial=0)) + 1):
        r = last + d
        c = np.where(need >= r, coef[np.minimum(r, coef.shape[0] - 1)], 0.0)
        extra = np.flatnonzero(c)  # (rows of even degree have coefficient 0)
        if extra.size:
            full[extra] -= c[extra] * M[r[extra], extra]
    return full


def _series(g, s, pts, L, gradient, spherical):
    """Truncated sums to degree L[i] (sorted ascending) per point: (br, bz) or (br, bz,
    br_over_rho, dbr_dz, dbz_dz); ``pts`` the points' (x, t, rho, sin theta) arrays.
    ``spherical``: everything from the P recurrence (Brho and dBz/drho through the spherical
    components, divided by sin theta); else Brho / rho and dBrho/dz from the C recurrence
    (exact on the axis)."""
    x, t, rho, sin = pts
    xt = x * t
    t2 = t * t
    lm = int(L[-1])
    # P~_m = t^(m+1) P_m, rows 0 .. lm + 1 (+ 1 with the gradient); coefficient rows m = l + k
    need_p = L + (2 if gradient else 1)
    P = _buffer("P", lm + (3 if gradient else 2), x.shape[0])
    kp = _recurrence(P, xt, t2, t, xt * t, lambda m: (2 * m + 1) / (m + 1),
                     lambda m: m / (m + 1), need_p)

    def rows(values, shift, kappa):
        c = np.zeros(kappa.shape[0])
        c[1 + shift : lm + 1 + shift] = values * kappa[1 + shift : lm + 1 + shift]
        return c

    lv = np.arange(1, lm + 1)
    gl = g[1 : lm + 1]
    g1 = gl * (lv + 1)
    g2 = g1 * (lv + 2)
    bz = s * _partial(rows(g1, 1, kp), P, L + 1, need_p)
    if gradient:
        dbz_dz = -_partial(rows(g2, 2, kp), P, L + 2, need_p)
    if spherical:
        b_r = (s * t) * _partial(rows(g1, 0, kp), P, L, need_p)
        br = (b_r - x * bz) / sin
        if not gradient:
            return br, bz
        # d/dr at fixed theta multiplies degree l's term by -(l + 2) / r
        drbz = -t * _partial(rows(g2, 1, kp), P, L + 1, need_p)
        return br, bz, br / rho, (drbz - x * dbz_dz) / sin, dbz_dz
    # C~_m = t^(m+3) C_m
    need_c = L + (1 if gradient else 0)
    C = _buffer("C", lm + (2 if gradient else 1), x.shape[0])
    t3 = t2 * t
    kc = _recurrence(C, xt, t2, t3, 3.0 * xt * t3, lambda m: (2 * m + 3) / (m + 1),
                     lambda m: (m + 2) / (m + 1), need_c)
    brr = _partial(rows(gl, 0, kc), C, L, need_c)
    if not gradient:
        return rho * brr, bz
    dbr_dz = -(rho / s) * _partial(rows(g1, 1, kc), C, L + 1, need_c)
    return rho * brr, bz, brr, dbr_dz, dbz_dz


def harmonic_rz(ri, ro, h, rho, z, gradient, rtol, tries=2):
    """Exterior expansion where its bound meets rtol.

    Returns (done, values): ``done`` (n,) bool marks the points computed here (their error
    bound holds); ``values`` (2 or 5, n) the components (br, bz[, br_over_rho, dbr_dz,
    dbz_dz]) per unit mu0 J (m, dimensionless derivatives), meaningful where done. A point
    whose bound fails is retried with up to ``tries`` larger degrees.
    """
    n = rho.shape[0]
    nout = 5 if gradient else 2
    out = np.empty((nout, n))
    done = np.zeros(n, dtype=bool)
    co = coefficients(ri, ro, h)
    s, g, tb, tg = co["s"], co["g"], co["tb"], co["tg"]
    r2 = rho * rho + z * z
    cand = np.nonzero(r2 * (T_MAX * T_MAX) >= s * s)[0]
    if cand.size == 0:
        return done, out
    rc = np.sqrt(r2[cand])
    tc = s / rc
    j = np.minimum(np.ceil(tc * NT).astype(np.intp), NT)
    est = _estimate(ri, ro, h, rho[cand], z[cand], gradient)
    # smallest degree whose tabulated B tail is within 0.7 of the allowed error (estimated |B|)
    # (and G tail of |G|)
    bucket = _lookup(co["deg"], j, (0.7 * B_FRACTION * rtol / s) * (
        est[0] if gradient else est) / tc)
    if gradient:
        bucket = np.maximum(bucket, _lookup(co["deg_g"], j, (0.7 * G_FRACTION * rtol / G_FROB)
                                            * est[1] / (tc * tc)))
    lb = np.array(L_BUCKETS + (L_BUCKETS[-1],))
    sin = rho[cand] / rc
    # sin theta below this takes Brho / rho (and dBrho/dz) from the C recurrence
    cut = SIN_SPHERICAL / rtol
    axis = (sin < min(0.2, math.sqrt(cut) if gradient else cut)).astype(np.int16)
    nbk = len(L_BUCKETS)
    todo = np.nonzero(bucket < nbk)[0]
    for attempt in range(tries + 1):
        if todo.size == 0:
            break
        # sorted by (mode, degree): each mode a contiguous run, degrees ascending within it
        todo = todo[np.argsort(bucket[todo] + 32 * axis[todo], kind="stable")]
        bi = bucket[todo].astype(np.intp)
        idx = cand[todo]
        ts, js, ss = tc[todo], j[todo], sin[todo]
        xs = z[idx] / rc[todo]
        rs = rho[idx]
        Ls = lb[bi]
        res = np.empty((nout, todo.size))
        k = todo.size - int(np.count_nonzero(axis[todo]))
        for sph, sl in ((True, slice(0, k)), (False, slice(k, todo.size))):
            if sl.stop > sl.start:
                res[:, sl] = _series(g, s, (xs[sl], ts[sl], rs[sl], ss[sl]), Ls[sl],
                                     gradient, sph)
        rnd = ROUND * (Ls + 2.0)
        if gradient:
            rnd_g = rnd.copy()
        # rounding through the spherical components: amplified by 1 / sin (Brho, dBrho/dz)
        # and 1 / sin^2 (Brho / rho)
        inv = 1.0 / np.maximum(ss[:k], 1e-300)
        if gradient:
            rnd_g[:k] *= 1.0 + 2.0 * inv * inv
        rnd[:k] *= 1.0 + 2.0 * inv
        eb = (s * ts) * (tb[bi, js] + rnd * tb[-1, js])
        nb = np.sqrt(res[0] * res[0] + res[1] * res[1])
        ok = eb <= B_FRACTION * rtol * (nb - eb)
        if gradient:
            eg = (G_FROB * ts * ts) * (tg[bi, js] + rnd_g * tg[-1, js])
            # |G|_F from the components (dbr_drho = -dbz_dz - br_over_rho, dbz_drho = dbr_dz)
            ng = np.sqrt((res[4] + res[2]) ** 2 + res[2] ** 2 + 2.0 * res[3] ** 2
                         + res[4] ** 2)
            ok &= eg <= G_FRACTION * rtol * (ng - eg)
        if ok.all():
            out[:, idx] = res
            done[idx] = True
            break
        good = idx[ok]
        out[:, good] = res[:, ok]
        done[good] = True
        # the estimate of |B| was too optimistic: retry with a larger degree
        todo = todo[~ok]
        bucket[todo] += 1
        todo = todo[bucket[todo] < nbk]
    return done, out
