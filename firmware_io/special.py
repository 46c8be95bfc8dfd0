"""Special functions both sides need, numpy only (the controller cannot import designkit;
designkit's field kernels use these, so each is defined once)."""

from __future__ import annotations

import math

import numpy as np


def cel(kc, p, c, s, *, tol: float = 3e-9, kc_min: float = 0.0) -> np.ndarray:
    """Bulirsch's generalized complete elliptic integral, vectorized over broadcast arrays.

    cel(kc, p, c, s) = int_0^{pi/2} (c cos^2 t + s sin^2 t) /
                       ((cos^2 t + p sin^2 t) sqrt(cos^2 t + kc^2 sin^2 t)) dt

    Bulirsch, Numer. Math. 13, 305 (1969). The iteration converges quadratically; stopping when
    the relative AGM gap is below ``tol`` leaves an error ~ tol^2. Where p <= 0, Bulirsch's
    transformation to p > 0 is applied first (the axial field of a cylinder on its rim
    cylinder rho = a needs p = 0). |kc| is raised to ``kc_min`` (kc = 0 is the logarithmic
    singularity; the caller states where it can occur).
    """
    kc = np.abs(np.asarray(kc, dtype=float))
    if kc_min > 0.0:
        kc = np.maximum(kc, kc_min)
    p = np.asarray(p, dtype=float)
    c = np.asarray(c, dtype=float)
    s = np.asarray(s, dtype=float)
    kc, p, c, s = np.broadcast_arrays(kc, p, c, s)
    neg = p <= 0
    if neg.any():
        g0 = np.where(neg, 1.0 - p, 1.0)  # used only where p <= 0, then >= 1
        pp = np.sqrt(np.where(neg, (kc * kc - p) / g0, p))
        cc = np.where(neg, (c - s) / g0, c)
        ss = np.where(neg, -(1.0 - kc * kc) * (s - c * p) / (g0 * g0 * np.where(neg, pp, 1.0))
                      + cc * pp, s / np.where(neg, 1.0, pp))
    else:
        pp = np.sqrt(p)
        ss = s / pp
        cc = c.copy()
    em = np.ones_like(kc)
    qc = kc.copy()
    kk = qc.copy()
    for _ in range(60):
        g = kk / pp
        cc, ss = cc + ss / pp, 2.0 * (ss + cc * g)
        pp = pp + g
        g = em
        em = em + qc
        if np.all(np.abs(g - qc) <= g * tol):
            break
        qc = 2.0 * np.sqrt(kk)
        kk = em * qc
    return (math.pi / 2) * (ss + cc * em) / (em * (em + pp))
