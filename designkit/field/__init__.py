"""Magnetic fields of the sources in an EHI: loops, thick windings, magnetized cylinders, dipoles.

All functions take SI inputs and points of shape (3,) or (n, 3) in metres (source at the origin,
axis +z), and return B of shape (n, 3) in tesla, or ``(B, G)`` with ``G[:, i, j] = dB_i/dx_j`` in
T/m when ``gradient=True`` (shapes (3,) and (3, 3) for a single point).

Accuracy: ~1e-15 relative for loops and sheets everywhere (no cancellation on the axis, in the
far field or near the wire); thick windings to the requested ``rtol``. See
:mod:`designkit.field.kernels` and :mod:`designkit.field.winding` for the formulations.

Singular points (documented values, never NaN/Inf):
* on a filament loop's wire (closer than ~1e-75 radii): B = 0 and G = 0;
* on a current sheet's / magnetized cylinder's rim: the rim's singular terms are 0; on its
  side surface Bz is the mean of the inside and outside limits;
* a point dipole at its own position: B = 0 and G = 0.
Thick windings have no singular points (B is continuous, G is finite; on the winding's surface
the mu0 J term of dBz/drho takes half its value).
"""

from __future__ import annotations

import math

import numpy as np

from ..constants import MU0
from ..errors import BadInputError
from ..support import validate as v
from .kernels import loop_rz, sheet_rz
from .winding import ASPECT_RANGE, RATIO_RANGE, RTOL_MAX, RTOL_MIN, winding_rz

__all__ = [
    "loop_field",
    "winding_field",
    "magnetized_cylinder_field",
    "dipole_field",
    "cylindrical_to_cartesian",
    "MU0",
]


def _cyl(points):
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    rho = np.hypot(x, y)
    c = np.divide(x, rho, out=np.ones_like(x), where=rho > 0)
    s = np.divide(y, rho, out=np.zeros_like(y), where=rho > 0)
    tiny = np.flatnonzero(rho < 1e-290)
    if tiny.size:
        # subnormal x, y: hypot rounds (e.g. hypot(5e-324, 5e-324) = 5e-324) and then
        # c^2 + s^2 != 1; the direction is taken from the rescaled coordinates instead
        xs, ys = x[tiny] * 2.0**600, y[tiny] * 2.0**600
        rs = np.hypot(xs, ys)
        with np.errstate(invalid="ignore", divide="ignore"):
            c[tiny] = np.where(rs > 0, xs / rs, 1.0)
            s[tiny] = np.where(rs > 0, ys / rs, 0.0)
    return rho, z, c, s


def cylindrical_to_cartesian(c, s, scale, res, gradient):
    """Assemble Cartesian B (n, 3) [and G (n, 3, 3)] from an axisymmetric kernel's output.

    ``res`` is (br, bz) or the 7-tuple (br, bz, dbr_drho, dbr_dz, dbz_drho, dbz_dz, br_over_rho);
    every entry is multiplied by ``scale`` (e.g. mu0 I).
    """
    br, bz = res[0], res[1]
    n = br.shape[0]
    b = np.empty((n, 3))
    b[:, 0] = scale * br * c
    b[:, 1] = scale * br * s
    b[:, 2] = scale * bz
    if not gradient:
        return b
    _, _, dbr_dr, dbr_dz, dbz_dr, dbz_dz, br_r = (scale * q for q in res)
    g = np.empty((n, 3, 3))
    cc, ss, cs = c * c, s * s, c * s
    g[:, 0, 0] = dbr_dr * cc + br_r * ss
    g[:, 1, 1] = dbr_dr * ss + br_r * cc
    g[:, 0, 1] = g[:, 1, 0] = (dbr_dr - br_r) * cs
    g[:, 0, 2] = dbr_dz * c
    g[:, 1, 2] = dbr_dz * s
    g[:, 2, 0] = dbz_dr * c
    g[:, 2, 1] = dbz_dr * s
    g[:, 2, 2] = dbz_dz
    return b, g


