"""Slow, independent high-precision references for the field kernels (tests and studies only).

Nothing here is used by the fast path. Every function works in mpmath at ``dps`` decimal
digits, from formulations that share no code and no algebra with :mod:`.kernels` /
:mod:`.winding`:

* :func:`loop_biot_savart` -- the Biot-Savart phi-integral of a circular filament, in
  Cartesian coordinates, gradient by differentiating the integrand under the integral sign
  (mp.quad, breakpoints graded towards the nearest wire point).
* :func:`sheet_textbook` -- the ideal finite solenoid in the textbook K, E, Pi form
  (Callaghan & Maslen, NASA TN D-465 (1960); Derby & Olbert, Am. J. Phys. 78, 229 (2010),
  with P1 = K - 2 (K - E)/m and P2 = (K + gamma Pi(1 - gamma^2 | m)) / (1 + gamma) written out
  with mpmath's ellipk, ellipe, ellippi); gradient by mp.diff of that closed form.
* :func:`winding_textbook` -- the thick winding as mp.quad over the radius of
  :func:`sheet_textbook`, with breakpoints at a = rho and graded around it.
* :func:`winding_loops_2d` -- the thick winding as a 2-D mp.quad over (a, z') of textbook
  K, E loop fields (very slow; used to validate :func:`winding_textbook` itself).
* :func:`winding_axis_bz` -- the on-axis closed form
  Bz = (mu0 J / 2) [F(z + L/2) - F(z - L/2)],
  F(u) = u ln((Ro + sqrt(Ro^2 + u^2)) / (Ri + sqrt(Ri^2 + u^2))), in mpmath (in float64 the
  difference cancels far away).

mu0 is 4 pi 1e-7 (designkit's constant, :data:`designkit.design.MU0`) in every function.
Results are float64 numpy arrays; Cartesian conventions as in :mod:`designkit.field`.
"""

from __future__ import annotations

import numpy as np

from ..errors import require


def _mp():
    return require("mpmath", "mpmath", "designkit.field.reference")


def _breaks(center, scale, lo, hi, mp):
    """Breakpoints in [lo, hi] graded geometrically (x10) towards ``center``, down to ``scale``."""
    pts = {lo, hi}
    if lo < center < hi:
        pts.add(center)
    d = max(scale, mp.mpf(10) ** (-mp.mp.dps + 5))
    while d < hi - lo:
        for p in (center - d, center + d):
            if lo < p < hi:
                pts.add(p)
        d *= 10
    return sorted(pts)


def loop_biot_savart(point, radius, current, *, dps=30):
    """B (3,) T and G (3, 3) T/m of the loop of :func:`designkit.field.loop_field`.

    B = mu0 I / (4 pi) int dl x R / |R|^3 over phi in [phi0 - pi, phi0 + pi], phi0 the azimuth
    of the point; dG_ij = mu0 I / (4 pi) [(dl x e_j)_i / |R|^3 - 3 (dl x R)_i R_j / |R|^5].
    """
    mp = _mp()
    with mp.workdps(dps):
        x, y, z = (mp.mpf(float(c)) for c in point)
        a = mp.mpf(float(radius))
        phi0 = mp.atan2(y, x) if (x != 0 or y != 0) else mp.mpf(0)
        rho = mp.sqrt(x * x + y * y)
        dist = mp.sqrt((rho - a) ** 2 + z * z)
        brk = _breaks(mp.mpf(0), dist / a / 10, -mp.pi, mp.pi, mp)

        memo = {}

        def parts(t):
            # mp.quad visits the same nodes for all 12 integrands: compute geometry once
            key = t
            if key in memo:
                return memo[key]
            ph = phi0 + t
            c, s = mp.cos(ph), mp.sin(ph)
            dl = (-a * s, a * c, mp.mpf(0))
            R = (x - a * c, y - a * s, z)
            r2 = R[0] ** 2 + R[1] ** 2 + R[2] ** 2
            memo[key] = (dl, R, r2)
            return memo[key]

        def cross(u, w):
            return (u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0])

        def fb(i):
            def f(t):
                dl, R, r2 = parts(t)
                return cross(dl, R)[i] / (r2 * mp.sqrt(r2))
            return f

        def fg(i, j):
            e = [mp.mpf(0)] * 3
            e[j] = mp.mpf(1)

            def f(t):
                dl, R, r2 = parts(t)
                r3 = r2 * mp.sqrt(r2)
                return cross(dl, e)[i] / r3 - 3 * cross(dl, R)[i] * R[j] / (r3 * r2)
            return f

        k = mp.mpf(4e-7) * mp.pi * mp.mpf(float(current)) / (4 * mp.pi)
        b = np.array([float(k * mp.quad(fb(i), brk)) for i in range(3)])
        g = np.array([[float(k * mp.quad(fg(i, j), brk)) for j in range(3)] for i in range(3)])
    return b, g


