"""Force of the magnetized iron on the magnet, from B printed on the magnet's end faces.

F = integral over the magnet of (M . grad) B_ind dV with B_ind = B(with cores) - B(cores
replaced by air), both on the same mesh so the magnet's own discretized field cancels; for an
axial, uniform M this is F = M [ int_top B_ind dA - int_bottom B_ind dA ] (exact), evaluated
with a Gauss rule on the two end faces. Forces in N, lengths in m, M in A/m (docs/fem.md).
"""

from __future__ import annotations

import math

import numpy as np


def face_rule(mag, n, symmetry):
    """Gauss points (just inside) on the magnet's top and bottom faces and area weights.

    With symmetry the points cover the modelled part and the weights the whole face (the
    integrand's mirror images carry the same z component).

    Returns top (k, 3) m, bottom (k, 3) m, weights (k,) m^2."""
    xr, wr = np.polynomial.legendre.leggauss(n)
    r = mag.radius * np.sqrt(0.5 * (xr + 1.0))  # area coordinate
    wr = 0.5 * wr * math.pi * mag.radius ** 2
    nphi = 2 * n
    if symmetry == "quarter":
        phi = (np.arange(nphi) + 0.5) * (0.5 * math.pi) / nphi
    elif symmetry == "half":
        phi = (np.arange(nphi) + 0.5) * math.pi / nphi
    else:
        phi = (np.arange(nphi) + 0.5) * 2 * math.pi / nphi
    R, P = np.meshgrid(r, phi, indexing="ij")
    W = np.repeat(wr[:, None], nphi, axis=1) / nphi
    eps = 1e-4 * (mag.z1 - mag.z0)
    x = mag.x + (R * np.cos(P)).ravel()
    y = mag.y + (R * np.sin(P)).ravel()
    z0, z1 = mag.origin_z + mag.z0, mag.origin_z + mag.z1
    top = np.column_stack([x, y, np.full(x.size, z1 - eps)])
    bot = np.column_stack([x, y, np.full(x.size, z0 + eps)])
    return top, bot, W.ravel()


def read_faces(work):
    """B (k, 3) T on the top and bottom face points, as the last run printed them."""
    top = np.loadtxt(work / "face_top.txt", ndmin=2)[:, -3:]
    bot = np.loadtxt(work / "face_bot.txt", ndmin=2)[:, -3:]
    return top, bot


def force_on_magnet(magnetization, weights, with_iron, without_iron, symmetry):
    """(Fx, Fy, Fz) N from the face fields (top, bottom) with and without the iron.

    Components across a symmetry plane are zero by construction."""
    (top, bot), (top0, bot0) = with_iron, without_iron
    w = weights
    fz = magnetization * (np.sum(w * (top[:, 2] - top0[:, 2]))
                          - np.sum(w * (bot[:, 2] - bot0[:, 2])))
    fx = magnetization * (np.sum(w * (top[:, 0] - top0[:, 0]))
                          - np.sum(w * (bot[:, 0] - bot0[:, 0])))
    fy = magnetization * (np.sum(w * (top[:, 1] - top0[:, 1]))
                          - np.sum(w * (bot[:, 1] - bot0[:, 1])))
    if symmetry == "quarter":
        fx = fy = 0.0  # on the symmetry axis by construction
    elif symmetry == "half":
        fy = 0.0
    return np.array([fx, fy, fz])
