"""The array as one magnetic system: all cores magnetized together, by every source at hand.

Every linear, homogeneous core is a body of revolution about its own axis, so its response to
any applied field splits into azimuthal Fourier modes ``m`` that do not mix (about *its* axis).
The array-level solve keeps, per core:

``m = 0``
    The axisymmetric part, with exactly the unknowns and the integral equation of the single-core
    model (:mod:`designkit.core`, bound azimuthal surface current ``K`` on the meridian panels):
    ``K = f (H0_t + PV[H_K]_t)``. A single core driven by its own winding therefore gives
    *exactly* the single-core solution.
``m = 1 .. m_max`` (cos and sin)
    The non-axisymmetric part as bound surface *charge* ``sigma = M . n`` (a scalar; the
    magnetization of a linear core is curl- and divergence-free inside): the second-kind
    equation ``sigma = 2 (mu_r - 1) / (mu_r + 1) (H0_n + PV[H_sigma]_n)``, collocated on
    panels graded towards the rims. Its ill-conditioned mode (the net charge, ``m = 0``) is
    exactly the one these modes never contain.

The applied field of a core (``H0``) is the sources' field plus the field of every *other*
core; it is sampled on the core's collocation rings (``N_PHI_RING`` azimuths) and projected onto
the modes. The self blocks are mode-diagonal; the cross blocks (core i's unknowns -> core j's
projected field) are built once per design. Solving the block system for a source gives all
cores' magnetization at once (a dense LU, factorized once per design and reused for every
source: each coil's winding per ampere, the finger magnet at each position).

Costs (n_c cores, n_u = n0 + 2 m_max n1 unknowns per core; default 80 + 2*3*64 = 464, 4176
for the 3 x 3 array):

* per design (once, cached on the :class:`~designkit.array.CoilArray`): the self blocks of each
  core type (m = 0: core.py's influence matrix; m >= 1: n1^2 graded quadratures), one cross
  block per distinct relative placement of two cores (24 in a 3 x 3 grid; each = the basis
  fields of one core at (n0 + n1) x N_PHI_RING points of the other), one dense LU of
  n_c n_u (4176^2), and the coil columns (each winding sampled on every core's rings, one per
  distinct relative placement, then an LU back-substitution). Measured 3.3 s for the default
  array, both together, on a loaded 2-core machine (studies/bench_map.py, stage 'coupled
  solve'; the charges' basis fields are summed per mode before the unknowns are expanded);
* per point of A: the n_c windings (as uncoupled) plus, per core, ~30 compressed m = 0 rings and
  the compressed m >= 1 rings x FAR_AZIMUTHS charges (far points) or 176 panel kernels and
  6144 panel charges (points the Bernstein-ellipse test puts near): ~0.7 ms per point with
  gradient, 9 columns (loaded machine; studies/bench_map.py, 'direct coupled model');
* per magnet position (F0, torque, induced field): the magnet's field sampled on every core's
  rings (N_PHI_MAGNET azimuths on cores within 30 mm, N_PHI_RING on the others), one
  back-substitution, one evaluation: ~5 ms per position (dipole), ~4x that for the finite
  cylinder (face quadrature).

Accuracy (measured, tests/test_coupling.py, studies/fem3d_array.py): against the 3-D GetDP
FEM (designkit.fem.fem3d, level 1, B and grad B from the iron's magnetization; level 0 -> 1
changes them by <= 0.6 / 1.3 %), per point |dB|/|B| and ||dG||_F/||G||_F over a 5 x 5 grid
150 mm wide: 3 x 3 array, centre coil at 1 A, max 1.15 / 1.78 % at 20 mm, 0.65 / 1.01 % at
30 mm, < 0.5 % from 50 mm (1.92 / 2.80 % at 12 mm, 7 mm above the cores' tops); two cores
(18 points 12-60 mm): 0.62 / 1.27 %. The largest errors are
beside the array's edge cores, where the energized coil's field is mostly that of the
neighbour cores it magnetizes; they fall like 1 / n1 (:data:`N1_SIDE`). The solve is
reciprocal to ~0.2 %.

Magnet-core interaction (linear cores): the magnet magnetizes the cores
(:meth:`ArraySystem.magnet_solution`); the field of these cores anywhere is
``CoilArray.magnet_core_field``; the force and torque on the magnet are
:meth:`ArraySystem.magnet_load`: for a point dipole ``F0 = (m . grad) B_ind(p)``,
``tau = m x B_ind(p)``; for the real 10 x 10 mm N52 cylinder (``magnet_size_m``) its exact
field is the source and the force is that of its face charges (exact for uniform M). The
dipole is the default (the map and the controller carry only m); it underestimates the pull by
0.2 % at 80 mm, 0.7 % at 50 mm, 1.9 % at 30 mm, 4 % at 12-20 mm, and the sensor-induced field by
~1 %. With linear cores everything superposes: ``F(p, I) = F(m) A(p) I + F0(p)`` exactly for a
rigid point dipole. What remains: (1) saturation couples currents and magnet (their fields add
in the iron: at 12 mm the magnet adds ~0.12 T, 5 mm below the centre core's top, to the ~0.8 T
of its coil at 6 A; at 30 mm 0.015 T), not in a per-coil factor; (2) the magnet's finite size,
i.e. A(p) at the centre vs averaged over the magnet (the dipole-vs-cylinder numbers above);
(3) the magnet's own permeability (mu_r ~ 1.05 for NdFeB: the coils' field changes its
moment by ~chi H / M ~ 3e-4 at 10 mT).

Saturation correction (stored by the map, applied by the runner): see :func:`saturation_table`
and :meth:`designkit.array.CoilArray.saturation_correction`, which returns
``saturation_current_a`` (k,) A, ``saturation_factor`` (k, n_coils) and ``core_flux_t_per_a``
(n_coils, n_coils) T/A. Column k of the linear A(p) is scaled,
``A_sat(p, I)[:, :, k] = A(p)[:, :, k] * s_k``, with ``s_k = interp(|I_k|, saturation_current_a,
saturation_factor[:, k])`` (one coil on), or per state with |I_k| replaced by the equivalent own
current ``|sum_j C[k, j] I_j| / C[k, k]`` (C = core_flux_t_per_a). s is the single-core
nonlinear (1010 steel) force at the design point over the linear one (designkit's nonlinear
axisymmetric solve); against the nonlinear axisymmetric GetDP FEM see studies/array_coupling.py.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np

from ._blas import one_blas_thread
from .constants import MU0
from .errors import BadInputError
from .pose import Pose

M_MAX = 3
"""Highest azimuthal mode kept. Against the 3-D FEM (3 x 3 array, centre coil, 12 mm above the
windings beside an edge core) m_max 2 leaves ~4 % more error in grad B than 3;
4 and 6 change nothing further (studies/array_coupling.py, convergence)."""
N1_SIDE = 40
N1_CAP = 12
"""m >= 1 charge panels on the side and on each end face (n1 = 64), graded towards the rims
with :data:`N1_GRADING`. The piecewise-constant charges converge like 1 / n1 next to the
rims' field singularity: the error in B and grad B 12-20 mm above a neighbour core (the
largest anywhere in the workspace) against the level-1 3-D FEM was, 24 + 8 + 8 panels
graded cos / sin (m_max 2): 2.9 / 5.7 % at 20 mm; 40 + 12 + 12 graded cubically: 1.2 / 1.8 %
(designkit.fem.fem3d, level 1, iron-integral outputs)."""
N1_GRADING = 3.0
"""Panel edges of the m >= 1 charges: u -> u^q towards each rim (side: both ends; end faces:
the rim), q = N1_GRADING. q = 1 (uniform) triples the error of q = 2; q = 3 is ~20 % below
q = 2 and q = 4, 5 (same panel counts)."""
FAR_DISTANCE = 8e-3
"""Points nearer than this (m) to a core's bounding cylinder always sum its panels."""
FAR_NODES = 6
"""Gauss nodes per interval of the compressed ring rules (the product rule of
designkit.core's far field, here linear in the panel values)."""
FAR_RHO = 2.6
"""Bernstein-ellipse parameter a point needs w.r.t. every interval of the compressed rules
(error ~ FAR_RHO^-12 ~ 1e-5 with 6 nodes)."""
FAR_AZIMUTHS = 24
"""Azimuths of the compressed m >= 1 ring rules. A point 8 mm above a core's rim sees the
kernel vary over ~8 mm / radius in phi: 12 azimuths left up to 8.7e-4 of A's row maxima in the
coupling's gradient rows (against 12 Gauss nodes x 256 azimuths per panel, 2-core array), 24
leave < 3.2e-5 (36: unchanged)."""
N_PHI_RING = 12
"""Azimuthal samples per collocation ring when projecting another core's / a winding's field."""
N_PHI_MAGNET = 32
"""... and when projecting the magnet's field (it can be ~5 mm from a core top).
Observation points where :meth:`CoreModel.far_mask` fails sum a core's panels (m = 0) and
3 Gauss nodes x 32 azimuths per charge panel (m >= 1); the others use compressed product
rules (FAR_NODES rings per interval, FAR_AZIMUTHS azimuths)."""


