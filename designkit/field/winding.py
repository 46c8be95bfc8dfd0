"""Thick winding: the current-sheet field integrated over the winding radius.

B(rho, z) = mu0 J int_{ri}^{ro} B_sheet(a; rho, z) da, with J the uniform azimuthal current
density. The integrand is analytic in a except near a = rho: there it jumps (inside the
winding's z-range) and it has complex singularities at a = rho +- i tau, tau the distance to the
nearer end plane (the end rims). The interval is cut at a = rho and graded geometrically and
*symmetrically* about it, down to a few tau: mirrored Gauss-Legendre pieces make the odd
(principal-value) part of the end-loop integrand cancel on the end faces. Every piece gets
the fewest Gauss-Legendre nodes that its Bernstein ellipse (through the nearest singularity)
promises for the requested ``rtol``; far points need 2-4 nodes in all.

The integration variable is the offset delta = a - rho, so kernels receive 1 - rho/a =
delta / a exactly, which keeps points within 1e-15 of the sheet exact.

Gradients need no further integrals:
* d/dz of each sheet is K times the difference of its two end loops;
* dBz/drho = dBr/dz - mu0 J_phi (the J term only inside the winding);
* dBr/drho = -dBz/dz - Br/rho (divergence-free), Br/rho taken from the sheet's own Br/rho.
"""

from __future__ import annotations

import math

import numpy as np

from .kernels import _loop_scaled, _sheet_scaled

MAX_LEVELS = 30
CHUNK = 2048
"""Points per batch (memory: worst case ~2048 x 60 pieces x 64 nodes per temporary)."""
GRADE = 4.0
_BUCKETS = np.array([2, 3, 4, 5, 6, 7, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56, 64])
_GL = {int(n): np.polynomial.legendre.leggauss(int(n)) for n in _BUCKETS}
RHO_CAP = 30.0
# Calibrated against mpmath references (designkit.field.reference.winding_textbook) on 70 points,
# 40 of them 1e-5..1e-2 m from the winding's faces, edges and corners (inside and outside), for
# rtol = 1e-4..1e-12: worst achieved error / rtol = 0.057 (B) and 0.092 (G), i.e. rtol is met
# with a margin of ~10 (studies/stress_field.py re-checks this on every run).
SAFETY_B = 10.0
SAFETY_G = 10.0


def _bernstein_rho(lo, hi, s):
    """Usable Bernstein-ellipse parameter for the singularity s (complex) and [lo, hi].

    The Gauss-Legendre error bound holds on any ellipse inside the one through s, times the
    integrand's maximum there; the ellipse half-way in (rho' = (1 + rho_s) / 2) keeps that
    maximum within a small factor of the integrand's size."""
    x = (2.0 * s - lo - hi) / (hi - lo)
    w = x + np.sqrt(x - 1.0 + 0j) * np.sqrt(x + 1.0 + 0j)
    r = np.abs(w)
    r = np.maximum(r, 1.0 / np.maximum(r, 1e-300))
    # capped: far away the integrand's polynomial growth (a^2, a^4, ...) over a large ellipse,
    # not the distant singularity, limits the accuracy
    return np.minimum(0.5 * (1.0 + r), RHO_CAP)


def _pieces(ri, ro, h, rho, z):
    """Graded pieces (point index, delta_lo, delta_hi, tau_eff) for every point."""
    n = rho.shape[0]
    d_lo = ri - rho
    d_hi = ro - rho
    interior = (d_lo < 0.0) & (d_hi > 0.0)
    in_z = np.abs(z) < h
    tau_rim = np.minimum(np.abs(z - h), np.abs(z + h))
    # centre of grading (offset coordinates) and the distance of the nearest singularity to it
    c = np.clip(0.0, d_lo, d_hi)
    tau = np.where(interior | ~in_z, tau_rim, 0.0)
    dist = np.hypot(c, tau)
    width = np.maximum(c - d_lo, d_hi - c)
    levels = np.zeros(n, dtype=int)
    ok = dist < width / 2.0
    with np.errstate(divide="ignore"):
        lv = np.floor(np.log(width / np.maximum(dist, 1e-300) / 2.0) / math.log(GRADE)) + 1
    levels[ok] = np.minimum(lv[ok], MAX_LEVELS).astype(int)
    m = int(levels.max(initial=0))
    cols = [d_lo, d_hi, np.where(interior, c, np.nan)]
    for k in range(1, m + 1):
        w = width * GRADE ** (-k)
        use = levels >= k
        for sgn in (-1.0, 1.0):
            b = c + sgn * w
            valid = use & (b > d_lo) & (b < d_hi)
            cols.append(np.where(valid, b, np.nan))
    bp = np.sort(np.stack(cols, axis=1), axis=1)  # NaNs sort last
    lo = bp[:, :-1]
    hi = bp[:, 1:]
    good = np.isfinite(lo) & np.isfinite(hi) & (hi > lo)
    idx = np.nonzero(good)
    return idx[0], lo[idx], hi[idx], tau[idx[0]], rho[idx[0]]


