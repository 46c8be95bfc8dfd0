"""Several finger magnets over one array: the cores magnetized by all of them (linear cores).

The cores respond linearly, so the cores' magnetization is the sum of each magnet's own
(:meth:`designkit.cores.coupled.ArraySystem.magnet_solution`, one solve per magnet), and the
zero-current force on magnet i splits into

    F_i = sum_k F_ik,   F_ik = the pull on magnet i of the cores magnetized by magnet k,

F_ii its own F0 (the single-magnet :meth:`CoilArray.bias_force`), F_ik (k != i) the cross term;
point dipoles: F_ik = (m_i . grad) B_k(p_i), B_k the cores' field magnetized by magnet k;
uniformly magnetized cylinders: magnet i's face charges in B_k (:meth:`ArraySystem.load_on`).
The magnets' direct pull on each other is not a core term: :func:`firmware_io.magnet_pair.
pair_forces`. Positions in m, moments in A m^2, sizes (radius, length) in m, forces in N,
torques (about each magnet's centre) in N m. Derivation and accuracy: docs/coupling.md,
"Several magnets".
"""

from __future__ import annotations

import numpy as np

from firmware_io.cylinder_magnet import CylinderMagnet, check_apart

from ..errors import BadInputError
from ..support import validate as v


def magnet_set(positions_m, moments_a_m2, magnet_sizes_m=None):
    """The checked inputs of several magnets: positions (N, 3) m, moments (N, 3) A m^2 and
    sizes, a list of N entries None (point dipole) or (radius, length) m; ``magnet_sizes_m``
    None (all point dipoles), one (radius, length) for all, or (N, 2). Magnets that overlap
    (or two dipoles at one point) are refused, one line naming both and their positions."""
    p, _ = v.points(positions_m, "magnet_positions_m")
    try:
        m = np.asarray(moments_a_m2, dtype=float)
    except (TypeError, ValueError):
        raise BadInputError("moments_a_m2", "array-like of shape (N, 3), A m^2",
                            type(moments_a_m2).__name__) from None
    if m.shape != p.shape or not np.all(np.isfinite(m)):
        raise BadInputError("moments_a_m2", f"finite, shape {p.shape} (one per position), "
                            "A m^2", f"shape {m.shape}")
    sizes = _sizes(magnet_sizes_m, len(p))
    check_apart([CylinderMagnet(pk, mk, *(s or (0.0, 0.0))) for pk, mk, s in zip(p, m, sizes)],
                error=BadInputError)
    return p, m, sizes


def _sizes(magnet_sizes_m, n: int) -> list:
    if magnet_sizes_m is None:
        return [None] * n
    try:
        s = np.asarray(magnet_sizes_m, dtype=float)
    except (TypeError, ValueError):
        s = np.zeros(0)
    if s.shape == (2,):
        s = np.tile(s, (n, 1))
    if s.shape != (n, 2) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise BadInputError("magnet_sizes_m", f"None, (radius, length) or ({n}, 2) positive "
                            "sizes, m", magnet_sizes_m)
    return [(float(r), float(length)) for r, length in s]


def bias_force_matrix(array, positions_m, moments_a_m2, magnet_sizes_m=None):
    """Forces (N, N, 3) N and torques (N, N, 3) N m at zero current: entry [i, k] on magnet i
    (about its centre) from the cores magnetized by magnet k; the diagonal is each magnet's
    own F0, the rest the cross terms (:func:`magnet_set` for the inputs). Zeros without
    coupled cores."""
    p, m, sizes = magnet_set(positions_m, moments_a_m2, magnet_sizes_m)
    n = len(p)
    force, torque = np.zeros((n, n, 3)), np.zeros((n, n, 3))
    system = array.coupled()
    if system is None:
        return force, torque
    x = np.concatenate([system.magnet_solution(p[k][None], m[k], sizes[k])
                        for k in range(n)], axis=1)  # (nu, N): column k magnet k's cores
    for i in range(n):
        force[i], torque[i] = system.load_on(x, np.repeat(p[i][None], n, axis=0), m[i],
                                             sizes[i])
    return force, torque


def magnets_core_field(array, points_m, positions_m, moments_a_m2, magnet_sizes_m=None,
                       gradient: bool = False):
    """B (n, 3) T [, grad B (n, 3, 3) T/m] at ``points_m`` (n, 3) of the cores magnetized by
    all the magnets together (the sum of each magnet's; zeros without coupled cores)."""
    q, _ = v.points(points_m, "points_m")
    p, m, sizes = magnet_set(positions_m, moments_a_m2, magnet_sizes_m)
    system = array.coupled()
    b, g = np.zeros((len(q), 3)), np.zeros((len(q), 3, 3))
    if system is not None:
        x = sum(system.magnet_solution(p[k][None], m[k], sizes[k]) for k in range(len(p)))
        res = system.core_field(q, x, gradient=gradient)
        b, g = (res[0][..., 0], res[1][..., 0]) if gradient else (res[..., 0], g)
    return (b, g) if gradient else b
