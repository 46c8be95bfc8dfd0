"""B and grad B at points from least-squares fits of the FEM's B along short lines.

The ``outputs='lines'`` path of :func:`designkit.fem.fem3d.solve` (models with a magnet):
three lines (x, y, z) of length 2 FIT_HALF_WINDOW through each point, sampled by GetDP at
FIT_SAMPLES points; polynomials of degree FIT_DEGREE along each line average the element-wise
jumps of the piecewise-linear B. Lengths in m, B in T, grad B in T/m (G[i, j] = dB_i/dx_j).
"""

from __future__ import annotations

import numpy as np

FIT_HALF_WINDOW = 5e-3
"""Half-length of the three fitting lines through every output point, m."""
FIT_SAMPLES = 33
FIT_DEGREE = 3
"""Degree of the least-squares polynomials along the fitting lines (the slope error of a
lower degree grows as (window / field scale)^2: docs/fem.md)."""


def line_specs(folded, mirror_axes):
    """The fitting lines through the (folded) output points.

    Returns (lines, names): ``lines`` a list of (p0 (3,), p1 (3,), n, file name) for
    :func:`designkit.fem.fem3d.problem_text`, ``names[i][j]`` the file of point i's line along
    axis j. A line along a mirror axis is cut at the symmetry plane (the rest is its image)."""
    lines, names = [], []
    for i, c in enumerate(folded):
        row = []
        for j in range(3):
            e = np.zeros(3)
            e[j] = FIT_HALF_WINDOW
            p0, p1 = c - e, c + e
            if j in mirror_axes:
                p0[j] = max(p0[j], 0.0)  # the rest comes from the mirror image
            name = f"l{i}_{j}.txt"
            lines.append((p0, p1, FIT_SAMPLES - 1, name))
            row.append(name)
        names.append(row)
    return lines, names


def fit_lines(work, names, centres, mirror_axes=()):
    """B (n,3) and G (n,3,3) from least-squares polynomials along the x, y, z lines.

    A line along a mirror axis (x = 0 or y = 0 plane of the symmetric model) that would cross
    the plane is sampled on the modelled side only and completed by the mirror image
    (B_j odd, the other components even in x_j), so the window stays centred."""
    n = len(centres)
    b = np.zeros((n, 3))
    g = np.zeros((n, 3, 3))
    for i in range(n):
        for j in range(3):
            d = np.loadtxt(work / names[i][j], ndmin=2)
            u, vals = d[:, j], d[:, 3:6]
            if j in mirror_axes and centres[i, j] - FIT_HALF_WINDOW < 0:
                pos = u > 1e-12
                mv = vals[pos].copy()
                mv[:, j] *= -1.0
                u = np.concatenate([u, -u[pos]])
                vals = np.vstack([vals, mv])
            sel = np.abs(u - centres[i, j]) <= FIT_HALF_WINDOW * (1 + 1e-9)
            t = (u[sel] - centres[i, j]) / FIT_HALF_WINDOW
            for c in range(3):
                coef = np.polynomial.polynomial.polyfit(t, vals[sel, c], FIT_DEGREE)
                b[i, c] += coef[0] / 3.0
                g[i, c, j] = coef[1] / FIT_HALF_WINDOW
    return b, g