def winding_rz(ri, ro, h, rho, z, *, gradient=False, rtol=1e-10):
    """Field of a thick winding per unit mu0*J.

    Parameters
    ----------
    ri, ro : float, m
        Inner and outer radius, 0 < ri < ro.
    h : float, m
        Half-length; the winding spans z in [-h, h].
    rho, z : ndarray, shape (n,), m
        Observer cylindrical coordinates.
    gradient : bool
        Also return the derivatives.
    rtol : float
        Requested relative accuracy of the quadrature.

    Returns
    -------
    (br, bz) in m, or (br, bz, dbr_drho, dbr_dz, dbz_drho, dbz_dz, br_over_rho) with the
    derivatives dimensionless (multiply by mu0 J for T and T/m). On the winding's surface the
    mu0 J_phi term of dbz_drho takes half its value.
    """
    rho = np.ascontiguousarray(rho, dtype=float)
    z = np.ascontiguousarray(z, dtype=float)
    n = rho.shape[0]
    if n > CHUNK:
        # points at edges need up to ~60 graded pieces x 64 nodes each: bound the memory
        parts = [winding_rz(ri, ro, h, rho[k:k + CHUNK], z[k:k + CHUNK], gradient=gradient,
                            rtol=rtol) for k in range(0, n, CHUNK)]
        return tuple(np.concatenate(q) for q in zip(*parts))
    # The sheet form subtracts the two end terms: far away that loses eps * R^3 / (ri^2 L).
    # There, a 2-D Gauss-Legendre sum of loops (cancellation-free series) is used instead.
    r3 = (rho * rho + z * z) ** 1.5
    far = 4e-16 * r3 / (ri * ri * 2.0 * h) > 0.05 * rtol
    if np.any(far):
        out = [np.empty(n) for _ in range(7 if gradient else 2)]
        res_far = _winding_loops(ri, ro, h, rho[far], z[far], gradient, rtol)
        near = ~far
        res_near = (winding_rz(ri, ro, h, rho[near], z[near], gradient=gradient, rtol=rtol)
                    if np.any(near) else [np.empty(0)] * len(out))
        for o, f_, n_ in zip(out, res_far, res_near):
            o[far] = f_
            o[near] = n_
        return tuple(out)
    pidx, lo, hi, tau, prho = _pieces(ri, ro, h, rho, z)
    # nearest singularities in offset coordinates: the rims (i tau) and their mirror -2 rho
    rb = np.minimum(_bernstein_rho(lo, hi, 1j * tau), _bernstein_rho(lo, hi, -2.0 * prho + 1j * tau))
    safety = SAFETY_G if gradient else SAFETY_B
    with np.errstate(divide="ignore"):
        need = np.ceil(np.log(safety / rtol) / (2.0 * np.log(np.maximum(rb, 1.0 + 1e-12))))
    nb = _BUCKETS[np.minimum(np.searchsorted(_BUCKETS, need), len(_BUCKETS) - 1)]

    nout = 5 if gradient else 2
    acc = np.zeros((nout, n))
    hz = np.asarray(h, dtype=float)
    for nn in np.unique(nb):
        sel = nb == nn
        x, w = _GL[int(nn)]
        half = 0.5 * (hi[sel] - lo[sel])
        mid = 0.5 * (hi[sel] + lo[sel])
        delta = (mid[:, None] + half[:, None] * x[None, :]).ravel()
        pr = np.repeat(prho[sel], nn)
        pz = np.repeat(z[pidx[sel]], nn)
        a = pr + delta
        r_s = pr / a
        omr_s = delta / a
        z_s = pz / a
        h_s = hz / a
        res = _sheet_scaled(r_s, omr_s, z_s, h_s, gradient, rtol)
        ww = (half[:, None] * w[None, :]).ravel()
        # scale back: B_sheet is per mu0 K already (dimensionless); Br/rho and d/dz carry 1/a
        vals = [res[0], res[1]]
        if gradient:
            vals += [res[2] / a, res[3] / a, res[4] / a]
        for q, val in enumerate(vals):
            s = (val * ww).reshape(-1, nn).sum(axis=1)
            acc[q] += np.bincount(pidx[sel], weights=s, minlength=n)
    br, bz = acc[0], acc[1]
    if not gradient:
        return br, bz
    br_over_rho, dbr_dz, dbz_dz = acc[2], acc[3], acc[4]
    inside = ((rho > ri) & (rho < ro) & (np.abs(z) < h)).astype(float)
    surface = (((rho == ri) | (rho == ro)) & (np.abs(z) <= h)) | (
        (rho >= ri) & (rho <= ro) & (np.abs(z) == h))
    jphi = np.where(surface, 0.5, inside)
    dbr_drho = -dbz_dz - br_over_rho
    dbz_drho = dbr_dz - jphi
    return br, bz, dbr_drho, dbr_dz, dbz_drho, dbz_dz, br_over_rho


