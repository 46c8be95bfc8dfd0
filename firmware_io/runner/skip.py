"""Which coils may be left out near a point: an upper bound of each coil's force per ampere on
a magnet of any orientation.

The force of coil k per ampere on a dipole m is G_k m (G_k its field-gradient tensor, T/(m A)),
so |F_k| <= ||G_k||_F |m| whatever the direction of m (the Frobenius norm bounds the spectral
one). At start-up ||G_k||_F is tabulated on a grid over the map's box; a cell's bound is
``c_max + (c_max - c_min)`` of its eight corners. The runner skips coil k at p (current 0, not
allocated) when bound_k(cell(p)) |m| times its current limit is at most ``skip_force_n``.
studies/bench_runner.py checks the bound along a path; studies/bench_skip.py measures what
skipping saves per step (docs/runner.md: no time; the step is per-call overhead).
"""

from __future__ import annotations

import math

import numpy as np


def gradient_norm(g5: np.ndarray) -> np.ndarray:
    """||G||_F (T/(m A)) of the symmetric, traceless gradient from its five rows g5 (..., 5,
    n) = dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz: shape (..., n)."""
    xx, xy, xz, yy, yz = (g5[..., j, :] for j in range(5))
    zz = -(xx + yy)
    return np.sqrt(xx * xx + yy * yy + zz * zz + 2.0 * (xy * xy + xz * xz + yz * yz))


class CoilSkipBound:
    """Upper bound of each coil's force per ampere and per A m^2 of moment near a point, from a
    grid (N/(A A m^2), i.e. T/(m A)).

    At start-up ||G_k||_F is evaluated at the nodes of a grid of spacing <= ``spacing_m`` over
    the map's box. In a cell, with c_max and c_min the largest and smallest of it at its eight
    corners, the bound is ``c_max + (c_max - c_min)``: a smooth function sampled finely enough
    that it varies within a cell by no more than between the cell's corners stays below it
    (the coils' fields vary on the coil-size scale, ~20 mm; the default spacing is 5 mm). A
    coil is skipped at p when bound_k(cell(p)) |m| I_limit,k <= the stated force; the force
    the skipped coils could add is then at most that force each, for any orientation of m.

    Parameters
    ----------
    fieldmap : object with ``actuation(points (N, 3)) -> (N, 8, n)`` and ``bounds``
    spacing_m : float, m
    """

    def __init__(self, fieldmap, spacing_m: float = 5e-3):
        lo, hi = (np.asarray(b, float) for b in fieldmap.bounds)
        counts = [max(2, int(math.ceil((hi[k] - lo[k]) / spacing_m)) + 1) for k in range(3)]
        axes = [np.linspace(lo[k], hi[k], counts[k]) for k in range(3)]
        g = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        f = gradient_norm(np.asarray(fieldmap.actuation(g), float)[:, 3:8])   # (N, n)
        f = f.reshape(*counts, -1)
        corners = [f[i:i + counts[0] - 1, j:j + counts[1] - 1, k:k + counts[2] - 1]
                   for i in (0, 1) for j in (0, 1) for k in (0, 1)]
        cmax = np.maximum.reduce(corners)
        cmin = np.minimum.reduce(corners)
        self.bound_per_a_m2 = cmax + (cmax - cmin)        # (cx, cy, cz, n)
        self.lo = lo
        self.step = (hi - lo) / (np.asarray(counts) - 1)
        self.cells = [c - 2 for c in counts]

    def at(self, p) -> np.ndarray:
        """(n,) N/(A A m^2): the bound in the cell holding p (the nearest cell outside the
        box)."""
        idx = [min(max(int((p[k] - self.lo[k]) / self.step[k]), 0), self.cells[k])
               for k in range(3)]
        return self.bound_per_a_m2[idx[0], idx[1], idx[2]]

    def keep(self, p, limit_a: np.ndarray, force_n: float, moment_norm_a_m2: float):
        """Indices of the coils whose force at their limit on a moment of
        ``moment_norm_a_m2`` (A m^2) could exceed ``force_n`` (N) near p."""
        return np.flatnonzero(self.at(p) * (moment_norm_a_m2 * limit_a) > force_n)