# ============================================================================ per core type
def _gauss(n):
    return np.polynomial.legendre.leggauss(n)


def _product_matrix(lo_e, hi_e, intervals, n):
    """Ring nodes and the matrix W (n_nodes, n_panels): currents of the compressed far rule.

    Same product rule as :meth:`designkit.core.CoreSolution.far_rings`, linear in the panel
    values: ring weight = W @ k.
    """
    x, _ = _gauss(n)
    xf, wf = _gauss(n + 2)
    nodes_all, rows = [], []
    for a, b in intervals:
        nodes = 0.5 * (a + b) + 0.5 * (b - a) * x
        w = np.zeros((n, len(lo_e)))
        for j in range(len(lo_e)):
            p0, p1 = max(lo_e[j], a), min(hi_e[j], b)
            if p1 <= p0:
                continue
            s = 0.5 * (p0 + p1) + 0.5 * (p1 - p0) * xf
            ws = 0.5 * (p1 - p0) * wf
            for q in range(n):
                others = np.delete(nodes, q)
                lag = np.prod((s[:, None] - others[None, :]) / (nodes[q] - others[None, :]),
                              axis=1)
                w[q, j] = np.sum(ws * lag)
        nodes_all.append(nodes)
        rows.append(w)
    return np.concatenate(nodes_all), np.vstack(rows)


def _phi_nodes_graded(levels=22, n=8):
    """Gauss nodes on (0, pi] graded geometrically towards 0 (weakly singular at phi' = 0)."""
    x, w = _gauss(n)
    edges = np.r_[0.0, math.pi * 2.0 ** -np.arange(levels, -1, -1.0)]
    ph, wt = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        ph.append(0.5 * (a + b) + 0.5 * (b - a) * x)
        wt.append(0.5 * (b - a) * w)
    return np.concatenate(ph), np.concatenate(wt)


def _graded_hi(lo, hi, n, q=N1_GRADING):
    """n + 1 edges on [lo, hi] clustered towards hi (the rim): hi - (hi - lo) (1 - u)^q."""
    u = np.linspace(0.0, 1.0, n + 1)
    e = lo + (hi - lo) * (1.0 - (1.0 - u) ** q)
    e[0], e[-1] = lo, hi
    return e


def _graded_both(lo, hi, n, q=N1_GRADING):
    """n + 1 edges on [lo, hi] clustered towards both ends ((2u)^q / 2 on each half)."""
    u = np.linspace(0.0, 1.0, n + 1)
    g = np.where(u < 0.5, 0.5 * (2.0 * u) ** q, 1.0 - 0.5 * (2.0 * (1.0 - u)) ** q)
    e = lo + (hi - lo) * g
    e[0], e[-1] = lo, hi
    return e


