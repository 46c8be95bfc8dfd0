"""The moment direction as the fit sees it: two small rotations about axes perpendicular to it.

A unit vector u has two degrees of freedom. The fit moves it by (a, b) rad along its tangent
axes e1, e2 (:func:`tangent_axes`: e1 = normalize(x_min x u) with x_min the array axis least
aligned with u, e2 = u x e1, so (e1, e2, u) is right-handed) and retracts onto the sphere:
u' = normalize(u + a e1 + b e2) (:func:`rotated`). A field that rotates rigidly with the magnet
(an axisymmetric one: c(x; p, R u) = R c(R^T (x - p); u)) changes along a as e2 x c + J_p (e2 x
r) and along b as -(e1 x c + J_p (e1 x r)), with r = x - p and J_p = dc/dp
(:func:`rotation_derivatives`): its orientation derivative costs no evaluation beyond its
position Jacobian. numpy only.
"""

from __future__ import annotations

import math

import numpy as np


def tangent_axes(u: np.ndarray) -> np.ndarray:
    """(2, 3): e1, e2 perpendicular to the unit vector u (module docstring; Python floats:
    this runs at every iteration of the fit)."""
    ux, uy, uz = float(u[0]), float(u[1]), float(u[2])
    ax, ay, az = abs(ux), abs(uy), abs(uz)
    if ax <= ay and ax <= az:
        e1 = (0.0, -uz, uy)          # x_hat x u
    elif ay <= az:
        e1 = (uz, 0.0, -ux)          # y_hat x u
    else:
        e1 = (-uy, ux, 0.0)          # z_hat x u
    k = 1.0 / math.sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2])
    x, y, z = e1[0] * k, e1[1] * k, e1[2] * k
    return np.array([[x, y, z], [uy * z - uz * y, uz * x - ux * z, ux * y - uy * x]])


def rotated(u: np.ndarray, axes: np.ndarray, delta) -> np.ndarray:
    """u moved by delta = (a, b) rad along ``axes`` (e1, e2) and renormalized."""
    v = u + np.asarray(delta[:2], float) @ axes
    return v / math.sqrt(float(v @ v))


def angle_between(u: np.ndarray, v: np.ndarray) -> float:
    """Angle between two unit vectors, rad (stable at small angles)."""
    return 2.0 * math.atan2(float(np.linalg.norm(u - v)), float(np.linalg.norm(u + v)))


def rotation_derivatives(value: np.ndarray, jac_p: np.ndarray, r: np.ndarray,
                         axes: np.ndarray) -> np.ndarray:
    """(n, 3, 2): d value / d(a, b) of a field that rotates rigidly with the moment (module
    docstring); value (n, 3), jac_p = d value / d position (n, 3, 3), r = points - position
    (n, 3), axes (e1, e2). Along rotation k, w_k = (e2, -e1)[k]: w_k x value + J_p (w_k x r),
    with the cross products as the matrices [w_k]x."""
    e1, e2 = axes.tolist()
    skew = np.array([[[0.0, -e2[2], e2[1]], [e2[2], 0.0, -e2[0]], [-e2[1], e2[0], 0.0]],
                     [[0.0, e1[2], -e1[1]], [-e1[2], 0.0, e1[0]], [e1[1], -e1[0], 0.0]]])
    # (n, 3, 2): column k is [w_k]x v for v = value, and J_p [w_k]x r
    turned = np.einsum("kij,nj->nik", skew, value)
    turned += jac_p @ np.einsum("kij,nj->nik", skew, r)
    return turned