# ------------------------------------------------------------------ current sheet (textbook)
def _ke_mp(m, kc2, mp):
    """K(m), E(m); when m rounds to 1 (kc^2 below the working precision) the asymptotic
    K = ln(4 / kc), E = 1 (error O(kc^2 ln kc), below the working precision)."""
    if m >= 1:
        return mp.log(4 / mp.sqrt(kc2)), mp.mpf(1)
    return mp.ellipk(m), mp.ellipe(m)


def _sheet_rz_mp(a, h, rho, z, mp):
    """(Br, Bz) / (mu0 K) of a current sheet, textbook K, E, Pi form, mpmath numbers."""
    if rho == 0:
        # on the axis: Bz = K mu0/2 [cos-difference], Br = 0
        zp, zm = z + h, z - h
        return mp.mpf(0), (zp / mp.sqrt(zp * zp + a * a) - zm / mp.sqrt(zm * zm + a * a)) / 2
    gamma = (a - rho) / (a + rho)
    br = mp.mpf(0)
    bz = mp.mpf(0)
    for sign, zs in ((1, z + h), (-1, z - h)):
        den = zs * zs + (a + rho) ** 2
        q = (a - rho) ** 2 + zs * zs
        if q == 0:  # on the rim
            continue
        m = min(4 * a * rho / den, 1 - q / den)  # parameter k^2 of the end loop, <= 1
        K, E = _ke_mp(m, q / den, mp)
        alpha = a / mp.sqrt(den)
        beta = zs / mp.sqrt(den)
        p1 = K - 2 * (K - E) / m
        if gamma * gamma < mp.mpf(10) ** (-mp.mp.dps + 2):
            # 1 - gamma^2 rounds to 1: gamma Pi(1 - gamma^2 | m) -> sign(gamma) pi / (2 sqrt(1 - m))
            # (the sheet's jump); the neglected terms are O(gamma)
            p2 = (K + mp.sign(gamma) * mp.pi / (2 * mp.sqrt(q / den))) / (1 + gamma)
        else:
            p2 = (K + gamma * mp.ellippi(1 - gamma * gamma, m)) / (1 + gamma)
        br += sign * alpha * p1
        bz += sign * beta * p2
    return br / mp.pi, bz * a / ((a + rho) * mp.pi)


def sheet_textbook(a, h, rho, z, *, gradient=False, dps=30):
    """(Br, Bz) per mu0 K [, (dBr/drho, dBr/dz, dBz/drho, dBz/dz) per mu0 K in 1/m] of a sheet
    of radius ``a`` over z in [-h, h], as Python floats (mp.diff for the gradient)."""
    mp = _mp()
    with mp.workdps(dps):
        a_, h_, r_, z_ = (mp.mpf(float(q)) for q in (a, h, rho, z))
        br, bz = _sheet_rz_mp(a_, h_, r_, z_, mp)
        out = [float(br), float(bz)]
        if gradient:
            out += [float(d) for d in _sheet_grad_mp(a_, h_, r_, z_, mp)]
    return tuple(out)