@dataclass(frozen=True, eq=False)
class CoreModel:
    """Discretization and self blocks of one core type (local frame of its coil).

    m = 0: panels of :func:`designkit.core._geometry` (n0 = 80). m >= 1: ``N1_SIDE`` side panels
    and ``N1_CAP`` per end face (n1 = 40), charge density constant per panel.
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
            # designkit.core's field rules, so one coil alone is exactly the single-core model;
            # the small remainder of the other columns by the compressed rules below
            from .core import CoreSolution

            ns = len(self.side)
            sol = CoreSolution(self.radius, self.side[:, 0], self.side[:, 1], x0[:ns, own_col],
                               self.discs[:, 0], self.discs[:, 1], self.discs[:, 2],
                               x0[ns:, own_col], 0.0)
            res = sol.field(pts, gradient=gradient)
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

    def _m0_rz(self, pts, rho, gradient, far):
        """Cylindrical components per m = 0 unknown: list of (n, n0) arrays."""
        from .core import _disc_nodes
        from .field.kernels import loop_rz, sheet_rz

        n = len(rho)
        z = pts[:, 2]
        if far:
            nq = len(self.far_r)
            res = loop_rz(np.tile(self.far_r, n), np.repeat(rho, nq),
                          np.repeat(z, nq) - np.tile(self.far_z, n), gradient=gradient)
            return [q.reshape(n, nq) @ self.far_w for q in res]
        side, discs = self.side, self.discs
        hh = 0.5 * (side[:, 1] - side[:, 0])
        cc = 0.5 * (side[:, 1] + side[:, 0])
        ns = len(hh)
        rs = sheet_rz(self.radius, np.tile(hh, n), np.repeat(rho, ns),
                      np.repeat(z, ns) - np.tile(cc, n), gradient=gradient)
        nq = 4
        rq, wq = _disc_nodes(discs[:, 1], discs[:, 2], nq)
        nd = len(discs)
        m = nd * nq
        rl = loop_rz(np.tile(rq.ravel(), n), np.repeat(rho, m),
                     np.repeat(z, m) - np.tile(np.repeat(discs[:, 0], nq), n), gradient=gradient)
        ww = wq.ravel()
        return [np.hstack([a.reshape(n, ns), (b.reshape(n, m) * ww).reshape(n, nd, nq)
                           .sum(axis=2)]) for a, b in zip(rs, rl)]

    def _charges(self, x1: np.ndarray, rule):
        """Point charges of the m >= 1 unknowns x1 (2 m_max n1, k): positions (nc, 3), m, and
        charges (nc, k), A m. ``rule``: (Gauss nodes per panel, azimuths) or 'far' (the
        compressed product rule, ``FAR_NODES`` rings per interval, ``FAR_AZIMUTHS``)."""
        k = x1.shape[1]
        if rule == "far":
            pos, phi, arc = self._far_charge_nodes
            nphi = len(phi)
            dens = np.zeros((len(arc), nphi, k))
            for m in range(1, self.m_max + 1):
                a = (2 * (m - 1)) * self.n1
                wc = self.far1_w @ x1[a:a + self.n1]
                ws = self.far1_w @ x1[a + self.n1:a + 2 * self.n1]
                dens += wc[:, None, :] * np.cos(m * phi)[None, :, None]
                dens += ws[:, None, :] * np.sin(m * phi)[None, :, None]
            q = dens * arc[:, None, None]
            return pos.reshape(-1, 3), q.reshape(-1, k)
        ng, nphi = rule
        pos, wt, phi = self._charge_nodes(ng, nphi)
        dens = np.zeros((self.n1, nphi, k))
        for m in range(1, self.m_max + 1):
            a = (2 * (m - 1)) * self.n1
            dens += x1[a:a + self.n1, None, :] * np.cos(m * phi)[None, :, None]
            dens += x1[a + self.n1:a + 2 * self.n1, None, :] * np.sin(m * phi)[None, :, None]
        q = wt[:, :, None, None] * dens[:, None, :, :]  # (n1, ng, nphi, k)
        return pos.reshape(-1, 3), q.reshape(-1, k)

    @staticmethod
    def _charge_kernel(pts, src, gradient, q, pointwise, chunk=128):
        """Field of point charges q (nc, k) at src (nc, 3): (n, 3, k) [, (n, 3, 3, k)]."""
        n = len(pts)
        k = q.shape[1]
        shp = (n,) if pointwise else (n, k)
        h = np.empty((n, 3) + shp[1:])
        g = np.empty((n, 3, 3) + shp[1:]) if gradient else None
        for a in range(0, n, chunk):
            comps = _unit_charge_terms(pts[a:a + chunk], src, gradient)
            if pointwise:
                qq = q[:, a:a + chunk].T  # (c, nc)
                red = np.stack([np.einsum("cs,cs->c", t, qq) for t in comps], axis=1)
            else:
                red = np.stack([t @ q for t in comps], axis=1)  # (c, ncomp, k)
            h[a:a + chunk] = red[:, :3]
            if gradient:
                _fill_symmetric(g[a:a + chunk], red)
        return (h, g) if gradient else h

    def _rz_basis_to_xyz(self, pts, rho, comps, gradient):
        """(n, nb) cylindrical component arrays -> Cartesian (n, 3, nb) [, (n, 3, 3, nb)]."""
        from .field import cylindrical_to_cartesian

        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.where(rho > 0, pts[:, 0] / np.where(rho > 0, rho, 1.0), 1.0)
            s = np.where(rho > 0, pts[:, 1] / np.where(rho > 0, rho, 1.0), 0.0)
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

    @functools.cached_property
    def _far_charge_nodes(self):
        """The compressed m >= 1 rule's charge positions (n_rings, FAR_AZIMUTHS, 3) m, their
        azimuths (FAR_AZIMUTHS,) and the rings' arc weights r dphi (n_rings,) m."""
        nphi = FAR_AZIMUTHS
        phi = 2.0 * math.pi * (np.arange(nphi) + 0.5) / nphi
        r, z = self.far1_r, self.far1_z
        pos = np.stack([r[:, None] * np.cos(phi), r[:, None] * np.sin(phi),
                        np.repeat(z[:, None], nphi, axis=1)], axis=-1)
        return pos, phi, r * (2.0 * math.pi / nphi)

    @functools.cached_property
    def _charge_nodes_cache(self):
        return {}

    def _charge_nodes(self, ng, nphi):
        """Charge quadrature: positions (n1, ng, nphi, 3), weights (n1, ng) (area / dphi)."""
        key = (ng, nphi)
        cache = self._charge_nodes_cache
        if key not in cache:
            x, w = _gauss(ng)
            mid = 0.5 * (self.lo1 + self.hi1)
            half = 0.5 * (self.hi1 - self.lo1)
            s = mid[:, None] + half[:, None] * x[None]
            ws = half[:, None] * w[None]
            phi = 2.0 * math.pi * (np.arange(nphi) + 0.5) / nphi
            side = (self.kind1 == 0)[:, None]
            r = np.where(side, self.radius, s)
            zz = np.where(side, s, np.where((self.kind1 == 1)[:, None], self.z_hi, self.z_lo))
            wt = ws * r * (2.0 * math.pi / nphi)  # dA = r ds dphi
            pos = np.stack([r[:, :, None] * np.cos(phi), r[:, :, None] * np.sin(phi),
                            np.repeat(zz[:, :, None], nphi, axis=2)], axis=-1)
            cache[key] = (pos, wt, phi)
        return cache[key]

    def _m1_field(self, pts, ng, nphi, gradient, chunk=128):
        """H [and G] of every m >= 1 unknown (unit density) at local points: (n, 3, nb) A/m
        [, (n, 3, 3, nb) A/m^2], nb = 2 m_max n1 in unknown order. The kernel is summed over
        azimuth per mode first ((nphi, 2 m_max) weights), then over the panel's nodes: the
        cost is that of the charge nodes, not nodes x unknowns. ``ng`` Gauss nodes per panel
        and ``nphi`` azimuths, or ``ng = None``: the compressed far rule (``FAR_NODES`` rings
        per interval, ``FAR_AZIMUTHS``; ring weight = far1_w @ panel densities)."""
        n1 = self.n1
        if ng is None:
            pos, phi, arc = self._far_charge_nodes
            nphi = len(phi)
            ring_w = self.far1_w * arc[:, None]  # ring -> panels, with the arc weight r dphi
        else:
            pos, wt, phi = self._charge_nodes(ng, nphi)
            ring_w = None
        modes = []
        for m in range(1, self.m_max + 1):
            modes += [np.cos(m * phi), np.sin(m * phi)]
        modes_t = np.array(modes).T.copy()  # (nphi, 2M)
        nm = modes_t.shape[1]
        src = pos.reshape(-1, 3)  # (rings * nphi, 3), phi fastest
        n_rings = len(src) // nphi
        n = len(pts)
        nb = nm * n1
        h = np.empty((n, 3, nb))
        g = np.empty((n, 3, 3, nb)) if gradient else None
        for a in range(0, n, chunk):
            p = pts[a:a + chunk]
            c = len(p)
            comps = _unit_charge_terms(p, src, gradient)
            stack = np.stack(comps, axis=1).reshape(c, len(comps), n_rings, nphi)
            red = stack @ modes_t  # (c, ncomp, rings, 2M)
            if ring_w is None:
                red = (red * wt.reshape(-1)[None, None, :, None]).reshape(
                    c, len(comps), n1, ng, nm).sum(3)
                red = np.swapaxes(red, 2, 3)
            else:
                red = np.swapaxes(red, 2, 3) @ ring_w  # (c, ncomp, 2M, n1)
            red = red.reshape(c, len(comps), nb)  # mode-major
            h[a:a + chunk] = red[:, :3]
            if gradient:
                _fill_symmetric(g[a:a + chunk], red)
        return (h, g) if gradient else h


