"""The finger magnet's field at the sensors: the axisymmetric multipole and the exact cylinder.

:func:`multipole_field` is the dipole plus the l = 3 term of an axially magnetized magnet, with
its analytic Jacobian; :func:`multipole_rows` is the same algebra arranged for the fit's inner
loop. :func:`cylinder_field` is the exact field of a uniformly magnetized cylinder (Derby &
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
    r = points_m - position_m
    rho = np.einsum("ij,ij->i", r, r)
    s = r @ u
    c = mag / (4 * math.pi)
    ir = 1.0 / rho
    a = ir * ir * np.sqrt(ir)        # rho^-5/2: every derivative below is a = times a polynomial
    sa = s * a
    if octupole_m2:
        # with t = s^2 / rho (cos^2 of the polar angle) and w = k / rho, k = c q / 2:
        # f_s = a (c rho + k (15 t - 3)), f_rho = s a (-3c/2 + w (15/2 - 35 t / 2)), ...
        k = 0.5 * c * octupole_m2
        t = s * s * ir
        w = k * ir
        fs = a * (c * rho + k * (15.0 * t - 3.0))
        fr = sa * (w * (7.5 - 17.5 * t) - 1.5 * c)
    else:
        fs = c * rho * a
        fr = -1.5 * c * sa
    b = -MU0 * (fs[:, None] * u[None] + 2 * fr[:, None] * r)
    if not jacobian:
        return b
    if octupole_m2:
        fsr = a * (w * (7.5 - 52.5 * t) - 1.5 * c)
        frr = sa * ir * (w * (78.75 * t - 26.25) + 3.75 * c)
        fss = 30.0 * w * sa
    else:
        fsr = -1.5 * c * a
        frr = 3.75 * c * sa * ir
    # 2 fsr (u r^T + r u^T) + 4 frr r r^T + fss u u^T + 2 fr I, as r v1^T + u v2^T + 2 fr I
    # (fewer small-array operations: this runs in every fit iteration)
    v1 = (4 * frr)[:, None] * r + (2 * fsr)[:, None] * u
    v2 = (2 * fsr)[:, None] * r
    if octupole_m2:
        v2 += fss[:, None] * u
    d = r[:, :, None] * v1[:, None, :] + u[None, :, None] * v2[:, None, :]
    d[:, _DIAG, _DIAG] += (2 * fr)[:, None]
    return b, MU0 * d  # d/d(position) = -d/dr


def multipole_rows(r: np.ndarray, u: np.ndarray, c: float, k: float, out: np.ndarray,
                    work: tuple | None = None):
    """The fit's hot path: :func:`multipole_field`'s Jacobian and field at r = points - position
    (n, 3) m, written as out[:, :, :3] = dB/d(position) / mu0 (T/m per mu0) and out[:, :, 3] =
    B / mu0 (T per mu0), out (n, 3, 4); c = |m| / (4 pi), k = c q / 2, u the unit moment;
    ``work``: :func:`multipole_work` (n, u, c), reused between calls. The same algebra as
    :func:`multipole_field` (tested equal), arranged as a few matrix products (the overhead of a
    small numpy call outweighs its arithmetic here)."""
    b3, r5, pq, cm, tv, v, k6 = work if work is not None else multipole_work(len(r), u, c)
    rho = np.einsum("ij,ij->i", r, r)
    s = r @ u
    ir = 1.0 / rho
    a = ir * ir * np.sqrt(ir)
    # the radial functions, each a = rho^-5/2 times (a power of s, 1/rho, rho) times a polynomial
    # c0 c + c1 w + c2 w t in w = k / rho and t = s^2 / rho (see multipole_field), in the order
    # of cm: [4 f_rho rho, 2 f_s rho, -2 f_rho; 2 f_s rho, f_ss, -f_s]
    np.multiply(ir, k, out=tv[:, 1])
    np.multiply(tv[:, 1], s * s * ir, out=tv[:, 2])
    np.multiply(s, ir, out=v[:, 0])
    v[:, 2] = v[:, 4] = s
    v[:, 5] = rho
    x = tv @ k6
    x *= v
    np.multiply(x, a[:, None], out=cm.reshape(-1, 6))
    # row i of out[k] is r_i P_k + u_i Q_k + 2 f_rho [e_i, 0] with P = [4 frr r + 2 fsr u, -2 fr]
    # and Q = [2 fsr r + fss u, -fs]: [P; Q] = cm @ [[r, 0], [u, 0], [0, 0, 0, 1]], then
    # out = [r, u, I] @ [P; Q; 2 f_rho [I, 0]]
    b3[:, 0, :3] = r
    r5[:, :, 0] = r
    np.matmul(cm, b3, out=pq[:, :2])
    np.negative(cm[:, 0, 2], out=pq[:, 2, 0])
    pq[:, 3, 1] = pq[:, 4, 2] = pq[:, 2, 0]
    np.matmul(r5, pq, out=out)
    return out


def multipole_work(n: int, u: np.ndarray, c: float) -> tuple:
    """Buffers and constants of :func:`multipole_rows` for n points, unit moment u and c =
    |m| / (4 pi): b3 (n, 3, 4) = [[r, 0], [u, 0], [0, 0, 0, 1]], r5 (n, 3, 5) = [r, u, I],
    pq (n, 5, 4) (rows 2-4: 2 f_rho [I, 0]), cm (n, 2, 3), tv (n, 3) = [1, w, w t],
    v (n, 6) = [s / rho, 1, s, 1, s, rho], k6 (3, 6) the polynomials' coefficients; r, s, rho,
    w, t are filled in per call."""
    b3 = np.zeros((n, 3, 4))
    b3[:, 1, :3] = u
    b3[:, 2, 3] = 1.0
    r5 = np.zeros((n, 3, 5))
    r5[:, :, 1] = u
    r5[:, :, 2:] = EYE3
    tv = np.zeros((n, 3))
    tv[:, 0] = 1.0
    v = np.ones((n, 6))
    # columns: 4 f_rho rho / (a s / rho), 2 f_s rho / a, -2 f_rho / (a s), 2 f_s rho / a,
    # f_ss / (a s), -f_s / (a rho) as c0 c + c1 w + c2 w t
    k6 = np.array([[15.0 * c, -3.0 * c, 3.0 * c, -3.0 * c, 0.0, -c],
                   [-105.0, 15.0, -15.0, 15.0, 30.0, 3.0],
                   [315.0, -105.0, 35.0, -105.0, 0.0, -15.0]])
    return b3, r5, np.zeros((n, 5, 4)), np.zeros((n, 2, 3)), tv, v, k6


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

