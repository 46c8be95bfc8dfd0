"""The finger magnet's field at the sensors: the axisymmetric multipole and the exact cylinder.

:func:`multipole_field` is the dipole plus the l = 3 term of an axially magnetized magnet, with
its analytic Jacobian; :func:`multipole_pose_rows` adds the derivative in the moment's
direction (the pose fit's inner loop). :func:`cylinder_field` is the exact field of a uniformly magnetized cylinder (Derby &
Olbert, Am. J. Phys. 78, 229 (2010), with Bulirsch's cel from :mod:`firmware_io.special`).
Points, positions in m, moments in A m^2, fields in T. Derivations: docs/localization.md.
numpy only (runs on the controller).
"""

from __future__ import annotations

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


_POLY_ALPHA = np.array([-3.0, 7.5, 7.5, -26.25, 30.0])
_POLY_BETA = np.array([15.0, -17.5, -52.5, 78.75, 0.0])
_SCALES = MU0 * np.array([-1.0, -2.0, 2.0, 4.0, 1.0])


def multipole_pose_columns(r: np.ndarray, u: np.ndarray, axes: np.ndarray, c: float, k: float,
                           out: np.ndarray) -> np.ndarray:
    """The multipole's field and its pose Jacobian written into ``out`` (n, 3, >= 5): columns
    0-2 dB/d(position) (T/m), 3-4 dB along the rotations about ``axes`` (e1, e2) (T/rad), for
    the pose fit's inner loop (the derivative along a rotation w of the moment is dB/du (w x
    u); about e1 it moves u along e2 and about e2 along -e1: the directions the fit steps in,
    :func:`.pose.rotated`). r, u, c, k as in :func:`multipole_pose_rows`. Returns B (n, 3) T.

    The five radial functions of :func:`_radial` are each a prefactor (a rho, s a, a, s a /
    rho, s a) times c_i + w (alpha_i + beta_i t), w = k / rho, evaluated together; then, with
    the mu0 factors folded in, B = g0 u + g1 r, dB/dp = r (g3 r + g2 u)^T + u v^T - g1 I with
    v = g2 r + g4 u, and the rotation along e: g0 e - v (r . e).
    """
    rho = np.einsum("ij,ij->i", r, r)
    s = r @ u
    ir = 1.0 / rho
    sq = np.sqrt(ir)
    a = ir * sq * ir
    sa = s * a
    t = s * s * ir
    poly = (k * ir)[:, None] * (_POLY_ALPHA + t[:, None] * _POLY_BETA)
    poly[:, 0] += c
    poly[:, 1:4] -= (1.5 * c, 1.5 * c, -3.75 * c)
    pre = np.stack([ir * sq, sa, a, sa * ir, sa], 1)
    g = pre * poly * _SCALES                  # (n, 5): g0 .. g4
    g0, g1, g2, g3, g4 = (g[:, j:j + 1] for j in range(5))
    b = g0 * u + g1 * r
    v = g2 * r + g4 * u
    w1 = g3 * r + g2 * u
    jp = out[:, :, :3]
    np.multiply(r[:, :, None], w1[:, None, :], out=jp)
    jp += u[None, :, None] * v[:, None, :]
    jp[:, _DIAG, _DIAG] -= g1
    re = r @ axes.T                                         # (n, 2)
    rot = out[:, :, 3:5]
    np.multiply(v[:, :, None], re[:, None, :], out=rot)
    np.subtract(g0[:, :, None] * axes.T[None], rot, out=rot)
    return b