_GRADIENT_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
"""(i, k) of dH_i/dx_k in the order of :func:`_unit_charge_terms`' components 3 to 8 (the
gradient of a curl-free field is symmetric: six entries give all nine)."""


def _unit_charge_terms(p, src, gradient):
    """Field of unit point charges (A m) at ``src`` (ns, 3), m, at the points ``p`` (c, 3), m.

    Returns a list of (c, ns) arrays, A/m per A m: H_x, H_y, H_z, then with ``gradient``
    dH_i/dx_k for (i, k) in :data:`_GRADIENT_PAIRS`, A/m^2 per A m.
    """
    d = p[:, None, :] - src[None]  # (c, ns, 3)
    r2 = np.einsum("cij,cij->ci", d, d)
    inv3 = 1.0 / (4.0 * math.pi) / (r2 * np.sqrt(r2))
    comps = [d[..., i] * inv3 for i in range(3)]
    if gradient:
        inv5 = 3.0 * inv3 / r2
        for i, k in _GRADIENT_PAIRS:
            t = -d[..., i] * d[..., k] * inv5
            comps.append(t + inv3 if i == k else t)
    return comps


def _fill_symmetric(g, red):
    """Write components 3 to 8 of ``red`` (c, ncomp, ...) into the symmetric ``g`` (c, 3, 3,
    ...) in place."""
    for j, (i, k) in enumerate(_GRADIENT_PAIRS, 3):
        g[:, i, k] = red[:, j]
        g[:, k, i] = red[:, j]


