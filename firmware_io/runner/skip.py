"""Which coils may be left out near a point: an upper bound of each coil's force per ampere.

At start-up the force per ampere |F_k| (N/A) of every coil is tabulated on a grid over the
map's box; a cell's bound is ``c_max + (c_max - c_min)`` of its eight corners. The runner
skips coil k at p (current 0, not allocated) when bound_k(cell(p)) times its current limit is
at most ``skip_force_n``: the force each skipped coil could have added is below that.
studies/bench_runner.py checks the bound along a path; studies/bench_skip.py measures what
skipping saves per step (docs/runner.md: no time; the step is per-call overhead).
"""

from __future__ import annotations

import math

import numpy as np


class CoilSkipBound:
    """Upper bound of each coil's force per ampere |F_k| (N/A) near a point, from a grid.

    At start-up the force per ampere of every coil is evaluated at the nodes of a grid of
    spacing <= ``spacing_m`` over the map's box. In a cell, with c_max and c_min the largest and
    smallest of |F_k| at its eight corners, the bound is ``c_max + (c_max - c_min)``: a smooth
    |F_k| sampled finely enough that it varies within a cell by no more than between the cell's
    corners stays below it (the coils' fields vary on the coil-size scale, ~20 mm; the default
    spacing is 5 mm). A coil is skipped at p when bound_k(cell(p)) * I_limit,k <= the stated
    force; the force the skipped coils could add is then at most that force each.

    Parameters
    ----------
    fieldmap : object with ``actuation(points (N, 3)) -> (N, 8, n)`` and ``bounds``
    rows, matrix : from :func:`firmware_io.runner.forcelaw.force_law_rows`
    spacing_m : float, m
    """

    def __init__(self, fieldmap, rows, matrix, spacing_m: float = 5e-3):
        lo, hi = (np.asarray(b, float) for b in fieldmap.bounds)
        counts = [max(2, int(math.ceil((hi[k] - lo[k]) / spacing_m)) + 1) for k in range(3)]
        axes = [np.linspace(lo[k], hi[k], counts[k]) for k in range(3)]
        g = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        a = np.asarray(fieldmap.actuation(g), float)[:, rows]          # (N, r, n)
        f = np.linalg.norm(np.einsum("ij,njk->nik", matrix, a), axis=1)  # (N, n)
        f = f.reshape(*counts, -1)
        corners = [f[i:i + counts[0] - 1, j:j + counts[1] - 1, k:k + counts[2] - 1]
                   for i in (0, 1) for j in (0, 1) for k in (0, 1)]
        cmax = np.maximum.reduce(corners)
        cmin = np.minimum.reduce(corners)
        self.bound_n_per_a = cmax + (cmax - cmin)        # (cx, cy, cz, n)
        self.lo = lo
        self.step = (hi - lo) / (np.asarray(counts) - 1)
        self.cells = [c - 2 for c in counts]

    def at(self, p) -> np.ndarray:
        """(n,) N/A: the bound of each coil's force per ampere in the cell holding p (the
        nearest cell outside the box)."""
        idx = [min(max(int((p[k] - self.lo[k]) / self.step[k]), 0), self.cells[k])
               for k in range(3)]
        return self.bound_n_per_a[idx[0], idx[1], idx[2]]

    def keep(self, p, limit_a: np.ndarray, force_n: float) -> np.ndarray:
        """Indices of the coils whose force at their limit could exceed ``force_n`` near p."""
        return np.flatnonzero(self.at(p) * limit_a > force_n)
