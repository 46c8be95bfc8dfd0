"""Fourier-Bessel integrals of coaxial windings: the quadrature in t = k ro and S(x).

The mutual inductance of coaxial loops, mu0 pi a b int_0^inf J1(k a) J1(k b) exp(-k |z|) dk,
integrated over a winding's radial extent gives the factor
``S(x) = int_0^x t J1(t) dt = int_0^x J0 - x J0(x)`` evaluated at k ro and k ri (Dodd & Deeds
1968; Conway, IEEE Trans. Magn. 46, 75 (2010)). Both the air-core inductance
(:mod:`designkit.model.electrical`) and the fast rod core's applied flux
(:mod:`designkit.cores.rod`) integrate such kernels on the same fixed panels.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.special import itj0y0, j0

PANEL_NODES = 8
"""Default Gauss-Legendre nodes per quarter-period panel."""


@functools.lru_cache(maxsize=8)
def quarter_period_panels(t_max: float, nodes: int = PANEL_NODES):
    """Gauss-Legendre nodes/weights on [0, t_max] in panels of length pi/2 (a quarter period
    of the slowest Bessel oscillation in t = k ro, so every panel sees a smooth integrand).

    Returns (t, w), each shape (n_panels * nodes,)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    n_pan = int(math.ceil(t_max / (0.5 * math.pi)))
    edges = np.linspace(0.0, t_max, n_pan + 1)
    half = 0.5 * np.diff(edges)
    mid = 0.5 * (edges[1:] + edges[:-1])
    t = (mid[:, None] + half[:, None] * x[None, :]).ravel()
    wt = (half[:, None] * w[None, :]).ravel()
    return t, wt


def int_x_j1(x):
    """int_0^x t J1(t) dt = int_0^x J0 - x J0(x) (any shape); a series below x = 0.1 avoids
    the x^3/6 that the difference would lose to cancellation."""
    x = np.asarray(x, dtype=float)
    small = x < 0.1
    xs = np.where(small, x, 0.0)
    x2 = xs * xs
    series = xs ** 3 / 6.0 * (1.0 - x2 * (3.0 / 40.0) * (1.0 - x2 * (5.0 / 126.0)))
    ij0 = itj0y0(np.where(small, 1.0, x))[0]
    big = ij0 - x * j0(x)
    return np.where(small, series, big)