def _self_charge_matrices(radius, z_lo, z_hi, kind, lo, hi, rho_c, z_c, m_max):
    """D_m (n1, n1): normal H at the collocation points (phi = 0) per unit cos(m phi') density.

    Side panels: the z' integral is done in closed form (a uniform line charge), end-face
    panels by composite Gauss in r'; phi' by Gauss on intervals graded geometrically towards
    phi' = 0 (the integrand is weakly singular there on the panel itself). Integrands are even
    in phi' for the cos modes, so [0, pi] is doubled. The principal value on a panel's own
    surface is what the on-surface integral gives (the +-sigma/2 jump is added by the equation).
    """
    n1 = len(kind)
    ph, wph = _phi_nodes_graded()
    cph, sph = np.cos(ph), np.sin(ph)
    nrm = np.where(kind[:, None] == 0, [[1.0, 0.0, 0.0]], np.where(kind[:, None] == 1,
                                                                   [[0, 0, 1.0]], [[0, 0, -1.0]]))
    out = np.zeros((m_max, n1, n1))
    mw = np.array([np.cos(m * ph) for m in range(1, m_max + 1)]) * wph[None] * 2.0
    xg, wg = _gauss(8)
    for j in range(n1):
        if kind[j] == 0:
            # line charges at (R cos phi', R sin phi') from z = lo to hi, unit density per area:
            # lambda = R dphi'
            dx = rho_c[:, None] - radius * cph[None]  # (n1, nph)
            dy = -radius * sph[None] * np.ones((n1, 1))
            b2 = dx * dx + dy * dy
            ua = (z_c - lo[j])[:, None]
            ub = (z_c - hi[j])[:, None]
            sa, sb = np.sqrt(b2 + ua * ua), np.sqrt(b2 + ub * ub)
            # (1/b^2) [u/sqrt(b^2+u^2)] written without 0/0: u / (b^2 sqrt(b^2+u^2)) ... use
            # the identity ua/sa - ub/sb = (ua sb - ub sa) / (sa sb)
            with np.errstate(invalid="ignore", divide="ignore"):
                brk = (ua / sa - ub / sb) / b2
            brk = np.where(b2 > 0, brk, 0.0)
            hp = radius / (4 * math.pi) * brk  # per unit dphi'
            hx, hy = hp * dx, hp * dy
            hz = radius / (4 * math.pi) * (1.0 / sb - 1.0 / sa)
        else:
            zc = z_hi if kind[j] == 1 else z_lo
            pieces = np.linspace(lo[j], hi[j], 5)
            rr = np.concatenate([0.5 * (a + b) + 0.5 * (b - a) * xg for a, b in
                                 zip(pieces[:-1], pieces[1:])])
            wr = np.concatenate([0.5 * (b - a) * wg for a, b in zip(pieces[:-1], pieces[1:])])
            # (n1, nr, nph)
            dx = rho_c[:, None, None] - rr[None, :, None] * cph[None, None]
            dy = -rr[None, :, None] * sph[None, None] * np.ones((n1, 1, 1))
            dz = (z_c - zc)[:, None, None] * np.ones((1, len(rr), 1))
            r3 = (dx * dx + dy * dy + dz * dz) ** -1.5 / (4 * math.pi)
            ww = (wr * rr)[None, :, None]
            hx = (dx * r3 * ww).sum(axis=1)
            hy = (dy * r3 * ww).sum(axis=1)
            hz = (dz * r3 * ww).sum(axis=1)
        hn = hx * nrm[:, 0:1] + hy * nrm[:, 1:2] + hz * nrm[:, 2:3]  # (n1, nph)
        if kind[j] != 0:
            same = kind == kind[j]
            hn[same] = 0.0  # a flat face's charges have no normal field in its own plane
        out[:, :, j] = (hn @ mw.T).T
    return out


@functools.lru_cache(maxsize=32)
def core_model(radius: float, length: float, offset: float, mu_r: float, key: tuple,
               m_max: int = M_MAX, refine: int = 1) -> CoreModel:
    """Discretization and self blocks of a linear core (cached per core type).

    ``refine`` multiplies every panel count (convergence studies, wide cores).
    """
    from .core import N_CAP, N_SIDE, _geometry, _interface_factor, _system

    side, side_slice, discs = _geometry(radius, length, offset, n_side=N_SIDE * refine,
                                        n_cap=N_CAP * refine)
    a, _, rho0, z0 = _system(radius, side, discs, key)
    f_side = _interface_factor(np.full(len(side), mu_r), 1.0)
    below = discs[:, 3].astype(int)
    above = discs[:, 4].astype(int)
    f_disc = _interface_factor(np.where(below < 0, 1.0, mu_r), np.where(above < 0, 1.0, mu_r))
    f0 = np.concatenate([f_side, f_disc])
    self0 = np.eye(len(f0)) - f0[:, None] * a
    lo, hi = offset - length / 2, offset + length / 2
    # far rule (compressed rings), as CoreSolution.far_rings
    L = hi - lo
    end = min(0.15 * L, 2 * radius)
    rr, zz, ww = [], [], []
    nodes, w = _product_matrix(side[:, 0], side[:, 1],
                               [(lo, lo + end), (lo + end, hi - end), (hi - end, hi)], FAR_NODES)
    ns = len(side)
    rr.append(np.full_like(nodes, radius))
    zz.append(nodes)
    ww.append(np.hstack([w, np.zeros((len(nodes), len(discs)))]))
    for zp in np.unique(discs[:, 0]):
        sel = np.flatnonzero(discs[:, 0] == zp)
        nodes, w = _product_matrix(discs[sel, 1], discs[sel, 2], [(0.0, radius)], FAR_NODES)
        full = np.zeros((len(nodes), len(f0)))
        full[:, ns + sel] = w
        rr.append(nodes)
        zz.append(np.full_like(nodes, zp))
        ww.append(full)
    # m >= 1 panels
    n1s, n1c = N1_SIDE * refine, N1_CAP * refine
    e_side = _graded_both(lo, hi, n1s)
    e_cap = _graded_hi(0.0, radius, n1c)
    kind = np.r_[np.zeros(n1s, int), np.ones(n1c, int), np.full(n1c, 2)]
    lo1 = np.r_[e_side[:-1], e_cap[:-1], e_cap[:-1]]
    hi1 = np.r_[e_side[1:], e_cap[1:], e_cap[1:]]
    mid = 0.5 * (lo1 + hi1)
    rho1 = np.where(kind == 0, radius, mid)
    z1 = np.where(kind == 0, mid, np.where(kind == 1, hi, lo))
    self1 = ()
    if m_max:
        d = _self_charge_matrices(radius, lo, hi, kind, lo1, hi1, rho1, z1, m_max)
        lam2 = 2.0 * (mu_r - 1.0) / (mu_r + 1.0)
        self1 = tuple(np.eye(len(kind)) - lam2 * d[m] for m in range(m_max))
    # compressed far rule of the m >= 1 charges (same product rule as m = 0)
    r1, z1f, w1 = [], [], []
    n1 = len(kind)
    nodes, w = _product_matrix(lo1[:n1s], hi1[:n1s],
                               [(lo, lo + end), (lo + end, hi - end), (hi - end, hi)], FAR_NODES)
    r1.append(np.full_like(nodes, radius))
    z1f.append(nodes)
    w1.append(np.hstack([w, np.zeros((len(nodes), n1 - n1s))]))
    for kk, zp in ((1, hi), (2, lo)):
        sel = np.flatnonzero(kind == kk)
        nodes, w = _product_matrix(lo1[sel], hi1[sel], [(0.0, radius)], FAR_NODES)
        full = np.zeros((len(nodes), n1))
        full[:, sel] = w
        r1.append(nodes)
        z1f.append(np.full_like(nodes, zp))
        w1.append(full)
    segs = np.array([[[radius, a], [radius, b]] for a, b in
                     [(lo, lo + end), (lo + end, hi - end), (hi - end, hi)]]
                    + [[[0.0, zp], [radius, zp]] for zp in (lo, hi)])
    return CoreModel(radius, lo, hi, mu_r, m_max, side, discs, f0, self0, rho0, z0,
                     np.concatenate(rr), np.concatenate(zz), np.vstack(ww), kind, lo1, hi1,
                     rho1, z1, self1, np.concatenate(r1), np.concatenate(z1f), np.vstack(w1),
                     segs)