def _sheet_grad_mp(a, h, rho, z, mp):
    step = mp.mpf(10) ** (-(mp.mp.dps // 3)) * max(a, abs(rho), abs(z))
    if rho < step:  # one-sided near the axis is not needed: the field is smooth in x there
        rho = step
    def f(i, rr, zz):
        return _sheet_rz_mp(a, h, rr, zz, mp)[i]
    dbr_dr = mp.diff(lambda t: f(0, t, z), rho, h=step)
    dbr_dz = mp.diff(lambda t: f(0, rho, t), z, h=step)
    dbz_dr = mp.diff(lambda t: f(1, t, z), rho, h=step)
    dbz_dz = mp.diff(lambda t: f(1, rho, t), z, h=step)
    return dbr_dr, dbr_dz, dbz_dr, dbz_dz


def _loop_rz_mp(a, rho, u, mp):
    """(Br, Bz) per mu0 I of a loop of radius a at axial offset u, textbook K, E form."""
    d2 = (a + rho) ** 2 + u * u
    q = (a - rho) ** 2 + u * u
    if q == 0:
        return mp.mpf(0), mp.mpf(0)
    m = min(4 * a * rho / d2, 1 - q / d2)  # the min keeps rounding from pushing m past 1
    K, E = _ke_mp(m, q / d2, mp)
    pre = 1 / (2 * mp.pi * mp.sqrt(d2))
    bz = pre * (K + (a * a - rho * rho - u * u) * E / q)
    br = pre * u / rho * (-K + (a * a + rho * rho + u * u) * E / q) if rho != 0 else mp.mpf(0)
    return br, bz


def winding_textbook(ri, ro, length, rho, z, *, gradient=False, dps=20):
    """Thick winding per unit mu0 J, as mp.quad over the radius a in [ri, ro].

    B is the integral of :func:`sheet_textbook`; dB/dz the integral of the sheet's two end
    loops (textbook K, E form), since d/dz of a uniform sheet is K [B_loop(z + h) - B_loop(z - h)].
    The remaining derivatives follow from Maxwell's equations (div B = 0, curl B = mu0 J):
    dBr/drho = -dBz/dz - Br/rho, dBz/drho = dBr/dz - [inside] (the -mu0 J term).

    Returns (Br, Bz) in m [and (dBr/drho, dBr/dz, dBz/drho, dBz/dz, Br/rho), dimensionless].
    """
    mp = _mp()
    with mp.workdps(dps):
        ri_, ro_, h_ = mp.mpf(float(ri)), mp.mpf(float(ro)), mp.mpf(float(length)) / 2
        r_, z_ = mp.mpf(float(rho)), mp.mpf(float(z))
        tau = min(abs(z_ - h_), abs(z_ + h_))
        dist = max(tau, mp.mpf(10) ** (-dps + 3) * ro_)
        near = ri_ - 10 * dist < r_ < ro_ + 10 * dist
        brk = _breaks(r_, dist / 4, ri_, ro_, mp) if near else [ri_, ro_]
        bz = mp.quad(lambda a: _sheet_rz_mp(a, h_, r_, z_, mp)[1], brk)
        br = mp.quad(lambda a: _sheet_rz_mp(a, h_, r_, z_, mp)[0], brk) if r_ != 0 else 0
        if not gradient:
            return float(br), float(bz)

        def dz(a, i):
            return _loop_rz_mp(a, r_, z_ + h_, mp)[i] - _loop_rz_mp(a, r_, z_ - h_, mp)[i]

        dbz_dz = mp.quad(lambda a: dz(a, 1), brk)
        if r_ == 0:
            half = -dbz_dz / 2
            return (0.0, float(bz), float(half), 0.0, 0.0, float(dbz_dz), float(half))
        dbr_dz = mp.quad(lambda a: dz(a, 0), brk)
        # the -mu0 J term: full inside, half on the winding's surface (designkit's convention)
        inside = 1 if (ri_ < r_ < ro_ and abs(z_) < h_) else (
            0.5 if (ri_ <= r_ <= ro_ and abs(z_) <= h_) else 0)
        br_r = br / r_
        return (float(br), float(bz), float(-dbz_dz - br_r), float(dbr_dz),
                float(dbr_dz - inside), float(dbz_dz), float(br_r))


def winding_loops_2d(ri, ro, length, rho, z, *, dps=20):
    """(Br, Bz) per mu0 J of the thick winding as a 2-D mp.quad over (a, z') of the textbook
    loop field Bz = [K + (a^2 - rho^2 - u^2) E / ((a - rho)^2 + u^2)] / (2 pi sqrt((a+rho)^2+u^2)),
    Br = u / rho [-K + (a^2 + rho^2 + u^2) E / ((a - rho)^2 + u^2)] / (2 pi sqrt(...)), u = z - z'.
    Slow (seconds per point): used to validate :func:`winding_textbook`. Requires rho > 0."""
    mp = _mp()
    with mp.workdps(dps):
        ri_, ro_, h_ = mp.mpf(float(ri)), mp.mpf(float(ro)), mp.mpf(float(length)) / 2
        r_, z_ = mp.mpf(float(rho)), mp.mpf(float(z))

        def loop(a, zp, i):
            return _loop_rz_mp(a, r_, z_ - zp, mp)[i]

        ab = sorted({ri_, ro_} | ({r_} if ri_ < r_ < ro_ else set()))
        zb = sorted({-h_, h_} | ({z_} if -h_ < z_ < h_ else set()))
        return tuple(float(mp.quad(lambda a, zp: loop(a, zp, i), ab, zb)) for i in range(2))


def winding_axis_bz(ri, ro, length, z, *, dps=40):
    """On-axis Bz per unit mu0 J (m) of the thick winding, closed form in mpmath."""
    mp = _mp()
    with mp.workdps(dps):
        ri_, ro_, h_ = mp.mpf(float(ri)), mp.mpf(float(ro)), mp.mpf(float(length)) / 2
        z_ = mp.mpf(float(z))

        def F(u):
            return u * mp.log((ro_ + mp.sqrt(ro_ ** 2 + u * u)) / (ri_ + mp.sqrt(ri_ ** 2 + u * u)))

        return float((F(z_ + h_) - F(z_ - h_)) / 2)


def rz_to_cartesian(point, br, bz, grad=None):
    """Assemble Cartesian B (3,) [and G (3, 3)] at ``point`` from cylindrical components.

    ``grad`` = (dBr/drho, dBr/dz, dBz/drho, dBz/dz, Br/rho)."""
    x, y, _ = (float(q) for q in point)
    rho = float(np.hypot(x, y))
    c, s = (x / rho, y / rho) if rho > 0 else (1.0, 0.0)
    b = np.array([br * c, br * s, bz])
    if grad is None:
        return b
    drr, drz, dzr, dzz, brr = grad
    g = np.array([
        [drr * c * c + brr * s * s, (drr - brr) * c * s, drz * c],
        [(drr - brr) * c * s, drr * s * s + brr * c * c, drz * s],
        [dzr * c, dzr * s, dzz],
    ])
    return b, g


# ------------------------------------------------------------------ thick winding, charge picture
def _ring_charge_mp(b, rho, u, mp):
    """(H_rho, H_z) at (rho, u) of a ring of radius b carrying unit surface-charge density over
    a unit radial width (total magnetic charge 2 pi b), textbook K, E form:
    H_z = b u E / (pi Q sqrt(D)), H_rho = b [K - (b^2 - rho^2 + u^2) E / Q] / (2 pi rho sqrt(D)),
    D = (b + rho)^2 + u^2, Q = (b - rho)^2 + u^2, m = 4 b rho / D. Near the axis K - ... cancels
    like 1 - O(m): the working precision is raised by log10(1/m) digits there."""
    D = (b + rho) ** 2 + u * u
    Q = (b - rho) ** 2 + u * u
    if Q == 0:
        return mp.mpf(0), mp.mpf(0)
    if rho == 0:
        return mp.mpf(0), b * u * mp.pi / 2 / (mp.pi * Q * mp.sqrt(D))
    m = 4 * b * rho / D
    extra = int(max(0, -mp.log10(m))) + 5 if m < 1e-3 else 0
    with mp.extradps(extra):
        D = (b + rho) ** 2 + u * u
        Q = (b - rho) ** 2 + u * u
        m = min(4 * b * rho / D, 1 - Q / D)
        K, E = _ke_mp(m, Q / D, mp)
        sd = mp.sqrt(D)
        hz = b * u * E / (mp.pi * Q * sd)
        hr = b * (K - (b * b - rho * rho + u * u) * E / Q) / (2 * mp.pi * rho * sd)
    return +hr, +hz


def _graded_breaks(center, scale, lo, hi, mp, ratio=4):
    """Breakpoints in [lo, hi]: lo, hi, ``center`` (if inside) and center +- scale * ratio^k."""
    pts = {lo, hi}
    if lo < center < hi:
        pts.add(center)
    d = max(scale, (hi - lo) * mp.mpf(10) ** (-mp.mp.dps))
    while d < hi - lo:
        for p in (center - d, center + d):
            if lo < p < hi:
                pts.add(p)
        d *= ratio
    return sorted(pts)


def _quad_pv(f, lo, hi, c, scale, mp, kinks=()):
    """int_lo^hi f over breakpoints graded towards c (scale: the distance of f's nearest
    complex singularity from c) and at ``kinks``. If scale == 0 and lo < c < hi, f may have a
    1/(x - c) pole: the principal value, by folding x = c +- t over the symmetric part."""
    def q(a, b, center, sc):
        brk = set(_graded_breaks(center, sc, a, b, mp)) | {k for k in kinks if a < k < b}
        return mp.quad(f, sorted(brk))

    if scale == 0 and lo < c < hi:
        d = min(c - lo, hi - c)
        tb = set(_graded_breaks(mp.mpf(0), d * mp.mpf(10) ** (-mp.mp.dps // 2), mp.mpf(0), d, mp))
        tb |= {abs(k - c) for k in kinks if 0 < abs(k - c) < d}
        total = mp.quad(lambda t: f(c + t) + f(c - t), sorted(tb))
        if c - d > lo:
            total += q(lo, c - d, c - d, (c - d - lo) * mp.mpf(10) ** (-mp.mp.dps // 2))
        if c + d < hi:
            total += q(c + d, hi, c + d, (hi - c - d) * mp.mpf(10) ** (-mp.mp.dps // 2))
        return total
    return q(lo, hi, c, scale / 2)


def winding_charge(ri, ro, length, rho, z, *, gradient=False, dps=30):
    """Thick winding per unit mu0 J, from its equivalent magnetization (an independent picture).

    A uniform azimuthal current density J over ri < r < ro, |z| < h is the curl of the axial
    magnetization M_z(r) = J (ro - max(r, ri)) for r < ro, |z| < h (0 elsewhere). M has no volume
    charge (it does not depend on z); its surface charge sigma = +-M_z(r) sits on the two end
    disks z = +-h, r < ro. So B = mu0 (H + M) with H the field of two charged disks: a 1-D
    mp.quad over the ring radius b in [0, ro] of textbook ring-of-charge fields (K, E only),
    with breakpoints at b = ri and graded towards b = rho by the distance to each end plane (a
    principal value by folding when the point lies on an end plane).

    The gradient's d/dz column is mu0 J int_ri^ro [B_loop(a, z + h) - B_loop(a, z - h)] da
    (textbook K, E loops); the rest follows from div B = 0 and curl B = mu0 J.

    Returns (Br, Bz) in m [and (dBr/drho, dBr/dz, dBz/drho, dBz/dz, Br/rho), dimensionless],
    with the designkit conventions on the winding's surface (half the -J term, mean of the
    two sides) and B, G in units of mu0 J. ``rho``, ``z`` are exact (converted from the given
    floats without rounding).
    """
    mp = _mp()
    # far points: the two disks' fields cancel like (size / R): keep dps digits after it
    R = max(abs(float(rho)), abs(float(z)), 1e-300)
    size = min(float(length), float(ro))
    extra = int(max(0.0, np.log10(R / size))) + 2
    # within d of a face plane the near-singular integrands need ~log10(size / d) more digits
    # to keep mp.quad's nodes and error estimates meaningful (found at 1e-18 of the size)
    d = min(abs(float(z) - length / 2), abs(float(z) + length / 2), abs(float(rho) - ri),
            abs(float(rho) - ro))
    if d > 0:
        extra += int(min(30.0, max(0.0, np.log10(float(ro) / d) - 8)))
    with mp.workdps(dps + extra):
        ri_, ro_, h_ = mp.mpf(float(ri)), mp.mpf(float(ro)), mp.mpf(float(length)) / 2
        r_, z_ = mp.mpf(float(rho)), mp.mpf(float(z))

        def sigma(b):
            return ro_ - (b if b > ri_ else ri_)

        hr = mp.mpf(0)
        hz = mp.mpf(0)
        for s, u in ((1, z_ - h_), (-1, z_ + h_)):
            memo = {}

            def f(b, i):
                if b not in memo:
                    memo[b] = _ring_charge_mp(b, r_, u, mp)
                return s * sigma(b) * memo[b][i]

            # sigma has a kink at ri (a breakpoint)
            if r_ != 0:
                hr += _quad_pv(lambda b: f(b, 0), mp.mpf(0), ro_, r_, abs(u), mp, (ri_,))
            # H_z of a disk on its own plane is 0 off the ring (principal value)
            if u != 0:
                hz += _quad_pv(lambda b: f(b, 1), mp.mpf(0), ro_, r_, abs(u), mp, (ri_,))
        az = abs(z_)
        if r_ <= ro_ and az <= h_:
            m_here = sigma(r_) * (mp.mpf(1) / 2 if az == h_ else 1)
        else:
            m_here = 0
        br, bz = hr, hz + m_here
        if not gradient:
            return float(br), float(bz)

        def loop_end(a, u, i):
            return _loop_rz_mp_safe(a, r_, u, mp)[i]

        def dz_int(i):
            total = mp.mpf(0)
            for sgn, u in ((1, z_ + h_), (-1, z_ - h_)):
                total += sgn * _quad_pv(lambda a: loop_end(a, u, i), ri_, ro_, r_, abs(u), mp)
            return total

        dbz_dz = dz_int(1)
        if r_ == 0:
            half = -dbz_dz / 2
            return (0.0, float(bz), float(half), 0.0, 0.0, float(dbz_dz), float(half))
        dbr_dz = dz_int(0)
        inside = 1 if (ri_ < r_ < ro_ and az < h_) else (
            mp.mpf(1) / 2 if (ri_ <= r_ <= ro_ and az <= h_) else 0)
        br_r = br / r_
        return (float(br), float(bz), float(-dbz_dz - br_r), float(dbr_dz),
                float(dbr_dz - inside), float(dbz_dz), float(br_r))


def _loop_rz_mp_safe(a, rho, u, mp):
    """:func:`_loop_rz_mp` with the working precision raised near the axis, where its Br
    bracket -K + (...) E / q cancels like O(m)."""
    if rho == 0:
        return _loop_rz_mp(a, rho, u, mp)
    m = 4 * a * rho / ((a + rho) ** 2 + u * u)
    extra = int(max(0, -mp.log10(m))) + 5 if m < 1e-3 else 0
    with mp.extradps(extra):
        br, bz = _loop_rz_mp(a, rho, u, mp)
    return +br, +bz


# ------------------------------------------------------------------ randomized test cases
REGIONS = ("axis", "bore", "body", "face", "corner", "ulp", "near", "far")


def sample_cases(seed, n_geometries, regions=REGIONS, per_region=1, extremes=True):
    """Seeded random thick windings and observer points in every region (tests and studies).

    Geometry: Ro = 1 cm x 10^U(-1, 1), Ri / Ro and L / Ro log-uniform in [1e-4, 0.99] and
    [1e-3, 1e3], except the first four (if ``extremes``), the corners of that domain. Regions ("size" = the section's diagonal hypot(Ro - Ri, L)):

    * axis: rho = 0, z uniform in +-(h + 2 Ro);
    * bore: rho in (0, Ri), |z| < h;  body: Ri < rho < Ro, |z| < h;
    * face: 1e-9..1e-2 x size (log-uniform) inside or outside one of the four faces, away
      from its ends; corner: the same distance from one of the four corners, any direction;
    * ulp: 1..4 ulps from a face or a corner (either side);
    * near: 1e-2..1 x size outside the section; far: 2..1e4 x hypot(Ro, h) from the centre.

    Face, corner and ulp points lie in the plane y = 0 (rho exact); the others have a random
    azimuth. Returns a list of dicts (ri, ro, length, region, point (3,), corner_distance, size).
    """
    rng = np.random.default_rng(seed)
    out = []
    # the first four geometries are the domain's corners (Ri/Ro, L/Ro) = (1e-4 | 0.99, 1e-3 | 1e3)
    use_extremes = extremes
    corners_rl = [(1e-4, 1e-3), (1e-4, 1e3), (0.99, 1e-3), (0.99, 1e3)]
    for g in range(n_geometries):
        ro = 0.01 * 10 ** rng.uniform(-1, 1)
        ri = ro * 10 ** rng.uniform(-4, np.log10(0.99))
        length = ro * 10 ** rng.uniform(-3, 3)
        if use_extremes and g < len(corners_rl):
            ri, length = ro * corners_rl[g][0], ro * corners_rl[g][1]
        h = length / 2
        size = float(np.hypot(ro - ri, length))
        corners = [(ri, h), (ri, -h), (ro, h), (ro, -h)]
        for region in regions:
            for _k in range(per_region):
                phi = rng.uniform(0, 2 * np.pi)
                if region == "axis":
                    rho, z = 0.0, rng.uniform(-1, 1) * (h + 2 * ro)
                elif region == "bore":
                    rho, z = ri * rng.uniform(0, 1), h * rng.uniform(-1, 1)
                elif region == "body":
                    rho, z = rng.uniform(ri, ro), h * rng.uniform(-1, 1)
                elif region == "face":
                    phi = 0.0
                    d = size * 10 ** rng.uniform(-9, -2) * rng.choice([-1, 1])
                    f = rng.integers(4)
                    t = rng.uniform(0.1, 0.9)
                    if f < 2:  # side faces r = ri, ro
                        rho, z = (ri, ro)[f] + d, h * (2 * t - 1)
                    else:      # end faces z = +-h
                        rho, z = ri + t * (ro - ri), (h if f == 2 else -h) + d
                elif region == "corner":
                    phi = 0.0
                    d = size * 10 ** rng.uniform(-9, -2)
                    ang = rng.uniform(0, 2 * np.pi)
                    cr, cz = corners[rng.integers(4)]
                    rho, z = abs(cr + d * np.cos(ang)), cz + d * np.sin(ang)
                elif region == "ulp":
                    phi = 0.0
                    k = float(rng.choice([1, 2, 4])) * rng.choice([-1, 1]) * 2.0 ** -52
                    cr, cz = corners[rng.integers(4)]
                    kind = rng.integers(3)
                    if kind == 0:    # end face
                        rho, z = ri + rng.uniform(0.1, 0.9) * (ro - ri), cz * (1 + k)
                    elif kind == 1:  # side face
                        rho, z = cr * (1 + k), h * rng.uniform(-0.9, 0.9)
                    else:            # corner
                        rho, z = cr * (1 + k), cz * (1 - k)
                elif region == "near":
                    d = size * 10 ** rng.uniform(-2, 0)
                    ang = rng.uniform(0, 2 * np.pi)
                    cr, cz = corners[rng.integers(4)]
                    # outward from a corner, or beside / above a face
                    side = rng.integers(3)
                    if side == 0:
                        rho = abs(cr + d * abs(np.cos(ang)) * np.sign(cr - 0.5 * (ri + ro)))
                        z = cz + d * abs(np.sin(ang)) * np.sign(cz)
                    elif side == 1:
                        rho, z = ro + d, h * rng.uniform(-1, 1)
                    else:
                        rho, z = rng.uniform(0, ro), np.sign(cz) * (h + d)
                else:  # far
                    R = float(np.hypot(ro, h)) * 10 ** rng.uniform(np.log10(2), 4)
                    u = rng.normal(size=3)
                    u /= np.linalg.norm(u)
                    rho, z = float(np.hypot(u[0], u[1])) * R, u[2] * R
                point = np.array([rho * np.cos(phi), rho * np.sin(phi), z])
                if phi == 0.0:
                    point[1] = 0.0
                rr = float(np.hypot(point[0], point[1]))
                cd = min(float(np.hypot(rr - cr, point[2] - cz)) for cr, cz in corners)
                out.append(dict(ri=float(ri), ro=float(ro), length=float(length),
                                region=region, point=point, corner_distance=cd, size=size))
    return out


def case_reference(case, dps=30):
    """(B (3,), G (3, 3)) per unit mu0 J (m, dimensionless) of a :func:`sample_cases` case, from
    :func:`winding_charge` at ``dps`` digits."""
    p = case["point"]
    rho = float(np.hypot(p[0], p[1]))
    r = winding_charge(case["ri"], case["ro"], case["length"], rho, p[2], gradient=True, dps=dps)
    return rz_to_cartesian(p, r[0], r[1], r[2:])
