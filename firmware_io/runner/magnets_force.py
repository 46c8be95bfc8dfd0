"""The allocation's rows for N magnets: each magnet's three force rows stacked, weighted by its
priority, and the targets with every current-independent force moved across.

The force on magnet i (moment m_i, position p_i) is linear in the currents I (A):

    F_i = F(m_i) G5(p_i) I  +  F0_i  +  sum_{k != i} F0_ik  +  P_i,

F(m_i) G5(p_i) the map's gradient rows contracted with the magnet's own moment (the force law,
:func:`firmware_io.runner.forcelaw.force_law_matrix`), F0_i the pull of the cores it magnetizes
itself (the map's bias force, for the map's moment; scaled by |m_i|^2 / |m_map|^2: F0 is
quadratic in the moment), F0_ik the pull of the cores magnetized by magnet k (not in the map:
not compensated, its size is stated in docs/runner.md, "Several magnets") and P_i the other
magnets' direct pull (:class:`firmware_io.magnet_pair.MagnetPairs`, at run time: it depends on
every position). The allocator (thesis eq. 4.9, :mod:`firmware_io.allocation`) then solves

    min sum_i w_i ||F(m_i) G5(p_i) I - (f_i - F0_i - P_i)||^2   within the bounds,

the stated priority: weighted least squares with one weight per magnet (rows and targets scaled
by sqrt(w_i)); equal weights (the default) treat a newton missed on any finger alike, a larger
weight makes that finger's contact win when the forces cannot all be met. The conditioning of
the stacked rows (unweighted) is reported every step. Forces N, currents A, numpy only.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import BadInputError

CONDITION_CAP = 1e16
"""The condition number reported for stacked rows without full row rank (finite, never Inf)."""


def magnet_weights(weights, n_magnets: int) -> np.ndarray:
    """The per-magnet priority weights (N,) > 0 (None: 1 each), checked."""
    if weights is None:
        return np.ones(n_magnets)
    try:
        w = np.asarray(weights, float).ravel()
    except (TypeError, ValueError):
        w = np.zeros(0)
    if w.shape != (n_magnets,) or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise BadInputError("magnet_weights", f"{n_magnets} finite weights > 0, one per magnet",
                            weights)
    return w


def stacked_rows(force_rows, targets, weights) -> tuple[np.ndarray, np.ndarray]:
    """The weighted stack: (sum_i r_i, n) rows and (sum_i r_i,) targets from each magnet's rows
    (r_i, n) N/A and target (r_i,) N, each scaled by sqrt(w_i)."""
    rows = np.concatenate(force_rows)
    scale = np.repeat(np.sqrt(np.asarray(weights, float)), [len(f) for f in force_rows])
    return rows * scale[:, None], np.concatenate(targets) * scale


def condition_number(rows) -> float:
    """The 2-norm condition number sigma_max / sigma_min of the stacked rows (r, n), r <= n:
    how much a force error in the weakest direction is amplified; :data:`CONDITION_CAP` when
    the rows are rank deficient or zero."""
    sv = np.linalg.svd(np.asarray(rows, float), compute_uv=False)
    if not len(sv) or not math.isfinite(float(sv[0])) or sv[0] <= 0:
        return CONDITION_CAP
    return float(min(sv[0] / max(sv[-1], sv[0] / CONDITION_CAP), CONDITION_CAP))


def bias_scale(moment_a_m2, map_moment_a_m2) -> float:
    """|m|^2 / |m_map|^2: the map's F0 (for its own moment) scaled to a magnet of another
    strength (F0 is quadratic in the moment; the direction stays the map's)."""
    ref = float(np.dot(map_moment_a_m2, map_moment_a_m2))
    return float(np.dot(moment_a_m2, moment_a_m2)) / ref if ref > 0 else 1.0
