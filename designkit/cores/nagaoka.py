"""Nagaoka's coefficient of a cylindrical current sheet and the cylinder's demagnetizing factor.

The field energy of a uniformly magnetized cylinder is (mu0/2) M^2 V (1 - N_m), and it equals
that of its equivalent current sheet (K = M), whose inductance is Nagaoka's k_N mu0 pi R^2 / L;
hence the magnetometric (volume-averaged, chi -> 0) axial demagnetizing factor is
N_m = 1 - k_N, with the exact closed form

    k_N = 4 / (3 pi k') [k'^2 (K - E) / k^2 + E - k],
    k = D / sqrt(D^2 + L^2),  k' = L / sqrt(D^2 + L^2),

(K - E) / k^2 being Bulirsch's cel(k', 1, 0, 1), free of cancellation for long rods.
Chen, Brug & Goldfarb, IEEE Trans. Magn. 27, 3601 (1991) tabulate the same values.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ellipe

from ..constants import MU0
from ..field.kernels import cel


def nagaoka_coefficient(aspect_ratio):
    """Nagaoka's k_N of a current sheet (any shape, float in -> float out), dimensionless.

    ``aspect_ratio``: length / diameter (> 0).
    """
    asp = aspect_ratio
    d2 = 1.0 / (1.0 + asp * asp)  # k^2 with D = 1, L = aspect
    k = np.sqrt(d2)
    kp = asp * k
    return 4.0 / (3.0 * math.pi * kp) * (kp * kp * cel(kp, 1.0, 0.0, 1.0) + ellipe(d2) - k)


def demagnetizing_factor(aspect_ratio: float) -> float:
    """Magnetometric (volume-averaged) axial demagnetizing factor of a cylinder, chi -> 0.

    Parameters
    ----------
    aspect_ratio : float
        Length / diameter (> 0).

    Returns
    -------
    float
        N_m = 1 - k_N in (0, 1) (module docs).
    """
    return 1.0 - float(nagaoka_coefficient(float(aspect_ratio)))


def nagaoka_self(length_m: np.ndarray, radius_m) -> np.ndarray:
    """Q(l) = mu0 pi a^2 l k_N: self-inductance of a sheet of unit turn density (H m^2).

    Vectorized; Q(0) = 0. ``radius_m`` (m) broadcasts against ``length_m`` (m).
    """
    ell, a = np.broadcast_arrays(np.abs(np.asarray(length_m, dtype=float)),
                                 np.asarray(radius_m, dtype=float))
    out = np.zeros(ell.shape)
    pos = ell > 0
    ap = a[pos]
    kn = nagaoka_coefficient(ell[pos] / (2.0 * ap))
    out[pos] = MU0 * math.pi * ap ** 2 * ell[pos] * kn
    return out
