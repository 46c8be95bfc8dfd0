"""Two finger magnets' pull on each other at run time: each magnet as point charges on its axis.

A uniformly magnetized cylinder (radius a, length 2 h, axis u) is, outside its circumscribing
sphere (radius r0 = sqrt(a^2 + h^2)), the field of its axial multipoles: phi = sum_{l odd} C_l
P_l(cos t) / r^(l+1), C_l = (M / 4 pi) 2 int_0^a 2 pi rho r'^l P_l(h / r') d rho (r'^2 =
rho^2 + h^2; H = -grad phi; C_1 = |m| / 4 pi). K pairs of magnetic charges +-q_k at +-d_k u
(d_k: :data:`CHARGE_FRACTIONS` of r0) matching C_1 .. C_(2K-1) pull on another magnet's charges
as Coulomb charges do (mu0 q q' / (4 pi r^2)), up to the multipoles they do not reproduce.

The error is bounded (docs/coupling.md, "The magnets' pull on each other"): for centres R >
r_a + r_b apart, U = 4 pi mu0 sum C^a_l C^b_l' (-1)^l / (l! l'!) (u_a . grad)^l
(u_b . grad)^l' (1 / R), and a mixed directional derivative of 1 / R of order n along unit
vectors is at most n! / R^(n+1) (Banach 1938: a symmetric multilinear form on a Hilbert space
has the norm of its polynomial; |(w . grad)^n 1/R| = n! |P_n| / R^(n+1)). So |F - F_charges|
<= 4 pi mu0 sum_{max(l, l') > 2K} |C'^a_l C'^b_l' - C^a_l C^b_l'| (l+l'+1)! / (l! l'!
R^(l+l'+2)) (C' the charges' moments), the torque likewise with l' (l+l')! / (l! l'!
R^(l+l'+1)); summed exactly to l, l' <= :data:`L_SUM`, beyond by a geometric series of
|C_l| <= kappa rho^l. :meth:`PairBound.switch_distance_m` is where the bound meets a
tolerance. Lengths in m, moments in A m^2, charges in A m, forces in N, torques in N m; numpy
only.
"""

from __future__ import annotations

import math

import numpy as np

from .constants import MU0

CHARGE_FRACTIONS = (0.2, 0.45, 0.7, 0.95)
"""The charge pairs' distances from the magnet's centre, in units of r0: one pair each, the
multipoles C_1 .. C_7 exact. Chosen by the bound (docs/coupling.md): for 10 x 10 mm magnets
it holds 1e-4 of the dipole scale from 26.3 mm (3 pairs at 0.3, 0.6, 0.9 r0: 50.4 mm; 5 pairs
at 0.2 .. 1.0 r0: 26.2 mm, more charges)."""
L_SUM = 119
"""Highest multipole order the error bound sums term by term (beyond: a geometric bound)."""