def _finish(out, single, gradient):
    if gradient:
        b, g = out
        return (b[0], g[0]) if single else (b, g)
    return out[0] if single else out


def loop_field(points, radius, current, *, gradient=False):
    """Circular filament loop in the plane z = 0, centred at the origin.

    Parameters
    ----------
    points : array-like, shape (3,) or (n, 3), m
    radius : float, m
        Loop radius, > 0.
    current : float, A
        Counter-clockwise seen from +z when positive.
    gradient : bool
        Also return G[:, i, j] = dB_i/dx_j, T/m.

    Returns
    -------
    B : ndarray, shape (n, 3), T [, G : ndarray, shape (n, 3, 3), T/m]
        On the wire itself (closer than ~1e-75 radii) B = 0 and G = 0.
    """
    p, single = v.points(points)
    a = v.positive("radius", radius, "m")
    i = v.finite("current", current, "A")
    rho, z, c, s = _cyl(p)
    res = loop_rz(a, rho, z, gradient=gradient)
    return _finish(cylindrical_to_cartesian(c, s, MU0 * i, res, gradient), single, gradient)


def winding_field(points, inner_radius, outer_radius, length, turns, current, *,
                  gradient=False, rtol=1e-10):
    """Thick multilayer solenoid with uniform current density over its rectangular section.

    The winding occupies inner_radius <= r <= outer_radius, -length/2 <= z <= length/2 and
    carries J = turns * current / ((outer_radius - inner_radius) * length) azimuthally
    (counter-clockwise seen from +z for positive current).

    Parameters
    ----------
    points : array-like, shape (3,) or (n, 3), m
    inner_radius, outer_radius : float, m
        0 < inner_radius < outer_radius, inner_radius / outer_radius in [1e-4, 0.999]
        (:data:`designkit.field.winding.RATIO_RANGE`).
    length : float, m
        length / outer_radius in [1e-3, 1e3] (:data:`designkit.field.winding.ASPECT_RANGE`).
    turns : int or float
        Number of turns (> 0); non-integer values are accepted (effective turns).
    current : float, A
    gradient : bool
        Also return G, T/m (exact, including the mu0 J term inside the winding, where G is
        not symmetric: dBz/drho = dBr/dz - mu0 J).
    rtol : float
        Relative accuracy wanted, in [1e-12, 1e-2]: |B - B_exact| <= rtol |B_exact| and
        |G - G_exact| <= 10 rtol |G_exact| (Frobenius norms) at every point, for every
        geometry of the domain above (verified against 30-digit mpmath references on randomized
        geometries and points on the axis, in the bore, inside, on and ulp-near the faces, near
        the corners and far away: tests/test_field_winding_random.py). Near the section's
        corners G grows like ln(1/d) and is ill-conditioned (one ulp of the point moves it by
        ~eps size / d relative): there the G bound holds beyond 1e-6 of the size. The
        quadrature uses the fewest nodes that reach rtol at each point (far points are cheap).
        Tighter requests raise BadInputError (float64 rounding of the kernels, amplified up
        to ~1e3 by thin windings, would not let them be kept).

    Returns
    -------
    B : ndarray, shape (n, 3), T [, G : ndarray, shape (n, 3, 3), T/m]
        At a corner of the section exactly, G is finite (see :mod:`designkit.field.winding`).

    Raises
    ------
    BadInputError
        Non-finite or badly shaped points, non-positive sizes, turns or a geometry or rtol
        outside the ranges above.
    """
    p, single = v.points(points)
    ri = v.positive("inner_radius", inner_radius, "m")
    ro = v.positive("outer_radius", outer_radius, "m")
    if ro <= ri:
        raise BadInputError("outer_radius", f"> inner_radius ({ri!r} m)", outer_radius)
    L = v.positive("length", length, "m")
    n_turns = v.positive("turns", turns, "")
    i = v.finite("current", current, "A")
    ratio = ri / ro
    if not RATIO_RANGE[0] <= ratio <= RATIO_RANGE[1]:
        raise BadInputError("inner_radius", f"in [{RATIO_RANGE[0]:g}, {RATIO_RANGE[1]:g}] x "
                            f"outer_radius ({ro!r} m), the domain where rtol is guaranteed",
                            inner_radius)
    if not ASPECT_RANGE[0] <= L / ro <= ASPECT_RANGE[1]:
        raise BadInputError("length", f"in [{ASPECT_RANGE[0]:g}, {ASPECT_RANGE[1]:g}] x "
                            f"outer_radius ({ro!r} m), the domain where rtol is guaranteed",
                            length)
    rtol = v.in_range("rtol", rtol, RTOL_MIN, RTOL_MAX)
    rho, z, c, s = _cyl(p)
    res = winding_rz(ri, ro, L / 2, rho, z, gradient=gradient, rtol=rtol)
    j = n_turns * i / ((ro - ri) * L)
    return _finish(cylindrical_to_cartesian(c, s, MU0 * j, res, gradient), single, gradient)


