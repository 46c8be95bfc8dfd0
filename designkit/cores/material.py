"""B-H curves of the core material: the 1010 steel table, defined once for every core model.

B-H curve ``"steel1010"``: the "1010 Steel" curve of the FEMM 4.2 material library
(D. Meeker, femm.info; the same table is in MPEL/MotorProto ``Materials/Steel1010.m``), H in
A/m against B in T, extended beyond 318 kA/m with slope mu0; initial mu_r ~ 670, maximum ~ 930,
knee ~ 1.5 T. Two interpolations of the same table: piecewise linear (:func:`steel1010_h`,
the panel model's secant permeability) and a monotone cubic (:func:`steel1010_h_smooth`, C1,
for the rod model's Newton iteration).
"""

from __future__ import annotations

import functools
from typing import Literal

import numpy as np

from ..constants import MU0

BHCurveName = Literal["linear", "steel1010"]
BH_CURVES: tuple[str, ...] = ("linear", "steel1010")

# FEMM 4.2 material library, "1010 Steel" (H in A/m, B in T); last point extends with slope mu0.
STEEL1010_H = np.array([0.0, 238.7, 318.3, 358.1, 437.7, 477.5, 636.6, 795.8, 1114.1, 1273.2,
                        1591.5, 2228.2, 3183.1, 4774.6, 6366.2, 7957.7, 15915.5, 47746.5, 63662.0,
                        79577.5, 159155.0, 318310.0, 1909860.0])
STEEL1010_B = np.array([0.0, 0.2003, 0.3204, 0.40045, 0.50055, 0.5606, 0.7908, 0.9310, 1.1014,
                        1.2016, 1.302, 1.4028, 1.524, 1.626, 1.698, 1.73, 1.87, 2.04, 2.07, 2.095,
                        2.2, 2.4, 4.4])
KNEE_T = 1.5
"""Flux density above which low-carbon steel is past the knee of its B-H curve, T (default of
:attr:`designkit.cores.Core.knee_t`; a design file sets it as ``[core] saturation_t``)."""


def steel1010_h(b: np.ndarray) -> np.ndarray:
    """H(|B|) of the 1010 steel curve, A/m (linear interpolation; slope mu0 beyond the table)."""
    b = np.abs(np.asarray(b, dtype=float))
    h = np.interp(b, STEEL1010_B, STEEL1010_H)
    over = b > STEEL1010_B[-1]
    h[over] = STEEL1010_H[-1] + (b[over] - STEEL1010_B[-1]) / MU0
    return h


def steel1010_mu_r(b: np.ndarray) -> np.ndarray:
    """Secant relative permeability B / (mu0 H) of the 1010 steel curve at |B| (T)."""
    b = np.maximum(np.abs(np.asarray(b, dtype=float)), 1e-3)
    return b / (MU0 * steel1010_h(b))


def _pchip_edge(h0, h1, m0, m1):
    """End slope of a PCHIP: the one-sided three-point estimate, kept shape-preserving."""
    d = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
    if np.sign(d) != np.sign(m0):
        return 0.0
    if np.sign(m0) != np.sign(m1) and abs(d) > 3 * abs(m0):
        return 3 * m0
    return d


@functools.lru_cache(maxsize=1)
def _h_of_b():
    """Knot slopes dH/dB of the monotone cubic (Fritsch-Carlson PCHIP with Fritsch-Butland
    weighted harmonic means, the construction of scipy's PchipInterpolator; written out so
    the optimizer does not import scipy.interpolate, slow to import)."""
    x, y = STEEL1010_B, STEEL1010_H
    h = np.diff(x)
    m = np.diff(y) / h
    d = np.zeros_like(x)
    w1 = 2 * h[1:] + h[:-1]
    w2 = h[1:] + 2 * h[:-1]
    same = m[:-1] * m[1:] > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        d[1:-1] = np.where(same, (w1 + w2) / (w1 / m[:-1] + w2 / m[1:]), 0.0)
    d[0] = _pchip_edge(h[0], h[1], m[0], m[1])
    d[-1] = _pchip_edge(h[-1], h[-2], m[-1], m[-2])
    return d


def steel1010_h_smooth(b_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """H(|B|) (A/m, odd in B) and dH/dB (A/(m T)) of the 1010 steel table, C1 (PCHIP).

    Beyond the table's last point (4.4 T) the slope is 1/mu0 (the table's own end slope).
    """
    b = np.asarray(b_t, dtype=float)
    ab = np.abs(b)
    x, y = STEEL1010_B, STEEL1010_H
    d = _h_of_b()
    top = x[-1]
    k = np.clip(np.searchsorted(x, ab, side="right") - 1, 0, len(x) - 2)
    hk = x[k + 1] - x[k]
    t = (np.minimum(ab, top) - x[k]) / hk
    t2, t3 = t * t, t * t * t
    # cubic Hermite on [x_k, x_k+1] with end values y and slopes d
    hv = ((2 * t3 - 3 * t2 + 1) * y[k] + (t3 - 2 * t2 + t) * hk * d[k]
          + (-2 * t3 + 3 * t2) * y[k + 1] + (t3 - t2) * hk * d[k + 1])
    dv = ((6 * t2 - 6 * t) * (y[k] - y[k + 1]) / hk + (3 * t2 - 4 * t + 1) * d[k]
          + (3 * t2 - 2 * t) * d[k + 1])
    h = np.where(ab <= top, hv, y[-1] + (ab - top) / MU0)
    dh = np.where(ab <= top, dv, 1.0 / MU0)
    return np.sign(b) * h, dh
