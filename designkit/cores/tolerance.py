"""The cheapest ring rule of a coupled core's field for a requested relative tolerance.

A core's sources (m = 0 surface currents K, m >= 1 charge densities sigma, A/m) lie on its
meridian contour: three side stretches and two end faces ("segments"). Far enough from a
segment the field at a point is a product rule of n rings per segment (the kernel
interpolated at n Gauss nodes, K or sigma integrated exactly), and each m >= 1 ring a
trapezoid rule of N azimuths. Per point, n and N are the smallest whose error bounds are
<= rtol, relative to the segment's contribution:

* meridian, n nodes: 4 rho^-n / (rho - 1) (Chebyshev interpolation in the Bernstein ellipse
  of parameter rho, half-way to the kernel's singularity; times the face growth
  ((rho + 1 / rho) / 2)^2 and the segment's cancellation sum|K| w / |sum K w|);
* azimuth, N points, ring radius a at (rho, dz) from the point: the kernel is analytic in
  the strip |Im phi| < alpha, cosh alpha = (rho^2 + a^2 + dz^2) / (2 rho a); on the half
  strip it exceeds its smallest real value by at most D = ((cosh alpha + 1) /
  (cosh alpha - cosh(alpha / 2)))^(5/2) (up to 1 / d^5 kernels) and cos(m phi) by
  cosh(m alpha / 2), so the error is <= 2 D cosh(m_max alpha / 2) / (exp(N alpha / 2) - 1).

Points where no rule meets rtol take the model's reference path. Reference: Trefethen,
Approximation Theory and Approximation Practice, ch. 8; Trefethen and Weideman, SIAM Review
56 (2014) 385, the exponentially convergent trapezoidal rule. Derivation: docs/coupling.md.
"""

from __future__ import annotations

import numpy as np

from .quadrature import interp_bound, usable_rho

NODE_SET = (2, 3, 4, 6, 8, 12)
"""Rings per segment tried, cheapest first."""
AZIMUTH_SET = (4, 6, 8, 12, 16, 24, 32)
"""Azimuths per m >= 1 ring tried, cheapest first."""


def segment_singularity(seg, rho, z):
    """Complex kernel singularity of the points (rho, z) (n,) in the parameter of segment
    ``seg`` ((2, 2) (rho, z) ends; a side segment has constant rho, a face constant z), and
    the segment's parameter interval (lo, hi)."""
    (r0, z0), (r1, z1) = seg
    if r0 == r1:  # side: parameter z at rho = r0
        return z + 1j * np.abs(r0 - rho), min(z0, z1), max(z0, z1), False
    return rho + 1j * np.abs(z - z0), min(r0, r1), max(r0, r1), True


def meridian_nodes(segments, cancel, rho, z, rtol):
    """Rings of each segment for each point (nseg, n) int, 0 where no n of
    :data:`NODE_SET` meets ``rtol``, and the largest bound of the chosen rules (n,).

    segments : (nseg, 2, 2) (rho, z) ends, m; cancel : (nseg,) or (nseg, n) cancellation
    factors (>= 1); rho, z : (n,) points, m."""
    cancel = np.asarray(cancel, dtype=float)
    out = np.zeros((len(segments), len(rho)), dtype=int)
    worst = np.zeros(len(rho))
    for k, seg in enumerate(segments):
        s, lo, hi, face = segment_singularity(seg, rho, z)
        rb = usable_rho(lo, hi, s)
        factor = ((0.5 * (rb + 1.0 / rb)) ** 2 if face else 1.0) * cancel[k]
        todo = np.ones(len(rho), dtype=bool)
        for n in NODE_SET:
            bound = interp_bound(rb, n) * factor
            sel = todo & (bound <= rtol)
            out[k, sel] = n
            worst[sel] = np.maximum(worst[sel], bound[sel])
            todo &= ~sel
    return out, worst


def azimuth_count(ring_r, ring_z, rho, z, m_max, rtol):
    """Azimuths per m >= 1 ring (n,) int, 0 where none of :data:`AZIMUTH_SET` meets ``rtol``,
    and the bound of the chosen rule (n,).

    ring_r, ring_z : the rings (m), radius > 0; rho, z : (n,) points, m."""
    a = np.asarray(ring_r, dtype=float)[None, :]
    d2 = rho[:, None] ** 2 + a * a + (z[:, None] - np.asarray(ring_z)[None, :]) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        ch = np.where(rho[:, None] > 0, d2 / (2.0 * rho[:, None] * a), np.inf)
    ch = np.min(ch, axis=1)  # the nearest ring limits the strip
    alpha = np.arccosh(np.maximum(ch, 1.0))
    half = 0.5 * alpha
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        grow = ((ch + 1.0) / np.maximum(ch - np.cosh(half), 1e-300)) ** 2.5
        grow = np.where(np.isfinite(ch), grow, 1.0) * np.cosh(np.minimum(m_max * half, 700.0))
    out = np.zeros(len(rho), dtype=int)
    worst = np.zeros(len(rho))
    todo = np.ones(len(rho), dtype=bool)
    for n_az in AZIMUTH_SET:
        if n_az <= 2 * m_max:
            continue  # cos(m phi) K: the rule must resolve the modes themselves
        with np.errstate(over="ignore"):
            bound = np.where(np.isfinite(alpha), 2.0 * grow / np.expm1(n_az * half), 0.0)
        sel = todo & (bound <= rtol) & (alpha > 0)
        out[sel] = n_az
        worst[sel] = bound[sel]
        todo &= ~sel
    return out, worst


def segment_cancellation(values, widths, moments, groups, cap=1e4):
    """Cancellation factor sum |v| w / |sum v w| (>= 1, capped) of each segment for every
    column, (nseg, k): panel values ``values`` (npanel, k), the panels' ``widths`` (npanel,)
    and, for faces, dipole ``moments`` (npanel,) (the larger factor is kept); ``groups``: list
    of (panel indices, is_face) per segment."""
    out = np.ones((len(groups), values.shape[1]))
    for g, (idx, face) in enumerate(groups):
        v = values[idx]
        for w in ((widths[idx], moments[idx]) if face else (widths[idx],)):
            mag = np.abs(v).T @ w
            tot = np.abs(v.T @ w)
            with np.errstate(divide="ignore", invalid="ignore"):
                f = np.where(tot > 0, np.minimum(mag / tot, cap), cap)
            out[g] = np.maximum(out[g], f)
    return out
