"""One core type of the coupled array solve: its unknowns, self blocks and basis fields.

Every linear, homogeneous core is a body of revolution about its own axis, so its response to
any applied field splits into azimuthal Fourier modes m that do not mix. Per core type
(:class:`CoreModel`, local frame of its coil): the m = 0 unknowns are the bound azimuthal
surface currents K (A/m) of the single-core panel model (:mod:`designkit.cores.discretization`,
same integral equation, so one core driven by its own winding gives *exactly* the single-core
solution); the m = 1 .. m_max unknowns are bound surface charges (A/m, cos and sin;
:mod:`designkit.cores.charges`). Applied fields are sampled on collocation rings and projected
onto the modes; far from a core its field uses compressed product rules
(:func:`designkit.cores.quadrature.product_matrix`). Derivation: docs/coupling.md.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..constants import MU0
from ..field import cylindrical_to_cartesian
from ..field.kernels import loop_rz
from ..geometry.winding import WindingGeometry
from .charges import (N1_CAP, N1_SIDE, ChargeModes, graded_both, graded_hi,
                      self_charge_matrices)
from .discretization import (N_CAP, N_SIDE, influence_system, interface_factor,
                             panel_basis_rz, panel_geometry)
from .quadrature import azimuth_cos_sin, product_matrix
from .solution import CoreSolution

M_MAX = 3
"""Highest azimuthal mode kept (convergence in m_max against the 3-D FEM: docs/coupling.md)."""
FAR_DISTANCE = 8e-3
"""Points nearer than this (m) to a core's bounding cylinder always sum its panels."""
FAR_NODES = 6
"""Gauss nodes per interval of the compressed ring rules (the product rule of the single-core
field evaluation, here linear in the panel values)."""
FAR_RHO = 2.6
"""Bernstein-ellipse parameter a point needs w.r.t. every interval of the compressed rules
(error ~ FAR_RHO^-12 ~ 1e-5 with 6 nodes)."""


