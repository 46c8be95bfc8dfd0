"""Fast saturating rod core: axially magnetized slices on the 1010 steel B-H curve.

The panel model (:mod:`designkit.cores.panel`) with ``bh='steel1010'`` is too slow for an
optimizer's thousands of evaluations; this reduced model solves the same physics fast enough
for finite-difference gradients. It is a *model*, not a fit: no parameter is tuned to data
(its measured error against the panel model and GetDP: docs/core_model.md, "Fast rod model").

Model (SI, winding-local frame: winding centred at z = 0, axis z): the core (radius a, length
Lc, centre z_c) is cut into n axial slices, each uniformly magnetized along z with M_k (A/m),
i.e. a current sheet K = M_k on its side. Slice-averaged flux density
``<B>_k = B0_k + sum_j T_kj mu0 M_j`` with T from Nagaoka's coefficient
(:mod:`designkit.cores.nagaoka`) and B0_k the winding's flux density averaged over the slice;
material law ``B_k = mu0 (H(B_k) + M_k)`` on the smooth 1010 steel curve
(:func:`designkit.cores.material.steel1010_h_smooth`), solved by Newton. The flux linkage with
the winding follows by reciprocity. Full derivation: docs/core_model.md, "Fast rod model".
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.special import j1

from ..constants import MU0
from ..errors import BadInputError
from ..field.fourier_bessel import int_x_j1, quarter_period_panels
from ..geometry.winding import WindingGeometry
from .material import STEEL1010_B, STEEL1010_H, steel1010_h_smooth
from .nagaoka import nagaoka_self

N_SLICES = 24
"""Default slice count (convergence in the slice count: docs/core_model.md)."""


def interval_mutual(p: np.ndarray, q: np.ndarray, radius_m: float) -> np.ndarray:
    """C[k, j] = int_{p_k} int_{q_j} M_loop(a, a, z - z') dz dz' for intervals p (n,2), q (m,2).

    H m^2 (mutual inductance of the two unit-density sheets of radius a).
    """
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    p1, p2 = p[:, 0][:, None], p[:, 1][:, None]
    q1, q2 = q[:, 0][None, :], q[:, 1][None, :]
    qf = lambda x: nagaoka_self(x, radius_m)  # noqa: E731
    return 0.5 * (qf(p2 - q1) + qf(p1 - q2) - qf(p1 - q1) - qf(p2 - q2))


@dataclass(frozen=True)
class RodSolution:
    """Solved slices of a rod core at one current (SI, winding-local frame).

    edges_m : (n + 1,) slice boundaries along z; b_t : (n,) slice-averaged B; m_a_per_m : (n,)
    magnetization; b0_t : (n,) the winding's share of b_t; linkage_wb : flux linkage of the
    winding with the core's field; dlinkage_di_wb_per_a : its derivative in the current;
    air_inductance_h: not included (add :func:`designkit.model.electrical.air_inductance_from_geometry`).
    """

    radius_m: float
    edges_m: np.ndarray
    b_t: np.ndarray
    m_a_per_m: np.ndarray
    b0_t: np.ndarray
    current_a: float
    linkage_wb: float
    dlinkage_di_wb_per_a: float
    newton_iterations: int

    @property
    def peak_b_t(self) -> float:
        return float(np.max(np.abs(self.b_t)))

    @property
    def secant_extra_inductance_h(self) -> float:
        return self.linkage_wb / self.current_a

    @property
    def incremental_extra_inductance_h(self) -> float:
        return self.dlinkage_di_wb_per_a

    def axis_field(self, z_m) -> tuple[np.ndarray, np.ndarray]:
        """Core's Bz (T) and dBz/dz (T/m) on the axis at local heights z_m (any shape)."""
        z = np.asarray(z_m, dtype=float)[..., None]
        return _sheet_axis(self.radius_m ** 2, z - self.edges_m[:-1], z - self.edges_m[1:],
                           0.5 * MU0 * self.m_a_per_m)


@dataclass(frozen=True)
class RodBatch:
    """Solved slices of B rod cores (:func:`solve_rods`), SI; arrays lead with the design.

    radius_m (B,); edges_m (B, n + 1); b_t, m_a_per_m, b0_t (B, n); linkage_wb,
    dlinkage_di_wb_per_a (B,). ``batch[i]`` is design i's :class:`RodSolution`.
    """

    radius_m: np.ndarray
    edges_m: np.ndarray
    b_t: np.ndarray
    m_a_per_m: np.ndarray
    b0_t: np.ndarray
    current_a: float
    linkage_wb: np.ndarray
    dlinkage_di_wb_per_a: np.ndarray
    newton_iterations: int

    def __len__(self) -> int:
        return len(self.radius_m)

    def __getitem__(self, i: int) -> RodSolution:
        return RodSolution(float(self.radius_m[i]), self.edges_m[i], self.b_t[i],
                           self.m_a_per_m[i], self.b0_t[i], self.current_a,
                           float(self.linkage_wb[i]), float(self.dlinkage_di_wb_per_a[i]),
                           self.newton_iterations)

    @property
    def peak_b_t(self) -> np.ndarray:
        return np.max(np.abs(self.b_t), axis=1)

    def axis_field(self, z_m) -> tuple[np.ndarray, np.ndarray]:
        """Each core's Bz (T) and dBz/dz (T/m) on its axis at local height z_m[i], (B,) each."""
        z = np.broadcast_to(np.asarray(z_m, dtype=float), self.radius_m.shape)[:, None]
        return _sheet_axis(self.radius_m[:, None] ** 2, z - self.edges_m[:, :-1],
                           z - self.edges_m[:, 1:], 0.5 * MU0 * self.m_a_per_m)


def _sheet_axis(a2, u1, u2, k):
    """Bz and dBz/dz on the axis of stacked sheets (K = k 2 / mu0), summed over the last axis."""
    s1 = np.sqrt(a2 + u1 * u1)
    s2 = np.sqrt(a2 + u2 * u2)
    bz = np.sum(k * (u1 / s1 - u2 / s2), axis=-1)
    g = np.sum(k * (a2 / s1 ** 3 - a2 / s2 ** 3), axis=-1)
    return bz, g


def slice_edges(core_length_m: float, core_centre_m: float, n: int) -> np.ndarray:
    """Uniform slice boundaries of the core, m."""
    return core_centre_m + core_length_m * (np.linspace(0.0, 1.0, n + 1) - 0.5)


def applied_slice_flux(inner_radius_m, outer_radius_m, length_m, turns, radius_m, edges_m, *,
                       nr: int = 3, nz: int = 3) -> np.ndarray:
    """G_k = int over slice k of the winding's B_z dV per ampere (Wb m / A), (n,).

    Gauss-Legendre in the area coordinate s = (r/a)^2 and in z per slice; the integrand is
    smooth inside the bore (r <= inner radius) and beyond the winding's ends.
    """
    xr, wr = np.polynomial.legendre.leggauss(nr)
    xz, wz = np.polynomial.legendre.leggauss(nz)
    s = 0.5 * (xr + 1.0)
    rr = radius_m * np.sqrt(s)
    lo, hi = edges_m[:-1], edges_m[1:]
    zz = 0.5 * (lo + hi)[:, None] + 0.5 * (hi - lo)[:, None] * xz[None, :]  # (n, nz)
    rho = np.broadcast_to(rr[None, None, :], zz.shape + (nr,)).ravel()
    zp = np.broadcast_to(zz[..., None], zz.shape + (nr,)).ravel()
    winding = WindingGeometry(inner_radius_m, outer_radius_m, length_m, turns)
    hz = winding.h_rz(rho, zp, rtol=1e-8)[1].reshape(zz.shape + (nr,))
    # volume integral: pi a^2 * int_0^1 ds * int dz
    per = (hz @ (0.5 * wr)) @ (0.5 * wz)  # mean over the slice of H_z per ampere
    return MU0 * per * math.pi * radius_m ** 2 * (hi - lo)


def _q_exp(k, ell):
    """int_0^l int_0^l exp(-k |x - y|) dx dy = 2 (k l + exp(-k l) - 1) / k^2 (l >= 0)."""
    u = k * ell
    return 2.0 * (u + np.expm1(-u)) / (k * k)


@functools.lru_cache(maxsize=8)
def _outer_nodes(t_max: float, nodes: int):
    """Fixed t = k ro nodes, weights, S(t) and J-free parts that do not depend on the geometry."""
    t, wt = quarter_period_panels(float(t_max), nodes)
    return t, wt, int_x_j1(t)


def bessel_slice_flux(inner_radius_m, outer_radius_m, length_m, turns, radius_m, edges_m, *,
                      t_max: float = 200.0, nodes: int = 6) -> np.ndarray:
    """Same G_k as :func:`applied_slice_flux` by the Fourier-Bessel mutual-inductance integral.

    G_k = mu0 pi a n_w int_0^inf J1(k a) [S(k ro) - S(k ri)] / k^2 E_k(k) dk, with
    n_w = N / ((ro - ri) L) turns per m^2, S(x) = int_0^x t J1(t) dt and
    E_k = int_slice int_winding exp(-k |z - z'|) dz dz' (closed form, :func:`_q_exp`).
    Fixed Gauss-Legendre panels in t = k ro up to ``t_max`` (quarter periods), so the result is
    a smooth function of the geometry (finite-difference gradients stay clean); the
    truncation leaves ~(ro / (a t_max))^2 relative.

    Batched: the geometry arguments may be (B,) arrays with ``edges_m`` (B, n + 1); the
    result is then (B, n) Wb m / A.
    """
    edges = np.asarray(edges_m, dtype=float)
    single = edges.ndim == 1
    edges = np.atleast_2d(edges)
    ro, ri, ln, nt, a = (np.asarray(q, dtype=float).reshape(-1, 1)
                         for q in (outer_radius_m, inner_radius_m, length_m, turns, radius_m))
    t, wt, s_outer = _outer_nodes(float(t_max), int(nodes))
    k = t[None, :] / ro  # (B, T)
    wk = wt[None, :] / ro
    # the special functions and exponentials cost most: a finite-difference batch repeats
    # many designs' radii or axial geometry, so each distinct row is computed once
    uq, inv = np.unique(np.c_[ri, ro], axis=0, return_inverse=True)
    kq = t[None, :] / uq[:, 1:2]
    rad = ((s_outer[None, :] - int_x_j1(kq * uq[:, 0:1])) / (kq * kq))[inv.ravel()]
    # E_k from the 2 (n + 1) distances between slice edges and winding ends
    uz, invz = np.unique(np.c_[ro, ln, edges], axis=0, return_inverse=True)
    kz = (t[None, :] / uz[:, 0:1])[:, None, :]
    ez = uz[:, 2:, None]
    q1 = _q_exp(kz, np.abs(ez + uz[:, 1:2, None] / 2))  # to the bottom end, -L/2
    q2 = _q_exp(kz, np.abs(ez - uz[:, 1:2, None] / 2))  # to the top end, +L/2
    e = (0.5 * (q1[:, 1:] + q2[:, :-1] - q1[:, :-1] - q2[:, 1:]))[invz.ravel()]
    n_w = nt / ((ro - ri) * ln)
    out = MU0 * math.pi * a * n_w * np.einsum("bnt,bt->bn", e, wk * j1(k * a) * rad)
    return out[0] if single else out


@dataclass(frozen=True)
class RodGeometry:
    """The winding and the core of one or B rod models (scalars or (B,) arrays): winding
    section ``inner_radius_m``, ``outer_radius_m``, ``length_m`` (m, centred at z = 0),
    ``turns``; core ``core_radius_m``, ``core_length_m`` (m) and ``core_offset_m`` (its
    centre's z, m)."""

    inner_radius_m: object
    outer_radius_m: object
    length_m: object
    turns: object
    core_radius_m: object
    core_length_m: object
    core_offset_m: object


@dataclass(frozen=True)
class RodSettings:
    """How the rod model is solved: ``n_slices``; Newton until |residual| < ``tol_t`` (T) or
    ``max_iter``; ``relative_permeability`` a linear core with this mu_r instead of the B-H
    curve (for checks of the linear limit); ``quadrature`` (nr, nz) Gauss points per slice in
    the area coordinate and in z for the winding's flux, or 'bessel' (the Fourier-Bessel
    integral, :func:`bessel_slice_flux`, smooth in the geometry)."""

    n_slices: int = N_SLICES
    tol_t: float = 1e-12
    max_iter: int = 60
    relative_permeability: float | None = None
    quadrature: tuple[int, int] | str = (3, 3)


def solve_rod(geometry: RodGeometry, current_a: float,
              settings: RodSettings = RodSettings()) -> RodSolution:
    """Solve the slice model of a 1010-steel rod core driven by the winding at ``current_a``
    (A, > 0): :func:`solve_rods` of one design (``geometry`` of scalars)."""
    return solve_rods(geometry, current_a, settings)[0]


def solve_rods(geometry: RodGeometry, current_a: float,
               settings: RodSettings = RodSettings()) -> "RodBatch":
    """:func:`solve_rod` for B designs at once (``geometry`` of scalars or (B,) arrays, m).

    One Newton iteration works on all designs still above ``settings.tol_t`` together
    (stacked n x n solves): an optimizer's finite-difference gradient costs about one solve,
    not one per variable. Each design's iterates are those of its own solve.
    """
    g_ = geometry
    n_slices, tol_t, max_iter = settings.n_slices, settings.tol_t, settings.max_iter
    relative_permeability, quadrature = settings.relative_permeability, settings.quadrature
    inner_radius_m, outer_radius_m, length_m, turns = (g_.inner_radius_m, g_.outer_radius_m,
                                                       g_.length_m, g_.turns)
    core_radius_m, core_length_m, core_offset_m = (g_.core_radius_m, g_.core_length_m,
                                                   g_.core_offset_m)
    geo = np.broadcast_arrays(*(np.atleast_1d(np.asarray(q, dtype=float)) for q in (
        inner_radius_m, outer_radius_m, length_m, turns, core_radius_m, core_length_m,
        core_offset_m)))
    ri, ro, ln, nt, a, lc, off = (np.array(q, dtype=float) for q in geo)
    for name, val in (("core_radius_m", a), ("core_length_m", lc), ("turns", nt)):
        bad = ~(np.isfinite(val) & (val > 0))
        if bad.any():
            raise BadInputError(name, "a finite number > 0", float(val[bad][0]))
    if not (math.isfinite(current_a) and current_a > 0):
        raise BadInputError("current_a", "a finite number > 0", current_a)
    bad = ~((ro > ri) & (ri > 0))
    if bad.any():
        i = int(np.argmax(bad))
        raise BadInputError("outer_radius_m", f"> inner_radius_m ({ri[i]} m) > 0", ro[i])
    bad = a > ri * (1 + 1e-12)
    if bad.any():
        i = int(np.argmax(bad))
        raise BadInputError("core_radius_m", f"<= inner_radius_m ({ri[i]} m)", a[i])
    n = int(n_slices)
    nb = len(a)
    edges = off[:, None] + lc[:, None] * (np.linspace(0.0, 1.0, n + 1)[None, :] - 0.5)
    vol = math.pi * (a * a)[:, None] * np.diff(edges, axis=1)
    # uniform slices: C depends on |k - j| only (Toeplitz), Q at (m h), m = 0..n
    hs = lc / n
    qm = nagaoka_self(hs[:, None] * np.arange(n + 1)[None, :], a[:, None])
    idx = np.abs(np.arange(n)[:, None] - np.arange(n)[None, :])
    qpad = np.concatenate([qm[:, 1:2], qm], axis=1)  # Q(-h) = Q(h): index m - 1 + 1
    cm = 0.5 * (qm[:, np.minimum(idx + 1, n)] + qpad[:, idx] - 2.0 * qm[:, idx])
    t = cm / (MU0 * vol[:, :, None])
    if quadrature == "bessel":
        g = bessel_slice_flux(ri, ro, ln, nt, a, edges)
    else:
        g = np.stack([applied_slice_flux(ri[i], ro[i], ln[i], nt[i], a[i], edges[i],
                                         nr=quadrature[0], nz=quadrature[1])
                      for i in range(nb)])
    b0 = g * current_a / vol
    eye = np.eye(n)
    mu_i = STEEL1010_B[1] / (MU0 * STEEL1010_H[1])
    if relative_permeability is not None:
        mu_i = float(relative_permeability)
    b = np.linalg.solve(eye - t + t / mu_i, b0[:, :, None])[:, :, 0]
    if relative_permeability is not None:
        m = b / MU0 * (1.0 - 1.0 / mu_i)
        lk = np.sum(m * g, axis=1)
        return RodBatch(a, edges, b, m, b0, float(current_a), lk, lk / current_a, 0)

    def residual(tt, bb, bb0):
        h = steel1010_h_smooth(bb)[0]
        return bb - _mv(tt, bb) + _mv(tt, MU0 * h) - bb0

    it = 0
    for it in range(1, max_iter + 1):
        r = residual(t, b, b0)
        norm0 = np.max(np.abs(r), axis=1)
        act = np.nonzero(norm0 >= tol_t)[0]
        if not len(act):
            break
        ta, ba, b0a, n0 = t[act], b[act], b0[act], norm0[act]
        dh = steel1010_h_smooth(ba)[1]
        jac = (eye - ta) + ta * (MU0 * dh)[:, None, :]
        step = np.linalg.solve(jac, r[act][:, :, None])[:, :, 0]
        # backtracking: past the knee a full step can overshoot into the flat part; a design
        # that never decreases keeps the smallest step tried (lambda = 2^-13)
        lam = np.ones(len(act))
        searching = np.ones(len(act), dtype=bool)
        bn = ba - step
        for _ in range(14):
            s_ = np.nonzero(searching)[0]
            bn[s_] = ba[s_] - lam[s_, None] * step[s_]
            rn = residual(ta[s_], bn[s_], b0a[s_])
            done = np.max(np.abs(rn), axis=1) < n0[s_]
            searching[s_[done]] = False
            if not searching.any() or lam[searching][0] * 0.5 <= 1e-4:
                break
            lam[searching] *= 0.5
        b[act] = bn
    h, dh = steel1010_h_smooth(b)
    jac = (eye - t) + t * (MU0 * dh)[:, None, :]
    m = b / MU0 - h
    db = np.linalg.solve(jac, (b0 / current_a)[:, :, None])[:, :, 0]
    dm = db / MU0 - dh * db
    return RodBatch(a, edges, b, m, b0, float(current_a), np.sum(m * g, axis=1),
                    np.sum(dm * g, axis=1), it)


def _mv(mat, vec):
    """Stacked matrix-vector products (B, n, n) x (B, n) -> (B, n)."""
    return np.matmul(mat, vec[:, :, None])[:, :, 0]
