"""Trilinear interpolation on the map's 3-D grid of magnet positions (the bias force's
core-to-core part ``F0_RES`` on ``M_X``, ``M_Y``, ``M_Z``, m); linear extrapolation outside."""

from __future__ import annotations

import bisect

import numpy as np


def _cells(axis: np.ndarray, x: np.ndarray):
    """Cell index (n,) and local coordinate t (n,) of ``x`` on a strictly increasing axis;
    outside, the end cell with t < 0 or > 1 (linear extrapolation)."""
    i = np.clip(np.searchsorted(axis, x, side="right") - 1, 0, len(axis) - 2)
    return i, (x - axis[i]) / (axis[i + 1] - axis[i])


def trilinear(grid: tuple, p: np.ndarray) -> np.ndarray:
    """Trilinear interpolation of ``values`` (nx * ny * nz, q) at points (n, 3) -> (n, q)."""
    axes, values, shape = grid
    ny, nz = shape[1], shape[2]
    ix, tx = _cells(axes[0], p[:, 0])
    iy, ty = _cells(axes[1], p[:, 1])
    iz, tz = _cells(axes[2], p[:, 2])
    base = (ix * ny + iy) * nz + iz
    ux, uy, uz = 1.0 - tx, 1.0 - ty, 1.0 - tz
    out = np.zeros((len(p), values.shape[1]), values.dtype)
    for off, w in ((0, ux * uy * uz), (1, ux * uy * tz), (nz, ux * ty * uz),
                   (nz + 1, ux * ty * tz), (ny * nz, tx * uy * uz), (ny * nz + 1, tx * uy * tz),
                   (ny * nz + nz, tx * ty * uz), (ny * nz + nz + 1, tx * ty * tz)):
        corner = np.take(values, base + off, axis=0)
        corner *= w.astype(values.dtype)[:, None]
        out += corner
    return out


def trilinear_one(grid: tuple, q) -> np.ndarray:
    """The same for one point (3 floats) -> (q,), with Python scalars for the index work."""
    axes, values, shape = grid
    xs, ys, zs = grid_lists(grid)
    i = min(max(bisect.bisect_right(xs, q[0]) - 1, 0), len(xs) - 2)
    j = min(max(bisect.bisect_right(ys, q[1]) - 1, 0), len(ys) - 2)
    k = min(max(bisect.bisect_right(zs, q[2]) - 1, 0), len(zs) - 2)
    tx = (q[0] - xs[i]) / (xs[i + 1] - xs[i])
    ty = (q[1] - ys[j]) / (ys[j + 1] - ys[j])
    tz = (q[2] - zs[k]) / (zs[k + 1] - zs[k])
    ux, uy, uz = 1.0 - tx, 1.0 - ty, 1.0 - tz
    w = np.array([ux * uy * uz, ux * uy * tz, ux * ty * uz, ux * ty * tz,
                  tx * uy * uz, tx * uy * tz, tx * ty * uz, tx * ty * tz], dtype=values.dtype)
    block = values.reshape(shape + (-1,))[i:i + 2, j:j + 2, k:k + 2].reshape(8, -1)
    return w @ block


_LISTS: dict = {}


def grid_lists(grid: tuple) -> tuple:
    """The grid's axes as tuples of Python floats (cached per axes object), for
    :func:`trilinear_one`'s scalar index work."""
    key = id(grid[0])
    got = _LISTS.get(key)
    if got is None or got[0] is not grid[0]:
        got = _LISTS[key] = (grid[0], tuple(ax.tolist() for ax in grid[0]))
    return got[1]