# ============================================================================ the array system
def _core_model_of(coil, m_max, refine=1):
    from .core import _winding_key

    c = coil.core
    return core_model(float(c.radius), float(c.length), float(c.offset),
                      float(c.relative_permeability), _winding_key(coil), int(m_max),
                      int(refine))


def _rel_key(pa, pb):
    """Hashable relative placement of pose b seen from pose a (rounded to 1e-9 m / 1e-12)."""
    rel_pos = pa.to_local(np.asarray(pb.position, dtype=float)[None])[0]
    rel_rot = pa.matrix.T @ pb.matrix
    return tuple(np.round(rel_pos, 9)) + tuple(np.round(rel_rot.ravel(), 12))


class ArraySystem:
    """All cores of a :class:`~designkit.array.CoilArray` solved together (linear cores).

    Built once per array (:meth:`designkit.array.CoilArray.coupled`). Sources are projected
    onto the cores' modes, the block system is solved by a stored LU factorization, and the
    cores' fields are evaluated from the solved unknowns.
    """

    def __init__(self, array, m_max: int = M_MAX, refine: int = 1):
        from scipy.linalg import lu_factor

        self.array = array
        self.m_max = int(m_max)
        # linear at relative_permeability (a 1010-steel core too: its saturation is the
        # separate correction, saturation_table); 'thesis-uniform' cores stay uncoupled
        self.core_index = [k for k, c in enumerate(array.coils)
                           if c.core is not None and c.core.model == "surface-current"]
        self.models = [_core_model_of(array.coils[k], self.m_max, refine)
                       for k in self.core_index]
        self.poses = [array.coils[k].pose for k in self.core_index]
        sizes = [m.n_unknowns for m in self.models]
        self.offsets = np.r_[0, np.cumsum(sizes)].astype(int)
        n = int(self.offsets[-1])
        self.factors = np.concatenate([m.factors() for m in self.models]) if n else np.zeros(0)
        mat = np.zeros((n, n))
        cache = {}
        with one_blas_thread():
            self._assemble(mat, cache)
        self.n_blocks = len(cache)
        self.n_unknowns = n
        self._lu = lu_factor(mat) if n else None
        self._coil_solution = None

    def _assemble(self, mat, cache):
        for jj, (mj, pj) in enumerate(zip(self.models, self.poses)):
            sj = slice(self.offsets[jj], self.offsets[jj + 1])
            mat[sj, sj] = mj.self_block()
            for ii, (mi, pi) in enumerate(zip(self.models, self.poses)):
                if ii == jj:
                    continue
                key = (id(mi), id(mj), _rel_key(pi, pj))
                if key not in cache:
                    cache[key] = self._cross_block(mi, pi, mj, pj)
                si = slice(self.offsets[ii], self.offsets[ii + 1])
                mat[sj, si] = -mj.factors()[:, None] * cache[key]

    # ------------------------------------------------------------------ assembly
    @staticmethod
    def _cross_block(mi, pi, mj, pj):
        """Projected field at core j's rings per unit unknown of core i, (nu_j, nu_i)."""
        ring = mj.ring_points(N_PHI_RING)  # local j
        shape = ring.shape[:2]
        glob = ring.reshape(-1, 3) @ pj.matrix.T + np.asarray(pj.position)
        loc_i = pi.to_local(glob)
        h = mi.basis_field(loc_i, fine=False)  # (n, 3, nu_i) in frame i
        rot = pj.matrix.T @ pi.matrix  # frame i -> frame j
        h = np.einsum("ab,nbu->nau", rot, h)
        return mj.project(h.reshape(shape + (3, -1)))

    def _project_global_field(self, field_fn, n_phi, near_points=None) -> np.ndarray:
        """RHS: F * projection of a source's H (callable on global points -> (n, 3, k)).

        Without ``near_points``: ``n_phi`` azimuths per ring on every core. With
        ``near_points`` (k, 3) global m, one source per column (column q sits at
        near_points[q], and ``field_fn(points, cols)`` evaluates only columns ``cols``): a
        core uses ``n_phi`` azimuths for the sources closer than 30 mm to it and
        ``N_PHI_RING`` for the others (a source that far has no significant azimuthal
        content beyond the kept modes on the core's rings). Returns (n_unknowns, k).
        """
        rows = []
        for mj, pj in zip(self.models, self.poses):
            if near_points is None:
                groups = [(n_phi, None)]
            else:
                loc = pj.to_local(near_points)
                rho = np.hypot(loc[:, 0], loc[:, 1])
                dist = np.maximum.reduce([mj.z_lo - loc[:, 2], loc[:, 2] - mj.z_hi,
                                          rho - mj.radius])
                close = dist < 0.03
                groups = [(n_phi, np.flatnonzero(close)), (N_PHI_RING, np.flatnonzero(~close))]
            out = None
            for nphi, cols in groups:
                if cols is not None and len(cols) == 0:
                    continue
                ring = mj.ring_points(nphi)
                glob = ring.reshape(-1, 3) @ pj.matrix.T + np.asarray(pj.position)
                h = field_fn(glob) if cols is None else field_fn(glob, cols)  # (n, 3, k)
                h = np.einsum("ba,nbk->nak", pj.matrix, h)  # to local j
                proj = mj.project(h.reshape(ring.shape[:2] + h.shape[1:]))
                if cols is None:
                    out = proj
                else:
                    if out is None:
                        out = np.zeros((mj.n_unknowns, len(near_points)))
                    out[:, cols] = proj
            rows.append(out)
        return self.factors[:, None] * np.concatenate(rows, axis=0)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        from scipy.linalg import lu_solve

        return lu_solve(self._lu, rhs)

    # ------------------------------------------------------------------ coil sources
    def coil_solution(self) -> np.ndarray:
        """Unknowns of all cores per ampere in each coil, (n_unknowns, n_coils) (cached)."""
        if self._coil_solution is None:
            coils = self.array.coils

            rhs = np.zeros((self.n_unknowns, len(coils)))
            cache = {}
            for jj, (mj, pj) in enumerate(zip(self.models, self.poses)):
                ring = mj.ring_points(N_PHI_RING)
                glob = ring.reshape(-1, 3) @ pj.matrix.T + np.asarray(pj.position)
                for k, c in enumerate(coils):
                    # identical windings at the same relative placement: one evaluation
                    key = (dataclasses.replace(c, core=None, pose=Pose()), id(mj),
                           _rel_key(c.pose, pj))
                    if key not in cache:
                        h = c.field(glob, 1.0, include="winding", rtol=1e-9) / MU0
                        h = h @ pj.matrix  # to local j
                        cache[key] = mj.project(h.reshape(ring.shape[:2] + (3,)))
                    rhs[self.offsets[jj]:self.offsets[jj + 1], k] = cache[key]
            self._coil_solution = self.solve(self.factors[:, None] * rhs)
        return self._coil_solution

    # ------------------------------------------------------------------ evaluation
    def core_field(self, points: np.ndarray, x: np.ndarray, gradient: bool = False, *,
                   coil_columns: bool = False):
        """B of all cores for the unknown columns x (n_unknowns, k) at global points.

        ``coil_columns``: x is :meth:`coil_solution` (column k = coil k), and each core's own
        column is evaluated by designkit.core's rules. Returns B (n, 3, k) T [, G (n, 3, 3, k)
        T/m].
        """
        return self._field(points, x, gradient, False, coil_columns)

    def core_field_pointwise(self, points: np.ndarray, x: np.ndarray, gradient: bool = False):
        """Like :meth:`core_field` but point i uses its own column x[:, i]: B (n, 3) [, G]."""
        return self._field(points, x, gradient, True)

    def _field(self, points, x, gradient, pointwise, coil_columns=False):
        with one_blas_thread():
            return self._field_impl(points, x, gradient, pointwise, coil_columns)

    def _field_impl(self, points, x, gradient, pointwise, coil_columns=False):
        pts = np.asarray(points, dtype=float)
        tail = () if pointwise else (x.shape[1],)
        b = np.zeros((len(pts), 3) + tail)
        g = np.zeros((len(pts), 3, 3) + tail) if gradient else None
        for jj, (mj, pj) in enumerate(zip(self.models, self.poses)):
            xs = x[self.offsets[jj]:self.offsets[jj + 1]]
            res = mj.field(pj.to_local(pts), xs, gradient, pointwise,
                           self.core_index[jj] if coil_columns else None)
            rot = pj.matrix
            h = res[0] if gradient else res
            if pj.is_identity_rotation:
                b += MU0 * h
                if gradient:
                    g += MU0 * res[1]
                continue
            b += MU0 * np.einsum("ab,nb...->na...", rot, h)
            if gradient:
                gl = np.einsum("ab,nbc...->nac...", rot, res[1])
                g += MU0 * np.einsum("nac...,dc->nad...", gl, rot)
        return (b, g) if gradient else b

    # ------------------------------------------------------------------ magnet source
    def magnet_solution(self, positions: np.ndarray, moment: np.ndarray,
                        magnet_size_m=None) -> np.ndarray:
        """Unknowns of all cores magnetized by the magnet at each position, (nu, n).

        ``magnet_size_m``: None for a point dipole ``moment``; (radius, length) m for the
        uniformly magnetized cylinder (axis along ``moment``, M = |m| / volume; its exact
        field, :func:`designkit.field.magnetized_cylinder_field`).
        """
        pos = np.atleast_2d(np.asarray(positions, dtype=float))
        m = np.asarray(moment, dtype=float)
        if magnet_size_m is None:
            def src(glob, cols):
                # H of the point dipole (magnet outside every core: r > 0 at ring points)
                d = glob[:, None, :] - pos[None, cols, :]  # (n, k, 3)
                r2 = np.einsum("nki,nki->nk", d, d)
                inv_r = 1.0 / np.sqrt(r2)
                mr = d @ m
                h = (3.0 * d * (mr * inv_r ** 5)[..., None] - m * (inv_r ** 3)[..., None])
                return np.swapaxes(h, 1, 2) / (4.0 * math.pi)
        else:
            from .field.kernels import sheet_rz

            a, length = (float(v) for v in magnet_size_m)
            mm = float(np.linalg.norm(m))
            u = m / mm if mm > 0 else np.array([0.0, 0.0, 1.0])
            mag = mm / (math.pi * a * a * length)

            def src(glob, cols):
                d = glob[:, None, :] - pos[None, cols, :]  # (n, k, 3)
                zl = d @ u
                rv = d - zl[..., None] * u
                rho = np.sqrt(np.einsum("nki,nki->nk", rv, rv))
                br, bz = sheet_rz(a, 0.5 * length, rho.ravel(), zl.ravel())
                br, bz = br.reshape(rho.shape), bz.reshape(rho.shape)
                with np.errstate(invalid="ignore", divide="ignore"):
                    er = np.where(rho[..., None] > 0, rv / np.where(rho > 0, rho, 1.0)[..., None],
                                  0.0)
                h = mag * (br[..., None] * er + bz[..., None] * u)
                return np.swapaxes(h, 1, 2)

        with one_blas_thread():
            rhs = self._project_global_field(src, N_PHI_MAGNET, pos)
        return self.solve(rhs)

    def magnet_load(self, positions: np.ndarray, moment: np.ndarray, magnet_size_m=None,
                    n_r: int = 4, n_phi: int = 8):
        """Force (n, 3) N and torque (n, 3) N m on the magnet from the cores it magnetizes.

        Point dipole (``magnet_size_m`` None): F = (m . grad) B_ind(p), tau = m x B_ind(p).
        Cylinder (radius, length): its uniform axial M as face charges +-M on the end faces,
        F = M [int_top B_ind dA - int_bot B_ind dA], tau = M [int_top (r - p) x B_ind dA -
        int_bot ...] (exact for a uniformly magnetized body in a curl-free field; Gauss rule
        of n_r x n_phi points per face).
        """
        pos = np.atleast_2d(np.asarray(positions, dtype=float))
        m = np.asarray(moment, dtype=float)
        x = self.magnet_solution(pos, m, magnet_size_m)
        if magnet_size_m is None:
            b, g = self.core_field_pointwise(pos, x, gradient=True)
            return np.einsum("nji,j->ni", g, m), np.cross(m[None], b)
        a, length = (float(v) for v in magnet_size_m)
        mm = float(np.linalg.norm(m))
        u = m / mm if mm > 0 else np.array([0.0, 0.0, 1.0])
        mag = mm / (math.pi * a * a * length)
        e1 = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(u, e1)
        xr, wr = _gauss(n_r)
        s = 0.5 * (xr + 1.0)
        r = a * np.sqrt(s)
        ph = 2.0 * math.pi * np.arange(n_phi) / n_phi
        R, P = np.meshgrid(r, ph, indexing="ij")
        w = np.repeat(0.5 * wr * math.pi * a * a / n_phi, n_phi)  # area weights
        disc = (R.ravel()[:, None] * (np.cos(P.ravel())[:, None] * e1
                                      + np.sin(P.ravel())[:, None] * e2))
        nq = len(w)
        force = np.zeros((len(pos), 3))
        torque = np.zeros((len(pos), 3))
        for sign in (1.0, -1.0):
            rel = disc + sign * 0.5 * length * u  # (nq, 3) about the centre
            pts = (pos[:, None, :] + rel[None]).reshape(-1, 3)
            bq = self.core_field_pointwise(pts, np.repeat(x, nq, axis=1))
            bq = bq.reshape(len(pos), nq, 3)
            force += sign * mag * np.einsum("q,nqi->ni", w, bq)
            torque += sign * mag * np.einsum("q,nqi->ni", w, np.cross(rel[None], bq))
        return force, torque


