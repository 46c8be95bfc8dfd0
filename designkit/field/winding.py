"""Thick winding: uniform azimuthal current density over a rectangular (r, z) section.

Two formulations; each point gets the one whose error bound, evaluated for that point's
position relative to the section (in units of the section's own dimensions), is below ``rtol``
-- the cheaper one when both are:

* near (any point): the current-sheet closed forms integrated over the winding radius with
  graded, mirrored Gauss-Legendre pieces about the nearest singularity, node counts from
  Bernstein-ellipse bounds (no silent node cap);
* far (points outside the section only): a tensor Gauss-Legendre sum over (a, z') of filament
  loops, allowed only where both node counts are <= 64.

Both return, with each value, the sum of the absolute values of its terms: the rounding bound
(``ROUND_ULPS``) that decides when a near value is recomputed with the far formulation.
Gradients need no further integrals (end-loop differences, dBz/drho = dBr/dz - mu0 J_phi,
divergence-free dBr/drho). Supported domain: :data:`RTOL_MIN`, :data:`RATIO_RANGE`,
:data:`ASPECT_RANGE` (verified against mpmath in tests/test_field_winding_random.py).

The derivation, the error bounds, the grading rule and the behaviour at the section's corners
and surface: docs/field_winding.md ("Thick winding").
"""

from __future__ import annotations

import math

import numpy as np

from .harmonic import harmonic_rz
from .kernels import loop_scaled, sheet_scaled

RTOL_MIN = 1e-12
"""Tightest rtol guaranteed (rounding: the kernels' few-ulp errors amplified by at most
~1e3 for L/Ro = 1e-3 near the winding, where the far formulation is not allowed)."""
RTOL_MAX = 1e-2
RATIO_RANGE = (1e-4, 0.999)
"""Supported inner / outer radius."""
ASPECT_RANGE = (1e-3, 1e3)
"""Supported length / outer radius."""

MAX_NODES = 64
MAX_LEVELS = 30
"""Grading depth exactly at a corner with gradient=True (defines the corner value of G)."""
CHUNK = 2048
"""Points per batch (memory: edge points need ~60 pieces x ~24 nodes per temporary)."""
GRADE = 4.0
_BUCKETS = np.array([2, 3, 4, 5, 6, 7, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 56, 64])
_GL = {int(n): np.polynomial.legendre.leggauss(int(n)) for n in _BUCKETS}
RHO_CAP = 30.0
SAFETY_B = 10.0
SAFETY_G = 10.0
ROUND_ULPS = 16.0
ROUND_SAFETY = 4.0
EPS = float(np.finfo(float).eps)
COST_SHEET = 3.5
"""Run time of one sheet evaluation in loop evaluations (measured 2.9 for B, 3.6 with G)."""
_CENTRAL_NODES = 8
HARMONIC_RTOL_MIN = 1e-9
"""Tighter requests (the default 1e-10 of the consumers included) take the exact path, whose
results agree between calls to ~1e-15 whatever the batch; looser ones pay only for the
accuracy asked."""
HARMONIC_MIN_POINTS = 2000
"""Calls with fewer points go the exact way (the expansion's coefficients, computed once per
winding, cost about as much as this many exact points; small calls stay independent of what
was called before)."""
HARMONIC_CHUNK = 16384
"""Most points per call of the expansion (its scratch rows are kept per thread)."""


def _bernstein_rho(lo, hi, s):
    """Usable Bernstein-ellipse parameter for the singularity s (complex) and [lo, hi].

    The Gauss-Legendre error bound holds on any ellipse inside the one through s, times the
    integrand's maximum there; the ellipse half-way in (rho' = (1 + rho_s) / 2) keeps that
    maximum within a small factor (SAFETY) of the integrand's size."""
    x = (2.0 * s - lo - hi) / (hi - lo)
    w = x + np.sqrt(x - 1.0 + 0j) * np.sqrt(x + 1.0 + 0j)
    r = np.abs(w)
    r = np.maximum(r, 1.0 / np.maximum(r, 1e-300))
    # capped: far away the integrand's polynomial growth (a^2, a^4, ...) over a large ellipse,
    # not the distant singularity, limits the accuracy
    return np.minimum(0.5 * (1.0 + r), RHO_CAP)