@dataclass(frozen=True, eq=False)
class CoreModel(ChargeModes):
    """Discretization and self blocks of one core type (local frame of its coil).

    m = 0: panels of :func:`designkit.cores.discretization.panel_geometry` (n0 = 80).
    m >= 1: ``N1_SIDE`` side panels and ``N1_CAP`` per end face (n1 = 64), charge density
    constant per panel.
    """

    radius: float
    z_lo: float
    z_hi: float
    mu_r: float
    m_max: int
    # m = 0
    side: np.ndarray
    discs: np.ndarray
    f0: np.ndarray
    self0: np.ndarray
    rho0: np.ndarray
    z0: np.ndarray
    far_r: np.ndarray
    far_z: np.ndarray
    far_w: np.ndarray
    # m >= 1 panels: kind 0 side (param z), 1 top cap, 2 bottom cap (param r)
    kind1: np.ndarray
    lo1: np.ndarray
    hi1: np.ndarray
    rho1: np.ndarray
    z1: np.ndarray
    self1: tuple  # per m: (n1, n1) I - 2 lam D_m
    far1_r: np.ndarray = None  # compressed rings of the m >= 1 charges (far points)
    far1_z: np.ndarray = None
    far1_w: np.ndarray = None  # (n_rings, n1): ring line density = far1_w @ sigma
    far_segments: np.ndarray = None  # (n_int, 2, 2): (rho, z) ends of the product-rule intervals

    def far_mask(self, rho: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Points where the compressed ring rules are accurate (bool (n,)).

        The product rule interpolates the kernel by a degree FAR_NODES - 1 polynomial on each
        interval; its error is ~ r^(-2 FAR_NODES), r the Bernstein-ellipse parameter of the
        point (in the meridian plane) with respect to the interval. Far: r >= FAR_RHO on every
        interval and at least FAR_DISTANCE (8 mm) from the core.
        """
        dist = np.maximum.reduce([self.z_lo - z, z - self.z_hi, rho - self.radius])
        ok = dist >= FAR_DISTANCE
        for (r0, z0), (r1, z1) in self.far_segments:
            c = complex(0.5 * (r0 + r1), 0.5 * (z0 + z1))
            half = complex(0.5 * (r1 - r0), 0.5 * (z1 - z0))
            w = (rho + 1j * z - c) / half
            sq = np.sqrt(w * w - 1.0)
            r = np.maximum(np.abs(w + sq), np.abs(w - sq))
            ok &= r >= FAR_RHO
        return ok

    @property
    def n0(self) -> int:
        return len(self.rho0)

    @property
    def n1(self) -> int:
        return len(self.rho1)

    @property
    def n_unknowns(self) -> int:
        return self.n0 + 2 * self.m_max * self.n1

    @property
    def lam2(self) -> float:
        return 2.0 * (self.mu_r - 1.0) / (self.mu_r + 1.0)

    def factors(self) -> np.ndarray:
        """Row factors F of the interface equations, (n_unknowns,)."""
        return np.r_[self.f0, np.full(2 * self.m_max * self.n1, self.lam2)]

    def self_block(self) -> np.ndarray:
        n = self.n_unknowns
        out = np.zeros((n, n))
        out[:self.n0, :self.n0] = self.self0
        for m in range(1, self.m_max + 1):
            for c in range(2):
                s = self.n0 + (2 * (m - 1) + c) * self.n1
                out[s:s + self.n1, s:s + self.n1] = self.self1[m - 1]
        return out

    # ------------------------------------------------------------------ sampling rings
    def ring_points(self, n_phi: int) -> np.ndarray:
        """Local points of the m = 0 then m >= 1 collocation rings, (n0 + n1, n_phi, 3), m."""
        phi = 2.0 * math.pi * np.arange(n_phi) / n_phi
        rho = np.r_[self.rho0, self.rho1]
        z = np.r_[self.z0, self.z1]
        return np.stack([rho[:, None] * np.cos(phi)[None], rho[:, None] * np.sin(phi)[None],
                         np.repeat(z[:, None], n_phi, axis=1)], axis=-1)

    def project(self, h_local: np.ndarray) -> np.ndarray:
        """Mode projection of H (local frame) sampled on :meth:`ring_points`.

        h_local : (n0 + n1, n_phi, 3, ...) A/m (trailing axes are kept).
        Returns (n_unknowns, ...): m = 0 rows the azimuthal mean of the meridian tangential H
        (side +z, end faces -r), m >= 1 rows the cos / sin coefficients of the normal H.
        """
        n_phi = h_local.shape[1]
        phi = 2.0 * math.pi * np.arange(n_phi) / n_phi
        extra = (None,) * (h_local.ndim - 3)
        c = np.cos(phi)[(slice(None),) + extra]
        s = np.sin(phi)[(slice(None),) + extra]
        h0 = h_local[:self.n0]
        ns = len(self.side)
        t0 = np.concatenate([h0[:ns, :, 2], -(h0[ns:, :, 0] * c + h0[ns:, :, 1] * s)])
        rows = [t0.mean(axis=1)]
        h1 = h_local[self.n0:]
        side = self.kind1 == 0
        hn = np.where(side[(slice(None), None) + extra], h1[:, :, 0] * c + h1[:, :, 1] * s,
                      np.where((self.kind1 == 1)[(slice(None), None) + extra], h1[:, :, 2],
                               -h1[:, :, 2]))
        for m in range(1, self.m_max + 1):
            cm = np.cos(m * phi)[(None, slice(None)) + extra]
            sm = np.sin(m * phi)[(None, slice(None)) + extra]
            rows.append(2.0 / n_phi * (hn * cm).sum(axis=1))
            rows.append(2.0 / n_phi * (hn * sm).sum(axis=1))
        return np.concatenate(rows, axis=0)

    # ------------------------------------------------------------------ basis fields
    def basis_field(self, pts: np.ndarray, gradient: bool = False, fine: bool = False):
        """H of every unit unknown at local points (outside the core).

        Returns H (n, 3, n_unknowns) A/m per unit [, G (n, 3, 3, n_unknowns) A/m^2].
        m = 0 unknowns are surface currents K (A/m), m >= 1 charge densities (A/m).
        """
        pts = np.asarray(pts, dtype=float)
        n = len(pts)
        nu = self.n_unknowns
        h = np.zeros((n, 3, nu))
        g = np.zeros((n, 3, 3, nu)) if gradient else None
        if n == 0:
            return (h, g) if gradient else h
        rho = np.hypot(pts[:, 0], pts[:, 1])
        far = self.far_mask(rho, pts[:, 2])
        for sel, fn in ((far, self._m0_far), (~far, self._m0_near)):
            if np.any(sel):
                res = fn(pts[sel], rho[sel], gradient)
                if gradient:
                    h[sel, :, :self.n0], g[sel, :, :, :self.n0] = res
                else:
                    h[sel, :, :self.n0] = res
        if self.m_max:
            if fine:
                res = self._m1_field(pts, 4, 64, gradient)
                if gradient:
                    h[:, :, self.n0:], g[:, :, :, self.n0:] = res
                else:
                    h[:, :, self.n0:] = res
            else:
                # compressed rings where accurate (ring density = far1_w @ sigma), panel
                # charges elsewhere; each reduced per mode before the unknowns are expanded
                for sel, rule in ((far, "far"), (~far, (3, 32))):
                    if not np.any(sel):
                        continue
                    res = self._m1_field(pts[sel], *((None, None) if rule == "far" else rule),
                                         gradient)
                    if gradient:
                        h[sel, :, self.n0:], g[sel, :, :, self.n0:] = res
                    else:
                        h[sel, :, self.n0:] = res
        return (h, g) if gradient else h

    def field(self, pts: np.ndarray, xs: np.ndarray, gradient: bool = False,
              pointwise: bool = False, own_col: int | None = None):
        """H of the core for unknown columns ``xs`` (n_unknowns, k) at local points.

        Contracts the unknowns before the kernels (far rings for m = 0, charges for m >= 1).
        Returns H (n, 3, k) A/m [, G (n, 3, 3, k) A/m^2]; with ``pointwise`` point i uses
        column i (k = n) and the shapes are (n, 3) [, (n, 3, 3)].
        """
        pts = np.asarray(pts, dtype=float)
        n = len(pts)
        k = xs.shape[1]
        shp = (n,) if pointwise else (n, k)
        h = np.zeros((n, 3) + shp[1:])
        g = np.zeros((n, 3, 3) + shp[1:]) if gradient else None
        if n == 0:
            return (h, g) if gradient else h
        rho = np.hypot(pts[:, 0], pts[:, 1])
        far = self.far_mask(rho, pts[:, 2])
        x0 = xs[:self.n0]
        if own_col is not None and not pointwise:
            # the column of the core's own winding (by far its largest): m = 0 through
            # the single-core field rules (CoreSolution), so one coil alone is exactly the single-core model;
            # the small remainder of the other columns by the compressed rules below
            res = self._own_solution(x0[:, own_col]).field(pts, gradient=gradient)
            if gradient:
                h[..., own_col] += res[0] / MU0
                g[..., own_col] += res[1] / MU0
            else:
                h[..., own_col] += res / MU0
            x0 = x0.copy()
            x0[:, own_col] = 0.0
        # m = 0: cylindrical components per column, then Cartesian
        for sel, is_far in ((far, True), (~far, False)):
            if not np.any(sel):
                continue
            idx = np.flatnonzero(sel)
            comps = self._m0_rz(pts[idx], rho[idx], gradient, is_far)  # list (m, nb)
            xcol = x0[:, idx] if pointwise else x0
            if pointwise:
                cz = [np.einsum("nb,bn->n", q, xcol) for q in comps]
                res = self._rz_basis_to_xyz(pts[idx], rho[idx], [c[:, None] for c in cz],
                                            gradient)
                res = (res[0][..., 0], res[1][..., 0]) if gradient else res[..., 0]
            else:
                cz = [q @ xcol for q in comps]
                res = self._rz_basis_to_xyz(pts[idx], rho[idx], cz, gradient)
            if gradient:
                h[idx] += res[0]
                g[idx] += res[1]
            else:
                h[idx] += res
        if self.m_max:
            for sel, rule in ((~far, (3, 32)), (far, "far")):
                if not np.any(sel):
                    continue
                idx = np.flatnonzero(sel)
                src, q = self._charges(xs[self.n0:], rule)  # (nc, 3), (nc, k)
                res = self._charge_kernel(pts[idx], src, gradient,
                                          q[:, idx] if pointwise else q, pointwise)
                if gradient:
                    h[idx] += res[0]
                    g[idx] += res[1]
                else:
                    h[idx] += res
        return (h, g) if gradient else h

    @functools.cached_property
    def _own_solutions(self) -> dict:
        return {}

    def _own_solution(self, x0: np.ndarray) -> CoreSolution:
        """The single-core solution of the m = 0 unknowns ``x0`` (n0,), cached by value (its
        compressed rules are built on first use, per instance)."""
        key = x0.tobytes()
        cache = self._own_solutions
        sol = cache.get(key)  # one lookup: the map's sampling threads share the cache
        if sol is None:
            if len(cache) > 64:
                cache.clear()
            ns = len(self.side)
            x0 = x0.copy()
            sol = CoreSolution(self.radius, self.side[:, 0], self.side[:, 1], x0[:ns],
                               self.discs[:, 0], self.discs[:, 1], self.discs[:, 2],
                               x0[ns:], 0.0)
            cache[key] = sol
        return sol

    def _m0_rz(self, pts, rho, gradient, far):
        """Cylindrical components per m = 0 unknown: list of (n, n0) arrays."""
        n = len(rho)
        z = pts[:, 2]
        if far:
            nq = len(self.far_r)
            res = loop_rz(np.tile(self.far_r, n), np.repeat(rho, nq),
                          np.repeat(z, nq) - np.tile(self.far_z, n), gradient=gradient)
            return [q.reshape(n, nq) @ self.far_w for q in res]
        return panel_basis_rz(self.radius, self.side, self.discs, rho, z, 4, gradient)

    def _rz_basis_to_xyz(self, pts, rho, comps, gradient):
        """(n, nb) cylindrical component arrays -> Cartesian (n, 3, nb) [, (n, 3, 3, nb)]."""
        c, s = azimuth_cos_sin(pts, rho)
        nb = comps[0].shape[1]
        flat = [q.T.ravel() for q in comps]  # basis-major
        res = cylindrical_to_cartesian(np.tile(c, nb), np.tile(s, nb), 1.0, flat, gradient)
        n = len(rho)
        if gradient:
            b, gg = res
            return (np.moveaxis(b.reshape(nb, n, 3), 0, -1),
                    np.moveaxis(gg.reshape(nb, n, 3, 3), 0, -1))
        return np.moveaxis(res.reshape(nb, n, 3), 0, -1)

    def _m0_far(self, pts, rho, gradient):
        return self._rz_basis_to_xyz(pts, rho, self._m0_rz(pts, rho, gradient, True), gradient)

    def _m0_near(self, pts, rho, gradient):
        return self._rz_basis_to_xyz(pts, rho, self._m0_rz(pts, rho, gradient, False), gradient)


def _far_rings(radius, side_intervals, side_lo, side_hi, faces, n_cols):
    """Compressed ring rule of a core's panel values (:func:`product_matrix` with FAR_NODES
    nodes): rings on the side at r = radius over ``side_intervals`` (the side panels are
    columns 0 .. len(side_lo) - 1), then on each face ``(z, r_lo, r_hi, columns)`` over
    [0, radius]. Returns ring r, ring z (m) and W (n_rings, n_cols): ring density = W @ x."""
    nodes, w = product_matrix(side_lo, side_hi, side_intervals, FAR_NODES)
    full = np.zeros((len(nodes), n_cols))
    full[:, :len(side_lo)] = w
    rr, zz, ww = [np.full_like(nodes, radius)], [nodes], [full]
    for zp, r_lo, r_hi, cols in faces:
        nodes, w = product_matrix(r_lo, r_hi, [(0.0, radius)], FAR_NODES)
        full = np.zeros((len(nodes), n_cols))
        full[:, cols] = w
        rr.append(nodes)
        zz.append(np.full_like(nodes, zp))
        ww.append(full)
    return np.concatenate(rr), np.concatenate(zz), np.vstack(ww)


def _charge_panels(radius, lo, hi, refine):
    """The m >= 1 charge panels: kind (0 side, 1 top face, 2 bottom face), parameter
    interval [lo1, hi1] (z on the side, r on a face) and collocation point (rho1, z1), m."""
    n1s, n1c = N1_SIDE * refine, N1_CAP * refine
    e_side = graded_both(lo, hi, n1s)
    e_cap = graded_hi(0.0, radius, n1c)
    kind = np.r_[np.zeros(n1s, int), np.ones(n1c, int), np.full(n1c, 2)]
    lo1 = np.r_[e_side[:-1], e_cap[:-1], e_cap[:-1]]
    hi1 = np.r_[e_side[1:], e_cap[1:], e_cap[1:]]
    mid = 0.5 * (lo1 + hi1)
    rho1 = np.where(kind == 0, radius, mid)
    z1 = np.where(kind == 0, mid, np.where(kind == 1, hi, lo))
    return kind, lo1, hi1, rho1, z1


@functools.lru_cache(maxsize=32)
def core_model(radius: float, length: float, offset: float, mu_r: float, key: tuple,
               m_max: int = M_MAX, refine: int = 1) -> CoreModel:
    """Discretization and self blocks of a linear core (cached per core type).

    ``key``: the driving winding (a :class:`designkit.geometry.winding.WindingGeometry` or the tuple
    of its four numbers); ``refine`` multiplies every panel count (convergence studies, wide
    cores).
    """
    # m = 0: the single-core panels and influence matrix
    side, _, discs = panel_geometry(radius, length, offset, n_side=N_SIDE * refine,
                                    n_cap=N_CAP * refine)
    a, _, rho0, z0 = influence_system(radius, side, discs, WindingGeometry(*key))
    below = discs[:, 3].astype(int)
    above = discs[:, 4].astype(int)
    f_disc = interface_factor(np.where(below < 0, 1.0, mu_r), np.where(above < 0, 1.0, mu_r))
    f0 = np.concatenate([interface_factor(np.full(len(side), mu_r), 1.0), f_disc])
    self0 = np.eye(len(f0)) - f0[:, None] * a
    # m >= 1: charge panels and their mode-diagonal self blocks
    lo, hi = offset - length / 2, offset + length / 2
    kind, lo1, hi1, rho1, z1 = _charge_panels(radius, lo, hi, refine)
    self1 = ()
    if m_max:
        d = self_charge_matrices(radius, (lo, hi), (kind, lo1, hi1, rho1, z1), m_max)
        lam2 = 2.0 * (mu_r - 1.0) / (mu_r + 1.0)
        self1 = tuple(np.eye(len(kind)) - lam2 * d[m] for m in range(m_max))
    # compressed far rules of both (as CoreSolution.groups): the side in three stretches
    end = min(0.15 * (hi - lo), 2 * radius)
    stretches = [(lo, lo + end), (lo + end, hi - end), (hi - end, hi)]
    ns = len(side)
    faces0 = [(zp, discs[sel, 1], discs[sel, 2], ns + sel) for zp in np.unique(discs[:, 0])
              for sel in [np.flatnonzero(discs[:, 0] == zp)]]
    far0 = _far_rings(radius, stretches, side[:, 0], side[:, 1], faces0, len(f0))
    n1s = int(np.sum(kind == 0))
    faces1 = [(zp, lo1[sel], hi1[sel], sel) for kk, zp in ((1, hi), (2, lo))
              for sel in [np.flatnonzero(kind == kk)]]
    far1 = _far_rings(radius, stretches, lo1[:n1s], hi1[:n1s], faces1, len(kind))
    segs = np.array([[[radius, a], [radius, b]] for a, b in stretches]
                    + [[[0.0, zp], [radius, zp]] for zp in (lo, hi)])
    return CoreModel(radius, lo, hi, mu_r, m_max, side, discs, f0, self0, rho0, z0, *far0,
                     kind, lo1, hi1, rho1, z1, self1, *far1, segs)
