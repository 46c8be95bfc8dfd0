"""The finger magnet's field at the sensors: the axisymmetric multipole and the exact cylinder.

:func:`multipole_field` is the dipole plus the l = 3 term of an axially magnetized magnet, with
its analytic Jacobian; :func:`multipole_pose_rows` adds the derivative in the moment's
direction (the pose fit's inner loop). :func:`cylinder_field` is the exact field of a uniformly magnetized cylinder (Derby &
Olbert, Am. J. Phys. 78, 229 (2010), with Bulirsch's cel from :mod:`firmware_io.special`).
Points, positions in m, moments in A m^2, fields in T. Derivations: docs/localization.md.
numpy only (runs on the controller).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .. import special
from ..constants import MU0

EYE3 = np.eye(3)
_DIAG = np.arange(3)


def _radial(r: np.ndarray, u: np.ndarray, c: float, k: float, derivatives: bool):
    """The potential's radial functions at r (n, 3) for the unit moment u, c = |m| / (4 pi),
    k = c q / 2: f_s, f_rho and, with ``derivatives``, f_srho, f_rhorho, f_ss (see
    :func:`multipole_field`); each is a = rho^-5/2 times a polynomial in t = s^2 / rho and
    w = k / rho."""
    rho = np.einsum("ij,ij->i", r, r)
    s = r @ u
    ir = 1.0 / rho
    a = ir * ir * np.sqrt(ir)
    sa = s * a
    if k:
        t = s * s * ir
        w = k * ir
        fs = a * (c * rho + k * (15.0 * t - 3.0))
        fr = sa * (w * (7.5 - 17.5 * t) - 1.5 * c)
        if not derivatives:
            return fs, fr
        return (fs, fr, a * (w * (7.5 - 52.5 * t) - 1.5 * c),
                sa * ir * (w * (78.75 * t - 26.25) + 3.75 * c), 30.0 * w * sa)
    fs = c * rho * a
    fr = -1.5 * c * sa
    if not derivatives:
        return fs, fr
    return fs, fr, -1.5 * c * a, 3.75 * c * sa * ir, np.zeros_like(s)


def multipole_field(points_m: np.ndarray, position_m: np.ndarray, moment_a_m2: np.ndarray,
                    octupole_m2: float = 0.0, *, jacobian: bool = False):
    """Field of an axisymmetric magnet (dipole + l = 3 term) at points, (n, 3) T.

    Potential phi = C1 cos(t) / r^2 + C1 q P3(cos t) / r^4 with C1 = |m| / (4 pi), q =
    ``octupole_m2``; B = -mu0 grad phi. Written as phi = f(s, rho), s = u.r, rho = r.r, so that
    B = -mu0 (f_s u + 2 f_rho r) and dB/dr = -mu0 (f_ss u u^T + 2 f_srho (u r^T + r u^T)
    + 4 f_rhorho r r^T + 2 f_rho I).

    Parameters
    ----------
    points_m : (n, 3) m; position_m : (3,) m; moment_a_m2 : (3,) A m^2; octupole_m2 : float, m^2
    jacobian : also return dB/d(position_m), (n, 3, 3) T/m (= -dB/dr).
    """
    mag = math.sqrt(float(moment_a_m2 @ moment_a_m2))
    u = moment_a_m2 / mag
    c = mag / (4 * math.pi)
    r = np.asarray(points_m, float) - position_m
    if jacobian:
        b, jp, _ = multipole_pose_rows(r, u, c, 0.5 * c * octupole_m2)
        return b, jp
    fs, fr = _radial(r, u, c, 0.5 * c * octupole_m2, False)
    return -MU0 * (fs[:, None] * u[None] + 2 * fr[:, None] * r)


def cylinder_field(points_m: np.ndarray, position_m: np.ndarray, moment_a_m2: np.ndarray,
                   radius_m: float, length_m: float) -> np.ndarray:
    """Exact field (n, 3) T of a uniformly magnetized cylinder magnet (axis along the moment).

    Derby & Olbert, Am. J. Phys. 78, 229 (2010): the cylinder's B is that of a current sheet
    K = M = |m| / (pi a^2 L) on its side; in units of the radius a, with z0 = L / (2 a),
    z+- = z +- z0, B_rho and B_z are sums of Bulirsch cel integrals. Valid at every point outside
    the magnet (the sensors).

    Parameters
    ----------
    points_m : (n, 3) m; position_m : (3,) m, the magnet's centre; moment_a_m2 : (3,) A m^2;
    radius_m, length_m : float, m
    """
    mag = math.sqrt(float(moment_a_m2 @ moment_a_m2))
    u = moment_a_m2 / mag
    a = float(radius_m)
    pol = MU0 * mag / (math.pi * a * a * float(length_m))
    rel = (np.asarray(points_m, float) - position_m) / a
    z = rel @ u
    perp = rel - z[:, None] * u
    r = np.sqrt(np.einsum("ij,ij->i", perp, perp))
    z0 = 0.5 * float(length_m) / a
    zp, zm = z + z0, z - z0
    dp, dm = 1.0 + r, 1.0 - r
    sq = np.sqrt(np.r_[zp * zp, zm * zm] + np.r_[dp, dp] ** 2)
    k = np.sqrt((np.r_[zp * zp, zm * zm] + np.r_[dm, dm] ** 2)) / sq
    gam = dm / dp
    one = np.ones_like(k)
    # kc = 0 only on the magnet's edge circles, where the field is singular
    cel = special.cel(np.r_[k, k], np.r_[one, np.r_[gam, gam] ** 2], np.r_[one, one],
                      np.r_[-one, gam, gam], tol=1e-12, kc_min=1e-12)
    n = len(z)
    cr, cz = cel[:2 * n] / sq, cel[2 * n:] / sq
    br = pol / math.pi * (cr[:n] - cr[n:])
    bz = pol / (math.pi * dp) * (zp * cz[:n] - zm * cz[n:])
    # B_rho along the unit radial direction; on the axis B_rho = 0 (perp = 0)
    rhat = perp / np.maximum(r, 1e-300)[:, None]
    return br[:, None] * rhat + bz[:, None] * u



def multipole_pose_rows(r: np.ndarray, u: np.ndarray, c: float, k: float):
    """The multipole's field and its derivatives in the magnet's pose, for the pose fit.

    r = points - position (n, 3) m; u the unit moment; c = |m| / (4 pi) (A m^2); k = c q / 2
    (q = ``octupole_m2``). Returns B (n, 3) T, dB/d(position) (n, 3, 3) T/m and dB/du
    (n, 3, 3) T (u as a free 3-vector at fixed c: the derivative along a rotation of the moment
    is dB/du @ (w x u)). From B = -mu0 (f_s u + 2 f_rho r) (:func:`multipole_field`):
    dB/du = -mu0 (f_s I + (f_ss u + 2 f_srho r) r^T), since only s = u . r depends on u.
    """
    fs, fr, fsr, frr, fss = _radial(r, u, c, k, True)
    b = -MU0 * (fs[:, None] * u + 2.0 * fr[:, None] * r)
    # d/d(position) = mu0 (r v1^T + u v2^T + 2 f_rho I), v1 = 4 f_rr r + 2 f_sr u,
    # v2 = 2 f_sr r + f_ss u (multipole_field)
    fsr2 = 2.0 * fsr[:, None]
    v1 = (4.0 * frr)[:, None] * r + fsr2 * u
    v2 = fsr2 * r + fss[:, None] * u
    jp = r[:, :, None] * v1[:, None, :] + u[None, :, None] * v2[:, None, :]
    jp[:, _DIAG, _DIAG] += (2.0 * fr)[:, None]
    jp *= MU0
    # d/du = -mu0 (f_s I + v3 r^T), v3 = f_ss u + 2 f_sr r  (= v2)
    ju = v2[:, :, None] * r[:, None, :]
    ju[:, _DIAG, _DIAG] += fs[:, None]
    ju *= -MU0
    return b, jp, ju


def _pose_coefficients() -> tuple:
    """(M_c, M_k), each (8, 6): the multipole's radial functions as g = Q @ (c M_c + k M_k),
    Q = [x^1.5, x^2.5, x^3.5, x^4.5, x^5.5, s^2 x^3.5, s^2 x^4.5, s^2 x^5.5] (x = 1 / rho), in
    the order (g1 / s, g2, g3 / s, g0, g4 / s, g2) (:func:`multipole_pose_columns`). Each g_j is
    (prefactor) (c_j + w (alpha_j + beta_j t)) of :func:`_radial` times its mu0 factor, w = k x,
    t = s^2 x, prefactors (x^1.5, s x^2.5, x^2.5, s x^3.5, s x^2.5)."""
    alpha = (-3.0, 7.5, 7.5, -26.25, 30.0)
    beta = (15.0, -17.5, -52.5, 78.75, 0.0)
    c_term = (1.0, -1.5, -1.5, 3.75, 0.0)
    mu = MU0 * np.array([-1.0, -2.0, 2.0, 4.0, 1.0])
    # the x power index (0: x^1.5) of each prefactor without its s (odd functions: g / s)
    base = (0, 1, 1, 2, 1)
    m_c, m_k = np.zeros((8, 5)), np.zeros((8, 5))
    for j in range(5):
        e = base[j]
        m_c[e, j] += c_term[j] * mu[j]
        m_k[e + 1, j] += alpha[j] * mu[j]
        m_k[5 + e, j] += beta[j] * mu[j]            # s^2 x^(e + 2), at row 5 + e
    order = [1, 2, 3, 0, 4, 2]
    return m_c[:, order].copy(), m_k[:, order].copy()


_M_C, _M_K = _pose_coefficients()


@functools.lru_cache(maxsize=16)
def _pose_table(c: float, k: float) -> np.ndarray:
    """c M_c + k M_k (:func:`_pose_coefficients`), one per magnet (read-only)."""
    m = c * _M_C + k * _M_K
    m.flags.writeable = False
    return m
_X_POWERS = np.arange(5.0) + 1.5


def multipole_pose_columns(r: np.ndarray, u: np.ndarray, axes: np.ndarray, c: float, k: float,
                           out: np.ndarray) -> np.ndarray:
    """The multipole's field and its pose Jacobian written into ``out`` (n, 3, >= 5): columns
    0-2 dB/d(position) (T/m), 3-4 dB along the rotations about ``axes`` (e1, e2) (T/rad), for
    the pose fit's inner loop (the derivative along a rotation w of the moment is dB/du (w x
    u); about e1 it moves u along e2 and about e2 along -e1: the directions the fit steps in,
    :func:`.pose.rotated`). r, u, c, k as in :func:`multipole_pose_rows`. Returns B (n, 3) T.

    The five radial functions of :func:`_radial`, with the mu0 factors folded in (g0 .. g4),
    are one product of the powers of x = 1 / rho and s = u . r with a constant table
    (:func:`_pose_coefficients`); then B = g0 u + g1 r, dB/dp = r (g3 r + g2 u)^T + u v^T
    - g1 I with v = g2 r + g4 u, and the rotation along e: g0 e - v (r . e).
    """
    n = len(r)
    s = r @ u
    x = 1.0 / (r * r).sum(1)
    q = np.empty((n, 8))
    np.power(x[:, None], _X_POWERS, out=q[:, :5])
    np.multiply(q[:, 2:5], (s * s)[:, None], out=q[:, 5:])
    g = q @ _pose_table(c, k)                    # g1 / s, g2, g3 / s, g0, g4 / s, g2
    g[:, ::2] *= s[:, None]
    # rows b, v, w1: (g1, g2, g3) r + (g0, g4, g2) u
    bvw = g[:, :3, None] * r[:, None, :]
    bvw += g[:, 3:, None] * u
    b, v = bvw[:, 0], bvw[:, 1]
    # dB/dp = [r u] [w1; v] - g1 I: one batched (3 x 2)(2 x 3) product, the diagonal in place
    ru = np.empty((n, 3, 2))
    ru[:, :, 0] = r
    ru[:, :, 1] = u
    jp = ru @ bvw[:, 2:0:-1]
    jp.reshape(n, 9)[:, ::4] -= g[:, :1]
    out[:, :, :3] = jp
    rot = g[:, 3, None, None] * axes.T
    rot -= v[:, :, None] * (r @ axes.T)[:, None, :]
    out[:, :, 3:5] = rot
    return b