def _growth(mid, half, rb):
    """Growth of the integrand (~ a^2: a loop's or sheet's far field is its moment pi a^2 I
    over R^3) on the Bernstein ellipse rb of the radius interval mid +- half, relative to its
    size on the interval. Multiplies the Gauss-Legendre error bound."""
    amax = np.abs(mid) + half * 0.5 * (rb + 1.0 / rb)
    return (amax / np.maximum(np.abs(mid), half)) ** 2


def _need(rb, rtol, safety):
    with np.errstate(divide="ignore", over="ignore"):
        return np.ceil(np.log(safety / rtol) / (2.0 * np.log(np.maximum(rb, 1.0 + 1e-15))))


def _bucket(need):
    return _BUCKETS[np.minimum(np.searchsorted(_BUCKETS, need), len(_BUCKETS) - 1)]


def _geometry(ri, ro, h, rho, z):
    # offsets from the point (exact near the sheet through it); points beyond 2 ro use the
    # radius itself (a = rho + delta would lose eps rho / a there)
    anchor = np.where(rho > 2.0 * ro, 0.0, rho)
    d_lo = ri - anchor
    d_hi = ro - anchor
    interior = (d_lo < 0.0) & (d_hi > 0.0)
    in_z = np.abs(z) < h
    tau_rim = np.minimum(np.abs(z - h), np.abs(z + h))
    c = np.clip(rho - anchor, d_lo, d_hi)
    tau = np.where(interior | ~in_z, tau_rim, 0.0)
    dist = np.hypot(c - (rho - anchor), tau)
    width = np.maximum(c - d_lo, d_hi - c)
    return anchor, d_lo, d_hi, c, tau, dist, width


def _trunc_levels(rtol, ri, ro, h):
    """Grading depth below which the innermost piece's share of the integral (<= 4^-L of the
    interval times a log) is under rtol / 1e3 of the result: deeper grading buys nothing for B.
    The integrand (a sheet's field, O(1) near its rim) exceeds the result (~ L / (Ro - Ri) of
    it for a flat winding) by up to (Ro - Ri) / L."""
    amp = max(1.0, (ro - ri) / (2.0 * h))
    return int(math.ceil(math.log(1e3 * amp / rtol) / math.log(GRADE)))