def axial_moments(radius_m: float, length_m: float, l_max: int) -> np.ndarray:
    """C_l / |m| (1 / (4 pi) at l = 1), m^(l - 1), of a uniformly magnetized cylinder for the
    odd l <= ``l_max``: Gauss-Legendre in rho (exact: the integrand is a polynomial of degree
    l + 1 in rho), P_l by its three-term recurrence on (r' / r0)^l-scaled values."""
    a, h = float(radius_m), 0.5 * float(length_m)
    r0 = math.hypot(a, h)
    x, w = np.polynomial.legendre.leggauss(l_max // 2 + 4)
    rho = 0.5 * a * (x + 1.0)
    wr = 0.5 * a * w * 2.0 * math.pi * rho
    rp = np.sqrt(rho * rho + h * h)
    c, s = h / rp, rp / r0
    p_prev, p = np.ones_like(c), c.copy()  # P_0, P_1
    out = []
    for l in range(1, l_max + 1):
        if l % 2:
            out.append(float(wr @ (p * s ** l)) * r0 ** l)
        p_prev, p = p, ((2 * l + 1) * c * p - l * p_prev) / (l + 1)
    # per unit moment: C_l = (2 M / 4 pi) int ..., M = |m| / (pi a^2 2 h)
    return np.array(out) * (2.0 / (4.0 * math.pi)) / (math.pi * a * a * 2.0 * h)


class AxialCharges:
    """A cylinder magnet (``radius_m``, ``length_m``) as K pairs of charges on its axis (one
    per entry of ``fractions``, default :data:`CHARGE_FRACTIONS`): ``offsets_m`` (2 K,) along
    the axis from its centre and ``charges`` (2 K,) A m per A m^2 of moment, with its
    multipoles C_1 .. C_(2K-1); ``moments`` (the
    cylinder's C_l / |m|, odd l <= L_SUM) and ``model_moments`` (the charges') for the error
    bound (:class:`PairBound`)."""

    __slots__ = ("radius_m", "length_m", "r0", "offsets_m", "charges", "moments",
                 "model_moments", "kappa", "model_kappa", "model_rho")

    def __init__(self, radius_m: float, length_m: float, fractions=None):
        self.radius_m, self.length_m = float(radius_m), float(length_m)
        self.r0 = math.hypot(self.radius_m, 0.5 * self.length_m)
        self.moments = axial_moments(self.radius_m, self.length_m, L_SUM)
        d = self.r0 * np.asarray(CHARGE_FRACTIONS if fractions is None else fractions, float)
        pairs = len(d)
        ls = np.arange(1, 2 * pairs, 2)[:, None]
        # (1 / 4 pi) sum_k 2 q_k d_k^l = C_l: a Vandermonde system in d^2, scaled by r0
        v = 2.0 / (4.0 * math.pi) * (d[None, :] / self.r0) ** ls
        q = np.linalg.solve(v, self.moments[:pairs] / self.r0 ** ls[:, 0])
        self.offsets_m = np.r_[d, -d]
        self.charges = np.r_[q, -q]
        lall = np.arange(1, L_SUM + 1, 2)
        self.model_moments = (2.0 / (4.0 * math.pi)) * ((d[None, :] ** lall[:, None]) @ q)
        vol = math.pi * self.radius_m ** 2 * self.length_m
        self.kappa = self.r0 ** 2 / (3.0 * vol)  # |C_l| / |m| <= kappa r0^l
        self.model_kappa = float(np.abs(q).sum()) / (2.0 * math.pi)
        self.model_rho = float(d.max())


class PairBound:
    """The proven bound on the charges' error for magnets of geometries ``a`` and ``b``
    (:class:`AxialCharges`), relative to the pair's dipole scales 3 mu0 |m_a| |m_b| /
    (4 pi R^4) (force) and 2 mu0 |m_a| |m_b| / (4 pi R^3) (torque), as a function of the
    centre distance R (module docstring)."""

    def __init__(self, a: AxialCharges, b: AxialCharges):
        self.span = a.r0 + b.r0
        k = min(len(a.charges), len(b.charges)) // 2
        ls = np.arange(1, L_SUM + 1, 2)
        # scaled moments c_l = C_l / (|m| span^(l - 1)): products stay representable
        sc = self.span ** (ls - 1.0)
        ca, cb = a.moments / sc, b.moments / sc
        ma, mb = a.model_moments / sc, b.model_moments / sc
        e = np.abs(np.outer(ma, mb) - np.outer(ca, cb))
        la, lb = np.meshgrid(ls, ls, indexing="ij")
        keep = np.maximum(la, lb) >= 2 * k + 1
        n = la + lb
        lf = np.r_[0.0, np.cumsum(np.log(np.arange(1, 2 * L_SUM + 3)))]  # log n!
        wf = np.exp(lf[n + 1] - lf[la] - lf[lb])
        wt = lb * np.exp(lf[n] - lf[la] - lf[lb])
        self.powers = (n - 2)[keep]
        self.coef_f = (16.0 * math.pi ** 2 / 3.0) * (e * wf)[keep]
        self.coef_t = (8.0 * math.pi ** 2) * (e * wt)[keep]
        # beyond L_SUM: sum_{l + l' = n} kappa_a kappa_b rho_a^l rho_b^l' (...) for both
        # products, (rho_a + rho_b)^n = (t x)^n with x = span / R
        self.tails = [(a.kappa * b.kappa, (a.r0 + b.r0) / self.span),
                      (a.model_kappa * b.model_kappa, (a.model_rho + b.model_rho) / self.span)]

    def relative(self, distance_m: float) -> tuple[float, float]:
        """(force, torque) error bounds at centre distance ``distance_m``, relative to the
        pair's dipole scales; inf where the bound does not hold (R <= r_a + r_b)."""
        x = self.span / float(distance_m)
        if x >= 1.0:
            return math.inf, math.inf
        xp = x ** self.powers
        f, t = float(self.coef_f @ xp), float(self.coef_t @ xp)
        nn = L_SUM + 1  # the first order the exact sums may miss
        for kap, rho in self.tails:
            s = rho * x
            if s >= 1.0:
                return math.inf, math.inf
            # sum_{n >= N} (n + 1) s^n and sum n s^n, times the dipole scales' factors
            g1 = s ** nn * (nn + 1 - nn * s) / (1.0 - s) ** 2
            g0 = s ** nn * (nn - (nn - 1) * s) / (1.0 - s) ** 2
            f += (16.0 * math.pi ** 2 / 3.0) * kap * self.span ** 2 * g1 / x ** 2
            t += (8.0 * math.pi ** 2) * kap * self.span ** 2 * g0 / x ** 2
        return f, t

    def switch_distance_m(self, tol: float) -> float:
        """The smallest centre distance from which both relative bounds are <= ``tol`` (they
        fall monotonically with the distance), m."""
        lo, hi = self.span, 2.0 * self.span
        while max(self.relative(hi)) > tol:
            lo, hi = hi, 2.0 * hi
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if max(self.relative(mid)) > tol:
                lo = mid
            else:
                hi = mid
        return hi


def charge_forces(positions_m: np.ndarray, moments_a_m2: np.ndarray, models: list,
                  mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Forces (N, 3) N and torques (N, 3) N m (about each centre) of N magnets on each other
    from their axial charges (``models``: one :class:`AxialCharges` per magnet, all with the
    same number of charges); ``mask`` (N, N) bool: the pairs to include (default all; the
    diagonal never). At k = 8 charges each the cost is the number of numpy calls, not the
    arithmetic: per pair one (k, k, 3) difference, its weights and two batched products."""
    pos = np.asarray(positions_m, float)
    mom = np.asarray(moments_a_m2, float)
    n = len(pos)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)
             if mask is None or mask[i, j] or mask[j, i]]
    if not pairs:
        return np.zeros((n, 3)), np.zeros((n, 3))
    force, lever = np.zeros((n, 3)), np.zeros((n, 3))
    mag = np.sqrt((mom * mom).sum(axis=1))
    u = mom / np.where(mag > 0, mag, 1.0)[:, None]
    scale = MU0 / (4.0 * math.pi)
    x = [pos[i] + models[i].offsets_m[:, None] * u[i] for i in range(n)]   # (k, 3) each
    for i, j in pairs:                                              # each pair once
        d = x[i][:, None, :] - x[j][None, :, :]                   # (k, k, 3)
        r2 = np.einsum("abk,abk->ab", d, d)
        w = np.multiply.outer(models[i].charges, models[j].charges)
        w *= scale * mag[i] * mag[j]
        w /= r2 * np.sqrt(r2)
        # on each charge of i (Newton: j's opposite), w[a, b] d[a, b] summed over b, resp. a
        fi = np.matmul(w[:, None, :], d)[:, 0]
        fj = np.matmul(w.T[:, None, :], d.transpose(1, 0, 2))[:, 0]
        force[i] += fi.sum(axis=0)
        force[j] -= fj.sum(axis=0)
        # sum_k (off_k u) x f_k = u x sum_k off_k f_k
        lever[i] += models[i].offsets_m @ fi
        lever[j] -= models[j].offsets_m @ fj
    return force, cross_rows(u, lever)


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (n, 3) arrays (np.cross's axis handling, and numpy calls on
    single columns, cost more than the product for a few rows: Python floats)."""
    return np.array([[a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0]
                     for (a0, a1, a2), (b0, b1, b2) in zip(a.tolist(), b.tolist())],
                    float).reshape(-1, 3)