def magnetized_cylinder_field(points, radius, length, magnetization, *, gradient=False):
    """Uniformly axially magnetized cylinder centred at the origin (axis +z).

    Its B equals that of a current sheet with K = M on its side surface (inside and outside
    the material). Used for the iron core (uniform model) and the N52 finger magnet.

    Parameters
    ----------
    points : array-like, shape (3,) or (n, 3), m
    radius, length : float, m
    magnetization : float, A/m
        Axial magnetization M (signed).
    gradient : bool

    Returns
    -------
    B : ndarray, shape (n, 3), T [, G : ndarray, shape (n, 3, 3), T/m]
        On the side surface Bz is the mean of the two sides; on the rims the singular
        terms are 0.
    """
    p, single = v.points(points)
    a = v.positive("radius", radius, "m")
    L = v.positive("length", length, "m")
    m = v.finite("magnetization", magnetization, "A/m")
    rho, z, c, s = _cyl(p)
    res = sheet_rz(a, L / 2, rho, z, gradient=gradient)
    return _finish(cylindrical_to_cartesian(c, s, MU0 * m, res, gradient), single, gradient)


def dipole_field(points, moment, *, gradient=False):
    """Point dipole at the origin.

    B = mu0/(4 pi) (3 r (m.r) / r^5 - m / r^3);
    G_ij = 3 mu0/(4 pi r^5) [delta_ij (m.r) + r_i m_j + m_i r_j - 5 r_i r_j (m.r) / r^2].

    Parameters
    ----------
    points : array-like, shape (3,) or (n, 3), m
    moment : array-like, shape (3,), A m^2
    gradient : bool

    Returns
    -------
    B : ndarray, shape (n, 3), T [, G : ndarray, shape (n, 3, 3), T/m]
        At the dipole itself (r = 0) B = 0 and G = 0.
    """
    p, single = v.points(points)
    m = v.vector3("moment", moment, "A m^2")
    r2 = np.einsum("ij,ij->i", p, p)
    at0 = r2 == 0.0
    # scale out the magnitude so r^5 neither overflows nor underflows
    scale = np.sqrt(np.where(at0, 1.0, r2))
    u = p / scale[:, None]
    mr = u @ m
    k = MU0 / (4.0 * math.pi) / scale**3
    b = k[:, None] * (3.0 * u * mr[:, None] - m[None, :])
    b[at0] = 0.0
    if not gradient:
        return b[0] if single else b
    k2 = 3.0 * k / scale
    eye = np.eye(3)
    g = k2[:, None, None] * (eye[None] * mr[:, None, None] + u[:, :, None] * m[None, None, :]
                             + m[None, :, None] * u[:, None, :]
                             - 5.0 * u[:, :, None] * u[:, None, :] * mr[:, None, None])
    g[at0] = 0.0
    return (b[0], g[0]) if single else (b, g)