def _pieces(ri, ro, h, rho, z, rtol, safety, gradient):
    """Graded pieces for every point.

    Returns (point index, lo, hi, nodes) per piece (in coordinates a - anchor), the per-point
    anchor and the per-point flag ``trunc`` (grading stopped at MAX_LEVELS although the
    singularity is closer than the depth resolves, or on it)."""
    n = rho.shape[0]
    anchor, d_lo, d_hi, c, tau, dist, width = _geometry(ri, ro, h, rho, z)
    # innermost piece half-width w_L in (dist / 2, 2 dist]: its Bernstein ellipse still
    # reaches rtol = 1e-12 with <= 64 nodes (bisection below is the safety net)
    with np.errstate(divide="ignore"):
        full = np.floor(np.log(width / dist / 2.0) / math.log(GRADE)) + 1
    full = np.where(dist > 0, full, np.inf)
    lt = _trunc_levels(rtol, ri, ro, h)
    if gradient:
        # G must resolve the end loops' nascent delta (width ~ dist) unless dist is below
        # 4^-30 of the innermost piece, where its principal value plus the closed-form jump is
        # exact; exactly at a corner the depth is fixed (MAX_LEVELS) so that the documented
        # corner value does not depend on rtol
        trunc = full > lt + 30
        corner = (dist == 0) & ((c == d_lo) | (c == d_hi)) & (np.abs(z) == h)
        cut = np.where(corner, MAX_LEVELS, lt)
    else:
        trunc = full > lt
        cut = lt
    levels = np.where(trunc, cut, np.where(dist < width / 2.0, full, 0)).astype(int)
    m = int(levels.max(initial=0))
    cols = [d_lo, d_hi, np.where((c > d_lo) & (c < d_hi), c, np.nan)]
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
    pidx, lo, hi = idx[0], lo[idx], hi[idx]
    # truncated points: the piece(s) touching c hold the singularity; they get a fixed rule
    central = trunc[pidx] & (lo <= c[pidx]) & (hi >= c[pidx])
    taup = tau[pidx]
    rhop = rho[pidx]
    ancp = anchor[pidx]
    for _ in range(12):
        # nearest singularities: the rims (a = rho + i tau), the jump at a = rho (for points
        # beside the winding, tau = 0) and the mirror a = -rho + i tau
        rb = np.minimum(_bernstein_rho(lo, hi, (rhop - ancp) + 1j * taup),
                        _bernstein_rho(lo, hi, (-rhop - ancp) + 1j * taup))
        need = _need(rb, rtol, safety * _growth(ancp + 0.5 * (lo + hi), 0.5 * (hi - lo), rb))
        need = np.where(central, _CENTRAL_NODES, need)
        split = need > MAX_NODES
        if not np.any(split):
            break
        # bisect the pieces that need more than the largest rule (no silent cap)
        mid = 0.5 * (lo[split] + hi[split])
        pidx = np.concatenate([pidx[~split], pidx[split], pidx[split]])
        lo_new = np.concatenate([lo[~split], lo[split], mid])
        hi = np.concatenate([hi[~split], mid, hi[split]])
        lo = lo_new
        central = np.concatenate([central[~split], central[split], central[split]])
        taup = tau[pidx]
        rhop = rho[pidx]
        ancp = anchor[pidx]
    nodes = _bucket(need)
    return pidx, lo, hi, nodes, anchor, trunc


def _sheet_loops(a, pr, pz, h, gradient, nzs):
    """Sheets of radius a (one per entry) as Gauss-Legendre sums of nzs[i] loops over z'.

    Same units as the sheet terms of :func:`_near`; returns (values, magnitudes) lists."""
    m = a.size
    nout = 5 if gradient else 2
    vals = [np.zeros(m) for _ in range(nout)]
    mags = [np.zeros(m) for _ in range(nout)]
    for nn in np.unique(nzs):
        sel = np.nonzero(nzs == nn)[0]
        x, w = _GL[int(nn)]
        k = sel.size
        A = np.repeat(a[sel], nn)
        R = np.repeat(pr[sel], nn)
        U = np.repeat(pz[sel], nn) - np.tile(h * x, k)
        res = loop_scaled(R / A, U / A, gradient, (A - R) / A)
        f = np.tile(h * w, k) / (4.0 * math.pi * A)
        terms = [res[0] * f, res[1] * f]
        if gradient:
            terms += [res[4] * f / A, res[2] * f / A, res[3] * f / A]
        for q, t in enumerate(terms):
            t = t.reshape(k, nn)
            vals[q][sel] = t.sum(axis=1)
            mags[q][sel] = np.abs(t).sum(axis=1)
    return vals, mags