# ============================================================================ saturation
@functools.lru_cache(maxsize=8)
def _saturation_cached(coil, height_m, currents):
    c = coil.core
    lin = dataclasses.replace(coil, pose=Pose(), core=dataclasses.replace(c, bh="linear"))
    nl = dataclasses.replace(coil, pose=Pose(), core=dataclasses.replace(c, bh="steel1010"))
    pt = np.array([[0.0, 0.0, coil.length / 2 + height_m]])
    _, g_lin = lin.field(pt, 1.0, gradient=True)
    out = []
    for i in currents:
        if i <= 0:
            out.append(1.0)
            continue
        _, g = nl.field(pt, float(i), gradient=True)
        out.append(float(g[0, 2, 2] / (i * g_lin[0, 2, 2])))
    return np.array(out)


def saturation_table(coil, height_m: float = 0.03, currents_a=None) -> dict:
    """Per-coil force factor of the nonlinear 1010-steel core vs |I|, at the design point.

    ``s(|I|) = dBz/dz_nonlinear(I) / (I * dBz/dz_linear(1 A))`` of the single coil (its
    nonlinear axisymmetric solve, :class:`designkit.core.Core` with ``bh='steel1010'``, against
    the linear core at ``relative_permeability``), on the axis ``height_m`` above the coil's top
    (the design point; the vertical force on an upright magnet there scales the same way).

    How the runner applies it (the map file stores these arrays):

    * per coil, from its own current: ``A[:, :, k] *= s(|I_k|)`` with ``s`` interpolated
      linearly in |I_k| on ``current_a`` (s = 1 at 0 A). Exact for one energized coil
      (to the nonlinear solve's accuracy, see studies/array_coupling.py);
    * per state, when neighbours are energized too: the other coils change core k's flux
      (a side neighbour at 6 A changes the mid-plane flux density of the centre core by
      ~ -14 % of the centre coil's own 6 A value, linear model). Index the same table by the
      *equivalent own current* ``I_eq,k = |sum_j C[k, j] I_j| / C[k, k]`` with C the coupled
      linear mid-plane axial flux density per ampere
      (:meth:`designkit.array.CoilArray.saturation_correction` ``core_flux_t_per_a``):
      ``s_k = interp(I_eq,k, current_a, factor)`` (beyond the table: its last value).
      This assumes the core's saturation follows its mid-plane flux; it is not checked
      against a coupled nonlinear solve (none exists here).

    Returns
    -------
    dict with ``current_a`` (k,) A and ``factor`` (k,).
    """
    currents = np.arange(0.0, 6.01, 1.0) if currents_a is None else np.asarray(currents_a,
                                                                               float)
    key = dataclasses.replace(coil, pose=Pose())
    factor = _saturation_cached(key, float(height_m), tuple(float(i) for i in currents))
    return {"current_a": currents, "factor": factor}


__all__ = ["ArraySystem", "CoreModel", "core_model", "saturation_table",
           "M_MAX", "BadInputError"]
