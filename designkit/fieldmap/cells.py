"""Fitting A's harmonic cells: per layer, the least-squares harmonic potential of every cell
from the coupled model's A on the layer's Chebyshev-Lobatto lattice (T/A, T/(m A); m).

Every row is weighted by 1 / its largest |A| over the box (the error measure); one
pseudo-inverse serves a whole layer, every cell having the same local nodes. The basis:
:mod:`firmware_io.mapfile.harmonics`.
"""

from __future__ import annotations

import numpy as np

from firmware_io import mapfile as mf

from ..support.blas import one_blas_thread
from .plan import lobatto


def fit_layer(lay: dict, values: np.ndarray, row_max: np.ndarray, n: int) -> np.ndarray:
    """Harmonic coefficients (nx * ny, K, nc) float32 of one layer from A on its fit lattice
    (NX, NY, n, 8, nc): per cell the least-squares potential over its n^3 nodes, every row
    weighted by 1 / its largest |A| over the box (the error measure); one pseudo-inverse per
    layer (every cell has the same local nodes)."""
    nx, ny, deg = lay["nx"], lay["ny"], lay["degree"]
    hx, hy = lay["cell_x_m"], lay["cell_y_m"]
    dz = lay["z_hi_m"] - lay["z_lo_m"]
    r = max(hx, hy, dz) / 2
    t = lobatto(n) - 0.5
    s = np.stack(np.meshgrid(t * hx / r, t * hy / r, t * dz / r, indexing="ij"), -1)
    ops = mf.harmonic_rows(deg)  # (8, M, K)
    scale = np.array([r] * 3 + [r * r] * 5) * row_max
    g = np.einsum("mp,rmk->prk", mf.monomials(s.reshape(-1, 3), deg - 1), ops)
    g /= scale[None, :, None]
    with one_blas_thread():  # small: BLAS threads would wait longer than compute
        pinv = np.linalg.pinv(g.reshape(-1, g.shape[2]))  # (K, n^3 * 8)
    nc = values.shape[-1]
    # every cell's n x n x n nodes at once (a view: cells share their face nodes), rows
    # weighted, then one batched product with the layer's pseudo-inverse
    win = np.lib.stride_tricks.sliding_window_view(values, (n, n), axis=(0, 1))
    cells = win[::n - 1, ::n - 1]  # (nx, ny, n_z, 8, nc, n_x, n_y)
    cells = np.moveaxis(cells, (-2, -1), (2, 3))  # (nx, ny, n_x, n_y, n_z, 8, nc)
    rhs = (cells * (1.0 / row_max)[:, None]).reshape(nx * ny, -1, nc)
    with one_blas_thread():
        return np.matmul(pinv, rhs).astype(np.float32)


def fit_layers(layers: list, lattices: list, a_fit: np.ndarray, n: int) -> tuple[dict, np.ndarray]:
    """Every layer's table {name: (nx * ny, K, nc) float32} from A (N, 8, nc) on the layers'
    lattices (:func:`designkit.fieldmap.plan.layer_nodes`) concatenated in layer order, and the
    rows' largest |A| over them (8,), the fit's weights."""
    nc = a_fit.shape[-1]
    row_max = np.maximum(np.abs(a_fit).max(axis=(0, 2)), 1e-300)
    out, start = {}, 0
    for lay, axes in zip(layers, lattices):
        shape = tuple(len(a) for a in axes)
        stop = start + int(np.prod(shape))
        out[lay["name"]] = fit_layer(lay, a_fit[start:stop].reshape(shape + (8, nc)), row_max, n)
        start = stop
    return out, row_max