def _near(ri, ro, h, rho, z, gradient, rtol, zsum=False):
    """Radius quadrature of sheets. Returns (values, magnitudes, cost) per point.

    ``zsum``: sheets farther from the point than their own height (Bernstein ellipse of the
    z'-interval through z +- i |a - rho| needing <= 32 nodes) are summed as loops over z'
    instead of the closed form, whose two end terms cancel like (distance / L) -- the
    formulation for flat windings (L << Ro - Ri), where the closed forms lose ~(Ro - Ri) / L
    ulps."""
    n = rho.shape[0]
    safety = SAFETY_G if gradient else SAFETY_B
    pidx, lo, hi, nb, anchor, trunc = _pieces(ri, ro, h, rho, z, rtol, safety, gradient)
    nout = 5 if gradient else 2
    acc = np.zeros((nout, n))
    mag = np.zeros((nout, n))
    hz = float(h)
    for nn in np.unique(nb):
        sel = nb == nn
        x, w = _GL[int(nn)]
        half = 0.5 * (hi[sel] - lo[sel])
        mid = 0.5 * (hi[sel] + lo[sel])
        t = (mid[:, None] + half[:, None] * x[None, :]).ravel()
        pr = np.repeat(rho[pidx[sel]], nn)
        pz = np.repeat(z[pidx[sel]], nn)
        anc = np.repeat(anchor[pidx[sel]], nn)
        a = anc + t
        delta = np.where(anc == 0.0, a - pr, t)
        # z +- h formed before scaling: exact for points within an ulp of an end plane
        res = sheet_scaled(pr / a, delta / a, pz / a, hz / a, gradient, rtol, mag=True,
                            ends=((pz + hz) / a, (pz - hz) / a))
        ww = (half[:, None] * w[None, :]).ravel()
        # scale back: B_sheet is per mu0 K already (dimensionless); Br/rho and d/dz carry 1/a
        vals = [res[0], res[1]]
        mags = [res[nout], res[nout + 1]]
        if gradient:
            vals += [res[2] / a, res[3] / a, res[4] / a]
            mags += [res[7] / a, res[8] / a, res[9] / a]
        if zsum:
            rb = _bernstein_rho(-hz, hz, pz + 1j * np.abs(delta))
            nz = _need(rb, rtol, safety)
            lp = nz <= 32
            if np.any(lp):
                lv, lm = _sheet_loops(a[lp], pr[lp], pz[lp], hz, gradient,
                                      _bucket(nz[lp]))
                for q in range(nout):
                    vals[q] = vals[q].copy()
                    mags[q] = mags[q].copy()
                    vals[q][lp] = lv[q]
                    mags[q][lp] = lm[q]
        for q in range(nout):
            s = (vals[q] * ww).reshape(-1, nn).sum(axis=1)
            acc[q] += np.bincount(pidx[sel], weights=s, minlength=n)
            s = np.abs(mags[q] * ww).reshape(-1, nn).sum(axis=1)
            mag[q] += np.bincount(pidx[sel], weights=s, minlength=n)
    cost = COST_SHEET * np.bincount(pidx, weights=nb, minlength=n)
    if gradient and np.any(trunc):
        # the innermost piece integrated the end-loop nascent delta as its principal value:
        # add the one-sided limit of dBr/dz (continuous dBz/drho = dBr/dz - J_phi)
        on_face = trunc & (rho > ri) & (rho < ro) & (np.abs(np.abs(z) - h) < 0.5 * (ro - ri))
        side = np.where(np.abs(z) < h, 0.5, np.where(np.abs(z) > h, -0.5, 0.0))
        acc[3] += np.where(on_face, side, 0.0)
    return acc, mag, cost


def _far_nodes(ri, ro, h, rho, z, rtol, safety):
    dz = np.maximum(np.abs(z) - h, 0.0)
    dr = np.maximum(np.maximum(ri - rho, rho - ro), 0.0)
    outside = (dz > 0) | (dr > 0)
    rb_a = np.minimum(_bernstein_rho(ri, ro, rho + 1j * dz), _bernstein_rho(ri, ro, -rho + 1j * dz))
    rb_z = _bernstein_rho(-h, h, z + 1j * dr)
    na = np.where(outside, _need(rb_a, rtol, safety * _growth(0.5 * (ri + ro), 0.5 * (ro - ri),
                                                               rb_a)), np.inf)
    nz = np.where(outside, _need(rb_z, rtol, safety), np.inf)
    ok = (na <= MAX_NODES) & (nz <= MAX_NODES)
    na = np.where(ok, _bucket(np.where(ok, na, 2)), 0)
    nz = np.where(ok, _bucket(np.where(ok, nz, 2)), 0)
    return ok, na, nz


