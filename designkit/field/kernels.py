"""Pure numerical kernels in a source's local cylindrical frame. No checks, no defaults that
change meaning, no I/O: plain float64 arrays in, arrays out.

Conventions
-----------
Every kernel takes the source's characteristic radius ``a`` (m) and observer coordinates
``rho >= 0`` (m) and ``z`` (m) in the source frame, and returns field components normalised by
the source strength:

* :func:`loop_rz`    B / (mu0 I)    of a circular filament of radius a in the plane z = 0   [1/m]
* :func:`sheet_rz`   B / (mu0 K)    of a cylindrical current sheet (ideal solenoid) of radius
                                    a, z in [-h, h], surface current density K   [1]
* :func:`winding_rz` B / (mu0 J)    of a thick winding, uniform azimuthal current density J
                                    over ri <= r <= ro, -h <= z <= h   [m]

With ``gradient=True`` each returns the 7-tuple
``(br, bz, dbr_drho, dbr_dz, dbz_drho, dbz_dz, br_over_rho)`` (derivatives carry one more 1/m),
``br_over_rho`` being Br / rho evaluated without 0/0 on the axis.

Formulation: hypergeometric series in k^2 below ``K2_SERIES`` (no cancellation near the axis or
far away), closed forms in K(k), E(k) in the variable 1 - sin^2 t elsewhere (no cancellation
near the wire); the derivation is in docs/field_winding.md ("Loop and sheet kernels").
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ellipe, ellipkm1

from firmware_io.special import cel as _cel

K2_SERIES = 0.3
"""Below this k^2 the series are used (<= 42 terms reach 1e-17); above it the K, E forms,
whose recurrences divide by k^2 at most twice (error amplification <= 1/K2_SERIES^2 ~ 11)."""

ON_FILAMENT_KC2 = 1e-150
"""Points with kc^2 below this (closer than ~1e-75 radii to a filament or sheet rim) are on the
singular curve itself: kernels return 0 there (documented singular value), never Inf/NaN."""

_NTERMS = 42


def _series_tables(nterms: int = _NTERMS):
    j = np.arange(nterms, dtype=float)
    # c_j = (1/2)_j / j!   (int_0^{pi/2} u^j dt = (pi/2) c_j)
    c = np.ones(nterms + 3)
    for i in range(1, nterms + 3):
        c[i] = c[i - 1] * (i - 0.5) / i
    a3 = np.ones(nterms)
    a5 = np.ones(nterms)
    for i in range(1, nterms):
        a3[i] = a3[i - 1] * (1.5 + i - 1) / i
        a5[i] = a5[i - 1] * (2.5 + i - 1) / i
    cj = c[:nterms]
    r = j / (j + 1.0)
    tab = {
        # Bz:   (1+rho) c_j - 2 rho c_{j+1} = c_j (1 - rho j/(j+1))
        "bz0": a3 * cj,
        "bz1": -a3 * cj * r,
        # Br:   2 c_{j+1} - c_j = c_j j/(j+1); shifted by one power of k^2 for Br/rho
        "brk": (a3 * cj * r)[1:],
        # dBz/dz: same numerator as Bz with s = 5/2
        "gz0": a5 * cj,
        "gz1": -a5 * cj * r,
        # dBz/drho part 1: (1 - 2u), s = 3/2  -> - (brk series) (handled by sign)
        # dBz/drho part 2: (1+rho)^2 (1-2u) + 4 rho u^2, s = 5/2
        "gr0": -a5 * cj * r,                                                     # x (1+rho)^2
        "gr1": a5 * cj * (2 * j + 1) * (2 * j + 3) / (4 * (j + 1) * (j + 2)) * 4,  # x rho
        # T = int u (1-u) (1-k^2 u)^(-3/2): c_{j+1} - c_{j+2} = c_{j+1} / (2 (j + 2))
        "t": a3 * c[1 : nterms + 1] / (2 * (j + 2)),
    }
    return {k: np.ascontiguousarray(v[::-1]) for k, v in tab.items()}  # reversed for Horner


_TAB = _series_tables()


def _horner(coeffs_rev: np.ndarray, x: np.ndarray) -> np.ndarray:
    out = np.full_like(x, coeffs_rev[0])
    for cf in coeffs_rev[1:]:
        out *= x
        out += cf
    return out


def _ke(k2: np.ndarray, kc2: np.ndarray):
    """Complete elliptic integrals K, E of modulus k (parameter m = k^2), kc^2 given directly.

    k^2 = 4 rho / beta^2 can round to just above 1 when rho ~ a and z ~ 0 (ellipe would give
    NaN there); E(1 - kc^2) differs from E(1) by O(kc^2 ln kc) ~ eps, so clipping is exact."""
    return ellipkm1(kc2), ellipe(np.minimum(k2, 1.0))


def cel(kc, p, c, s, *, tol: float = 3e-9):
    """Bulirsch's generalized complete elliptic integral (vectorized, p > 0, kc != 0).

    cel(kc, p, c, s) = int_0^{pi/2} (c cos^2 t + s sin^2 t) /
                       ((cos^2 t + p sin^2 t) sqrt(cos^2 t + kc^2 sin^2 t)) dt

    Bulirsch, Numer. Math. 13, 305 (1969); defined once, in :func:`firmware_io.special.cel`
    (numpy only: the controller's exact magnet field needs it too). Stopping when the
    relative AGM gap is below ``tol`` leaves an error ~ tol^2.
    """
    return _cel(kc, p, c, s, tol=tol)


# --------------------------------------------------------------------------- current loop
def loop_scaled(rho, z, gradient, omr=None):
    """Loop of unit radius. Returns the dimensionless integrals scaled so that
    B/(mu0 I) = out / (4 pi a) and gradients = out / (4 pi a^2).

    ``omr`` = 1 - rho may be passed exactly (as (a - rho_phys) / a) by callers that know it."""
    n = rho.shape
    opr = 1.0 + rho
    if omr is None:
        omr = 1.0 - rho
    z2 = z * z
    beta2 = opr * opr + z2
    k2 = 4.0 * rho / beta2
    kc2 = (omr * omr + z2) / beta2
    beta = np.sqrt(beta2)
    inv_b3 = 1.0 / (beta2 * beta)

    bz = np.empty(n)
    br = np.empty(n)
    br_r = np.empty(n)
    if gradient:
        gzz = np.empty(n)
        gzr = np.empty(n)

    on = kc2 < ON_FILAMENT_KC2
    ser = (k2 < K2_SERIES) & ~on
    clo = ~(ser | on)
    half_pi = 0.5 * math.pi

    if np.any(ser):
        x = k2[ser]
        r = rho[ser]
        zz = z[ser]
        ib3 = inv_b3[ser]
        ib5 = ib3 / beta2[ser]
        bz[ser] = 4.0 * ib3 * half_pi * (_horner(_TAB["bz0"], x) + r * _horner(_TAB["bz1"], x))
        s_br = _horner(_TAB["brk"], x)  # Br integral / k^2
        br_r[ser] = 4.0 * zz * ib5 * 4.0 * half_pi * s_br
        br[ser] = br_r[ser] * r
        if gradient:
            gzz[ser] = -12.0 * zz * ib5 * half_pi * (_horner(_TAB["gz0"], x)
                                                     + r * _horner(_TAB["gz1"], x))
            p1 = -x * s_br  # int (1 - 2u) (..)^(-3/2) = - k^2 * s_br
            p2 = (opr[ser] ** 2) * _horner(_TAB["gr0"], x) + r * _horner(_TAB["gr1"], x)
            gzr[ser] = 4.0 * half_pi * (ib3 * p1 - 3.0 * ib5 * p2)

    if np.any(clo):
        x = k2[clo]
        xc = kc2[clo]
        r = rho[clo]
        zz = z[clo]
        om = omr[clo]
        K, E = _ke(x, xc)
        j03 = E / xc
        j13 = (K - E) / x
        ib3 = inv_b3[clo]
        bz[clo] = 4.0 * ib3 * (om * j03 + 2.0 * r * j13)
        i_br = j03 - 2.0 * j13
        br[clo] = 4.0 * zz * ib3 * i_br
        br_r[clo] = br[clo] / r
        if gradient:
            ib5 = ib3 / beta2[clo]
            j05 = (2.0 * (1.0 + xc) * E - xc * K) / (3.0 * xc * xc)
            j15 = ((1.0 - 2.0 * xc) * E + xc * K) / (3.0 * xc * x)
            j25 = (j13 - xc * j15) / x
            gzz[clo] = -12.0 * zz * ib5 * (om * j05 + 2.0 * r * j15)
            om2 = om * om
            p2 = -om2 * j05 + 2.0 * om2 * j15 + 4.0 * r * j25
            gzr[clo] = 4.0 * (-ib3 * i_br - 3.0 * ib5 * p2)

    if np.any(on):
        bz[on] = 0.0
        br[on] = 0.0
        br_r[on] = 0.0
        if gradient:
            gzz[on] = 0.0
            gzr[on] = 0.0
    if not gradient:
        return br, bz
    return br, bz, gzr, gzz, br_r


def loop_rz(a, rho, z, *, gradient: bool = False):
    """Field of a circular filament loop per unit mu0*I.

    Parameters
    ----------
    a : float or ndarray, m
        Loop radius (> 0), loop in the plane z = 0 centred on the axis.
    rho, z : ndarray, m
        Observer cylindrical coordinates (rho >= 0).
    gradient : bool
        Also return the derivatives (see module docs for the 7-tuple).

    Returns
    -------
    (br, bz) in 1/m, or (br, bz, dbr_drho, dbr_dz, dbz_drho, dbz_dz, br_over_rho) with the
    derivatives in 1/m^2. On the filament itself (within ~1e-75 a) every value is 0.
    """
    a = np.asarray(a, dtype=float)
    rho = np.asarray(rho, dtype=float)
    r = rho / a
    omr = (a - rho) / a  # exact near the wire (Sterbenz), unlike 1 - rho/a
    zz = np.asarray(z, dtype=float) / a
    r, zz, omr = np.broadcast_arrays(r, zz, omr)
    res = loop_scaled(np.ascontiguousarray(r, dtype=float), np.ascontiguousarray(zz, dtype=float),
                       gradient, np.ascontiguousarray(omr, dtype=float))
    f1 = 1.0 / (4.0 * math.pi * a)
    if not gradient:
        return res[0] * f1, res[1] * f1
    br, bz, gzr, gzz, br_r = res
    f2 = f1 / a
    dbz_dz = gzz * f2
    dbz_drho = gzr * f2
    br_over_rho = br_r * f2
    dbr_drho = -dbz_dz - br_over_rho
    dbr_dz = dbz_drho  # curl-free off the filament
    return br * f1, bz * f1, dbr_drho, dbr_dz, dbz_drho, dbz_dz, br_over_rho


# --------------------------------------------------------------------------- T(k)
def _t_integral(k2, kc2):
    """T = int_0^{pi/2} sin^2 cos^2 / (1 - k^2 sin^2)^(3/2) dt, free of cancellation."""
    out = np.empty_like(k2)
    ser = k2 < K2_SERIES
    if np.any(ser):
        out[ser] = 0.5 * math.pi * _horner(_TAB["t"], k2[ser])
    clo = ~ser
    if np.any(clo):
        x = k2[clo]
        xc = kc2[clo]
        K, E = _ke(x, xc)
        out[clo] = ((1.0 + xc) * K - 2.0 * E) / (x * x)
    return out


# --------------------------------------------------------------------------- current sheet
def sheet_rz(a, h, rho, z, *, gradient: bool = False):
    """Field of a cylindrical current sheet (ideal finite solenoid) per unit mu0*K.

    The sheet has radius ``a`` (m) and spans z in [-h, h] (m); K is the azimuthal surface
    current density (A/m). A uniformly axially magnetized cylinder of magnetization M has the
    same B everywhere with K = M.

    Returns
    -------
    (br, bz) dimensionless, or the gradient 7-tuple (derivatives in 1/m). On the sheet itself
    (rho == a, |z| < h) bz is the mean of the inside and outside limits, and dbz_drho is
    dbr_dz (the surface-current jump is not included). On the rims (within ~1e-75 a) the
    singular terms are returned as 0.

    Notes
    -----
    Bz: Derby & Olbert, Am. J. Phys. 78, 229 (2010) with Bulirsch's cel. Br is written as
    (4 rho / pi) [T(k-)/beta-^3 - T(k+)/beta+^3], T the cancellation-free integral of
    :func:`_t_integral`, so Br / rho is exact on the axis.
    """
    a = np.asarray(a, dtype=float)
    rho = np.asarray(rho, dtype=float)
    r = rho / a
    omr = (a - rho) / a
    zz = np.asarray(z, dtype=float) / a
    hh = np.asarray(h, dtype=float) / a
    r, zz, hh, omr = (np.ascontiguousarray(x, dtype=float)
                      for x in np.broadcast_arrays(r, zz, hh, omr))
    res = sheet_scaled(r, omr, zz, hh, gradient)
    if not gradient:
        return res
    br, bz, br_r, dbr_dz, dbz_dz = res
    br_over_rho = br_r / a
    dbr_dz = dbr_dz / a
    dbz_dz = dbz_dz / a
    dbr_drho = -dbz_dz - br_over_rho
    dbz_drho = dbr_dz
    return br, bz, dbr_drho, dbr_dz, dbz_drho, dbz_dz, br_over_rho


_SHEET_GL = {n: np.polynomial.legendre.leggauss(n) for n in (4, 6, 8, 12, 16, 24, 32, 48, 64)}


def _sheet_far(r, omr, zz, hh, gradient, mag=False):
    """Unit-radius sheet as a Gauss-Legendre sum of loops over z' (for far points).

    The closed forms subtract the two ends' terms: at distance R that cancels and loses
    ~eps R^3 / (a^2 L) relative (docs/field_winding.md). The loop series have no cancellation; the loop field is analytic in z' except at z' = z +- i|rho - a|, so the node
    count follows from the Bernstein ellipse through that point (target 1e-16)."""
    n = r.shape[0]
    x = (zz + 1j * np.maximum(np.abs(omr), 1e-300)) / hh
    w = x + np.sqrt(x - 1.0 + 0j) * np.sqrt(x + 1.0 + 0j)
    rb = np.abs(w)
    rb = np.maximum(rb, 1.0 / np.maximum(rb, 1e-300))
    rb = np.minimum(0.5 * (1.0 + rb), 30.0)
    need = np.ceil(np.log(1e2 / 1e-16) / (2.0 * np.log(np.maximum(rb, 1.0 + 1e-12))))
    sizes = np.array(sorted(_SHEET_GL))
    nb = sizes[np.minimum(np.searchsorted(sizes, need), len(sizes) - 1)]
    nc = 5 if gradient else 2
    out = [np.zeros(n) for _ in range(2 * nc if mag else nc)]
    for nn in np.unique(nb):
        sel = np.nonzero(nb == nn)[0]
        xk, wk = _SHEET_GL[int(nn)]
        m = sel.size
        zp = (hh[sel][:, None] * xk[None, :]).ravel()
        res = loop_scaled(np.repeat(r[sel], nn), np.repeat(zz[sel], nn) - zp, gradient,
                           np.repeat(omr[sel], nn))
        ww = (hh[sel][:, None] * wk[None, :]).ravel() / (4.0 * math.pi)
        comps = (res[0], res[1], res[4], res[2], res[3]) if gradient else res
        for q, val in enumerate(comps):
            out[q][sel] = (val * ww).reshape(m, nn).sum(axis=1)
            if mag:
                out[nc + q][sel] = np.abs(val * ww).reshape(m, nn).sum(axis=1)
    return tuple(out)


def sheet_scaled(r, omr, zz, hh, gradient, tol=1e-15, mag=False, ends=None):
    """Unit-radius sheet. Returns (br, bz) per mu0 K, or with gradient
    (br, bz, br_over_r, dbr_dz, dbz_dz) in units of the radius.

    Points whose closed-form cancellation error (~4e-16 R^3 / (2 h), unit radius) would exceed
    ``tol`` / 20 and that lie well outside the sheet use the loop sum of :func:`_sheet_far`.

    With ``mag=True`` the tuple is followed by the same number of magnitudes: the sums of the
    absolute values of the terms each output is formed from (the two end terms of the closed
    forms, the loop terms of the far sum). Rounding error <= ~eps x magnitude: callers use it
    to bound the cancellation a posteriori. ``ends`` = ((z + h) / a, (z - h) / a) may be passed
    when the caller can form them without the rounding of z / a +- h / a (points within an ulp
    of an end plane)."""
    big2 = r * r + zz * zz
    far = (big2 > 2.25 * (1.0 + hh * hh)) & (
        4e-16 * big2 * np.sqrt(big2) / (2.0 * hh) > 0.05 * tol)
    if np.any(far):
        res_far = _sheet_far(r[far], omr[far], zz[far], hh[far], gradient, mag)
        near = ~far
        res_near = _sheet_scaled_closed(r[near], omr[near], zz[near], hh[near], gradient, mag,
                                        None if ends is None else (ends[0][near], ends[1][near]))
        out = []
        for f_, n_ in zip(res_far, res_near):
            o = np.empty(r.shape)
            o[far] = f_
            o[near] = n_
            out.append(o)
        return tuple(out)
    return _sheet_scaled_closed(r, omr, zz, hh, gradient, mag, ends)


def _sheet_scaled_closed(r, omr, zz, hh, gradient, mag=False, ends_in=None):
    """Closed forms (Derby-Olbert Bz, T-integral Br, end-loop gradients) of the unit sheet."""
    opr = 1.0 + r
    br_r = np.zeros(r.shape)
    bz = np.zeros(r.shape)
    gamma = omr / opr
    flat = np.abs(gamma) < 1e-150  # on the sheet's cylinder: mean of the two sides
    p = np.where(flat, 1.0, gamma * gamma)
    s_cel = np.where(flat, 1.0, gamma)
    omr2 = omr * omr
    ends = []
    m_bz = np.zeros(r.shape)
    m_brr = np.zeros(r.shape)
    if ends_in is None:
        ends_in = (zz + hh, zz - hh)
    for sign, ze in ((+1.0, ends_in[0]), (-1.0, ends_in[1])):
        # sign=+1: the end at z = -h (seen at z + h) enters with +, the end at +h with -
        ze2 = ze * ze
        beta2 = opr * opr + ze2
        kc2 = (omr2 + ze2) / beta2
        k2 = 4.0 * r / beta2
        beta = np.sqrt(beta2)
        on = kc2 < ON_FILAMENT_KC2
        safe_kc2 = np.where(on, 1.0, kc2)
        t = _t_integral(k2, safe_kc2)
        c_ = cel(np.sqrt(safe_kc2), p, 1.0, s_cel)
        tz = np.where(on, 0.0, ze * c_ / (beta * opr))
        tr = np.where(on, 0.0, t / (beta2 * beta))
        bz += sign * tz
        br_r -= sign * tr
        if mag:
            m_bz += np.abs(tz)
            m_brr += np.abs(tr)
        ends.append(ze)
    bz *= 1.0 / math.pi
    br_r *= 4.0 / math.pi
    br = br_r * r
    if mag:
        m_bz *= 1.0 / math.pi
        m_brr *= 4.0 / math.pi
    if not gradient:
        return (br, bz, m_brr * r, m_bz) if mag else (br, bz)
    # d/dz of a sheet = K [B_loop(z + h) - B_loop(z - h)] (difference of its end loops)
    lp = loop_scaled(r, ends[0], False, omr)
    lm = loop_scaled(r, ends[1], False, omr)
    inv4pi = 1.0 / (4.0 * math.pi)
    out = (br, bz, br_r, (lp[0] - lm[0]) * inv4pi, (lp[1] - lm[1]) * inv4pi)
    if mag:
        out += (m_brr * r, m_bz, m_brr, (np.abs(lp[0]) + np.abs(lm[0])) * inv4pi,
                (np.abs(lp[1]) + np.abs(lm[1])) * inv4pi)
    return out
