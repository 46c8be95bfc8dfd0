"""What the multipole misses of a cylinder magnet's field, tabulated once: :class:`CylinderExcess`.

The exact field of the uniformly magnetized cylinder (:func:`.magnet.cylinder_field`) minus the
dipole and l = 3 terms (:func:`.magnet.multipole_field`) is axisymmetric about the moment u and
scales with |m|: c(r) = |m| (g_rho(R, t) rho_hat + g_z(R, t) u), R = |r|, t = the polar angle.
It is tabulated per unit moment on ln R (R_MIN to R_MAX, 0.5 % steps) and t (0.5 degree steps),
times (R / R_MIN)^7 (its l = 5 leading term falls as R^-7: the scaled table is smooth), and
interpolated bilinearly: within 3 uT of the exact difference beyond 11 mm of a 10 x 10 mm
magnet, 20 uT at 9-11 mm (where its field exceeds 0.1 T). Below R_MIN (inside the magnet) the
exact difference is evaluated directly; beyond R_MAX it is below 2 uT and taken as zero. The table's accuracy against the exact
field is a test (tests/test_localization_pose.py). numpy only.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .magnet import cylinder_field, multipole_field

R_STEP = 0.005
"""Relative radial step of the table (ln R), 0.5 %."""
T_STEPS = 360
"""Polar-angle steps of the table over [0, pi]."""


_SLOPE_A, _BASE_A = np.array([-1.0, -1.0, 1.0, 1.0]), np.array([1.0, 1.0, 0.0, 0.0])
_SLOPE_B, _BASE_B = np.array([-1.0, 1.0, -1.0, 1.0]), np.array([1.0, 0.0, 1.0, 0.0])
"""The bilinear weights of a cell's four corners (i, j), (i, j + 1), (i + 1, j), (i + 1,
j + 1): (1 - a)(1 - b), (1 - a) b, a (1 - b), a b as (a s_a + o_a)(b s_b + o_b)."""


@functools.lru_cache(maxsize=8)
def cylinder_excess(radius_m: float, length_m: float, octupole_m2: float) -> "CylinderExcess":
    """The table of one magnet, built once per process (it takes a fraction of a second)."""
    return CylinderExcess(radius_m, length_m, octupole_m2)


class CylinderExcess:
    """The tabulated exact-minus-multipole field of a cylinder magnet (module docstring).

    Parameters
    ----------
    radius_m, length_m : float, m -- the cylinder
    octupole_m2 : float, m^2 -- the multipole's l = 3 ratio the fit uses
    """

    def __init__(self, radius_m: float, length_m: float, octupole_m2: float):
        self.radius, self.length, self.octupole = radius_m, length_m, octupole_m2
        # from just outside the inscribed sphere: every point outside the magnet (entries
        # inside it are never asked for; within ~9 mm of a 10 mm magnet a sensor reads > 0.13 T)
        self.r_min = 1.05 * min(radius_m, 0.5 * length_m)
        self.r_max = 8.0 * max(radius_m, 0.5 * length_m)
        self.n_r = int(math.ceil(math.log(self.r_max / self.r_min) / R_STEP)) + 1
        s = math.log(self.r_min) + R_STEP * np.arange(self.n_r)
        t = np.linspace(0.0, math.pi, T_STEPS + 1)
        rr, tt = np.meshgrid(np.exp(s), t, indexing="ij")
        pts = np.stack([rr * np.sin(tt), np.zeros_like(rr), rr * np.cos(tt)], -1).reshape(-1, 3)
        d = self.exact(pts, np.zeros(3), np.array([0.0, 0.0, 1.0]))
        d = np.nan_to_num(d, nan=0.0, posinf=0.0, neginf=0.0)
        scale = ((rr / self.r_min) ** 7).reshape(-1)
        # components along rho_hat (+x here) and u (+z), scaled
        self.table = np.stack([d[:, 0] * scale, d[:, 2] * scale], -1).reshape(
            self.n_r, T_STEPS + 1, 2)
        # the four corners of a cell as offsets into the flat table (i, j), (i, j + 1),
        # (i + 1, j), (i + 1, j + 1)
        self.flat = self.table.reshape(-1, 2)
        self.corners = np.array([0, 1, T_STEPS + 1, T_STEPS + 2], np.intp)

    def exact(self, points: np.ndarray, position: np.ndarray, u: np.ndarray) -> np.ndarray:
        """(k, 3) T per A m^2: the exact difference by direct evaluation (slow)."""
        vol_m = np.asarray(u, float)
        return (cylinder_field(points, position, vol_m, self.radius, self.length)
                - multipole_field(points, position, vol_m, self.octupole))

    def field(self, points: np.ndarray, position: np.ndarray, u: np.ndarray) -> np.ndarray:
        """(k, 3) T per A m^2 at ``points`` (k, 3) m of a magnet at ``position`` (3,) with unit
        moment u: the table where R_MIN <= R < R_MAX, exact below, zero beyond."""
        r = points - position
        z = r @ u
        rho_v = r - z[:, None] * u
        big = np.einsum("ij,ij->i", r, r)
        rad = np.sqrt(big)
        out = np.zeros_like(r)
        inner = rad < self.r_min
        mid = ~inner & (rad < self.r_max)
        if mid.any():
            rm = rad[mid]
            fs = (np.log(rm) - math.log(self.r_min)) / R_STEP
            ft = np.arccos(np.clip(z[mid] / rm, -1.0, 1.0)) * (T_STEPS / math.pi)
            i = np.minimum(fs.astype(int), self.n_r - 2)
            j = np.minimum(ft.astype(int), T_STEPS - 1)
            a, b = fs - i, ft - j
            # bilinear: the corners (k, 4, 2) weighted (1-a)(1-b), (1-a) b, a (1-b), a b, one
            # gather and one product
            corners = self.flat[(i * (T_STEPS + 1) + j)[:, None] + self.corners]
            w = (a[:, None] * _SLOPE_A + _BASE_A) * (b[:, None] * _SLOPE_B + _BASE_B)
            w *= ((self.r_min / rm) ** 7)[:, None]
            g = np.matmul(w[:, None, :], corners)[:, 0]
            rho = np.sqrt(np.einsum("ij,ij->i", rho_v[mid], rho_v[mid]))
            rhat = rho_v[mid] / np.maximum(rho, 1e-300)[:, None]
            out[mid] = g[:, :1] * rhat + g[:, 1:] * u
        if inner.any():
            out[inner] = self.exact(points[inner], position, u)
        return out