def _far(ri, ro, h, rho, z, gradient, na, nz):
    """Tensor Gauss-Legendre over (a, z') of filament loops. Returns (values, magnitudes)."""
    n = rho.shape[0]
    nout = 5 if gradient else 2
    out = np.zeros((nout, n))
    mag = np.zeros((nout, n))
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
        res = loop_scaled(pr / aa, (pz - np.tile(ZP, sel.size)) / aa, gradient, (aa - pr) / aa)
        f1 = 1.0 / (4.0 * math.pi * aa)
        ww = np.tile(WW, sel.size)
        vals = [res[0] * f1, res[1] * f1]
        if gradient:
            f2 = f1 / aa
            vals += [res[4] * f2, res[2] * f2, res[3] * f2]  # br/rho, dbr/dz (= dbz/drho), dbz/dz
        for q, val in enumerate(vals):
            t = (val * ww).reshape(sel.size, m)
            out[q][sel] = t.sum(axis=1)
            mag[q][sel] = np.abs(t).sum(axis=1)
    return out, mag


def _round_bound(acc, mag):
    """Relative rounding bound of B (for choosing between formulations)."""
    return np.hypot(mag[0], mag[1]) * ROUND_ULPS * EPS / np.maximum(np.hypot(acc[0], acc[1]),
                                                                    1e-300)


def _round_ok(acc, mag, gradient, rtol):
    """Rounding bound <= rtol / ROUND_SAFETY of the computed |B| (and |G|)?"""
    bound = ROUND_ULPS * EPS
    nb = np.hypot(acc[0], acc[1])
    eb = np.hypot(mag[0], mag[1]) * bound
    ok = eb <= rtol / ROUND_SAFETY * nb
    if gradient:
        # |G| from its independent components (Br/rho, dBr/dz, dBz/dz)
        ng = np.sqrt(acc[2] ** 2 + acc[3] ** 2 + acc[4] ** 2)
        eg = np.sqrt(mag[2] ** 2 + mag[3] ** 2 + mag[4] ** 2) * bound
        ok &= eg <= rtol / ROUND_SAFETY * ng
    return ok