def _winding_loops(ri, ro, h, rho, z, gradient, rtol):
    """Far points: tensor Gauss-Legendre over (a, z') of filament loops."""
    n = rho.shape[0]
    dz = np.maximum(np.abs(z) - h, 0.0)
    dr = np.maximum(np.maximum(ri - rho, rho - ro), 0.0)
    rb_a = np.minimum(_bernstein_rho(ri, ro, rho + 1j * dz), _bernstein_rho(ri, ro, -rho + 1j * dz))
    rb_z = _bernstein_rho(-h, h, z + 1j * np.maximum(dr, 1e-300))
    safety = SAFETY_G if gradient else SAFETY_B
    out = [np.zeros(n) for _ in range(5 if gradient else 2)]
    na = np.ceil(np.log(safety / rtol) / (2.0 * np.log(np.maximum(rb_a, 1.0 + 1e-12))))
    nz = np.ceil(np.log(safety / rtol) / (2.0 * np.log(np.maximum(rb_z, 1.0 + 1e-12))))
    na = _BUCKETS[np.minimum(np.searchsorted(_BUCKETS, na), len(_BUCKETS) - 1)]
    nz = _BUCKETS[np.minimum(np.searchsorted(_BUCKETS, nz), len(_BUCKETS) - 1)]
    key = na * 1000 + nz
    for kk in np.unique(key):
        sel = np.nonzero(key == kk)[0]
        ka, kz = int(kk // 1000), int(kk % 1000)
        xa, wa = _GL[ka]
        xz, wz = _GL[kz]
        a = 0.5 * (ro + ri) + 0.5 * (ro - ri) * xa
        zp = h * xz
        A, ZP = np.meshgrid(a, zp, indexing="ij")
        WW = (0.5 * (ro - ri) * wa)[:, None] * (h * wz)[None, :]
        A = A.ravel()
        ZP = ZP.ravel()
        WW = WW.ravel()
        m = A.size
        pr = np.repeat(rho[sel], m)
        pz = np.repeat(z[sel], m)
        aa = np.tile(A, sel.size)
        r_s = pr / aa
        res = _loop_scaled(r_s, (pz - np.tile(ZP, sel.size)) / aa, gradient, (aa - pr) / aa)
        f1 = 1.0 / (4.0 * math.pi * aa)
        ww = np.tile(WW, sel.size)
        vals = [res[0] * f1, res[1] * f1]
        if gradient:
            f2 = f1 / aa
            vals += [res[4] * f2, res[2] * f2, res[3] * f2]  # br/rho, dbr/dz (= dbz/drho), dbz/dz
        for q, val in enumerate(vals):
            out[q][sel] = (val * ww).reshape(sel.size, m).sum(axis=1)
    if not gradient:
        return out[0], out[1]
    br, bz, br_over_rho, dbr_dz, dbz_dz = out
    return br, bz, -dbz_dz - br_over_rho, dbr_dz, dbr_dz, dbz_dz, br_over_rho