def _exact_rz(ri, ro, h, rho, z, gradient, rtol):
    """Near / far formulations (any point). Returns (2 or 5, n): br, bz[, br_over_rho,
    dbr_dz, dbz_dz] per unit mu0 J."""
    n = rho.shape[0]
    if n > CHUNK:
        # points at edges need up to ~120 graded pieces x 64 nodes each: bound the memory
        return np.concatenate([_exact_rz(ri, ro, h, rho[k:k + CHUNK], z[k:k + CHUNK],
                                         gradient, rtol) for k in range(0, n, CHUNK)], axis=1)
    nout = 5 if gradient else 2
    safety = SAFETY_G if gradient else SAFETY_B
    acc = np.zeros((nout, n))
    far_ok, na, nz = _far_nodes(ri, ro, h, rho, z, rtol, safety)
    # cheap far points first: loop sums with few nodes beat any sheet quadrature (>= 2 sheets)
    use_far = far_ok & (na * nz <= 2 * COST_SHEET * 2)
    done = np.zeros(n, dtype=bool)
    if np.any(use_far):
        f = np.nonzero(use_far)[0]
        v_f, m_f = _far(ri, ro, h, rho[f], z[f], gradient, na[f], nz[f])
        acc[:, f] = v_f
        done[f] = _round_ok(v_f, m_f, gradient, rtol)
    rest = np.nonzero(~done)[0]
    if rest.size:
        v_n, m_n, cost = _near(ri, ro, h, rho[rest], z[rest], gradient, rtol)
        ok_n = _round_ok(v_n, m_n, gradient, rtol)
        redo = ~ok_n & ~far_ok[rest]
        if np.any(redo):
            # the sheets' end terms cancel (flat winding) and the far sums are not allowed:
            # sum the distant sheets as loops over z' (no cancellation)
            k = rest[redo]
            v_z, m_z, _ = _near(ri, ro, h, rho[k], z[k], gradient, rtol, zsum=True)
            ok_z = _round_ok(v_z, m_z, gradient, rtol)
            better = ok_z | (_round_bound(v_z, m_z) < _round_bound(v_n[:, redo], m_n[:, redo]))
            idx = np.nonzero(redo)[0][better]
            v_n[:, idx] = v_z[:, better]
            ok_n[idx] = ok_z[better]
        # far sums where the sheets cancel too much, or where they are cheaper
        alt = far_ok[rest] & ~use_far[rest] & (~ok_n | (na[rest] * nz[rest] < cost))
        keep = ~alt
        acc[:, rest[keep]] = v_n[:, keep]
        if np.any(alt):
            f = rest[alt]
            v_f, m_f = _far(ri, ro, h, rho[f], z[f], gradient, na[f], nz[f])
            ok_f = _round_ok(v_f, m_f, gradient, rtol)
            # where neither bound holds keep the formulation with the smaller bound
            better = ok_f | ~ok_n[alt]
            acc[:, f[better]] = v_f[:, better]
            acc[:, f[~better]] = v_n[:, alt][:, ~better]
    return acc


def winding_rz(ri, ro, h, rho, z, *, gradient=False, rtol=1e-10):
    """Field of a thick winding per unit mu0*J.

    Parameters
    ----------
    ri, ro : float, m
        Inner and outer radius, 0 < ri < ro; accuracy verified for ri / ro in RATIO_RANGE.
    h : float, m
        Half-length; the winding spans z in [-h, h]; verified for 2 h / ro in ASPECT_RANGE.
    rho, z : ndarray, shape (n,), m
        Observer cylindrical coordinates.
    gradient : bool
        Also return the derivatives.
    rtol : float
        Requested relative accuracy, in [RTOL_MIN, RTOL_MAX] (not checked here: this is the raw
        kernel; :func:`designkit.field.winding_field` checks). The error of B is <= rtol |B|,
        that of the gradient <= 10 rtol |G| (away from the section's corners by more than 1e-6
        of its size; see the module notes on conditioning there).

    Returns
    -------
    (br, bz) in m, or (br, bz, dbr_drho, dbr_dz, dbz_drho, dbz_dz, br_over_rho) with the
    derivatives dimensionless (multiply by mu0 J for T and T/m). On the winding's surface the
    mu0 J_phi term of dbz_drho takes half its value.
    """
    rho = np.ascontiguousarray(rho, dtype=float)
    z = np.ascontiguousarray(z, dtype=float)
    n = rho.shape[0]
    nout = 5 if gradient else 2
    acc = np.empty((nout, n))
    rest = np.arange(n)
    if n >= HARMONIC_MIN_POINTS and rtol >= HARMONIC_RTOL_MIN:
        # exterior expansion where its bound holds (cost ~ degree, whatever the section)
        done = np.zeros(n, dtype=bool)
        size = -(-n // -(-n // HARMONIC_CHUNK))  # equal chunks: no small last one
        for k in range(0, n, size):
            d, v = harmonic_rz(ri, ro, h, rho[k:k + size], z[k:k + size], gradient, rtol)
            done[k:k + size] = d
            acc[:, k:k + size] = v
        rest = np.nonzero(~done)[0]
    if rest.size == n:
        acc = _exact_rz(ri, ro, h, rho, z, gradient, rtol)
    elif rest.size:
        acc[:, rest] = _exact_rz(ri, ro, h, rho[rest], z[rest], gradient, rtol)
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
