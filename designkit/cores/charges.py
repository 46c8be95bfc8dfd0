"""The m >= 1 azimuthal modes of a core in the coupled solve: bound surface charges.

The non-axisymmetric part of a linear core's magnetization (about its own axis) is carried by
a bound surface charge density sigma = M . n (A/m) on panels of the core's meridian contour
(graded towards the rims, constant per panel), expanded in cos(m phi) and sin(m phi),
m = 1 .. m_max. Their second-kind equation
``sigma = 2 (mu_r - 1) / (mu_r + 1) (H0_n + PV[H_sigma]_n)`` has mode-diagonal self blocks
(:func:`self_charge_matrices`); the field of the charges anywhere is a sum of point charges
(:func:`unit_charge_terms`), by panel quadrature near a core and by compressed product rules
far away (:class:`ChargeModes`). Derivation and measured convergence: docs/coupling.md.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .discretization import gauss

N1_SIDE = 40
N1_CAP = 12
"""m >= 1 charge panels on the side and on each end face (n1 = 64), graded towards the rims
with :data:`N1_GRADING`. The piecewise-constant charges converge like 1 / n1 next to the
rims' field singularity (measured against the 3-D FEM: docs/coupling.md)."""
N1_GRADING = 3.0
"""Panel edges of the m >= 1 charges: u -> u^q towards each rim (side: both ends; end faces:
the rim), q = N1_GRADING (the choice among q = 1 .. 5: docs/coupling.md)."""
FAR_AZIMUTHS = 24
"""Azimuths of the compressed m >= 1 ring rules (the choice: docs/coupling.md)."""


def _phi_nodes_graded(levels=22, n=8):
    """Gauss nodes on (0, pi] graded geometrically towards 0 (weakly singular at phi' = 0)."""
    x, w = gauss(n)
    edges = np.r_[0.0, math.pi * 2.0 ** -np.arange(levels, -1, -1.0)]
    ph, wt = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        ph.append(0.5 * (a + b) + 0.5 * (b - a) * x)
        wt.append(0.5 * (b - a) * w)
    return np.concatenate(ph), np.concatenate(wt)


def graded_hi(lo, hi, n, q=N1_GRADING):
    """n + 1 edges on [lo, hi] clustered towards hi (the rim): hi - (hi - lo) (1 - u)^q."""
    u = np.linspace(0.0, 1.0, n + 1)
    e = lo + (hi - lo) * (1.0 - (1.0 - u) ** q)
    e[0], e[-1] = lo, hi
    return e


def graded_both(lo, hi, n, q=N1_GRADING):
    """n + 1 edges on [lo, hi] clustered towards both ends ((2u)^q / 2 on each half)."""
    u = np.linspace(0.0, 1.0, n + 1)
    g = np.where(u < 0.5, 0.5 * (2.0 * u) ** q, 1.0 - 0.5 * (2.0 * (1.0 - u)) ** q)
    e = lo + (hi - lo) * g
    e[0], e[-1] = lo, hi
    return e


GRADIENT_PAIRS = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
"""(i, k) of dH_i/dx_k in the order of :func:`unit_charge_terms`' components 3 to 8 (the
gradient of a curl-free field is symmetric: six entries give all nine)."""


def unit_charge_terms(p, src, gradient):
    """Field of unit point charges (A m) at ``src`` (ns, 3), m, at the points ``p`` (c, 3), m.

    Returns a list of (c, ns) arrays, A/m per A m: H_x, H_y, H_z, then with ``gradient``
    dH_i/dx_k for (i, k) in :data:`GRADIENT_PAIRS`, A/m^2 per A m.
    """
    d = [p[:, i, None] - src[None, :, i] for i in range(3)]  # contiguous (c, ns) each
    r2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    inv3 = 1.0 / (4.0 * math.pi) / (r2 * np.sqrt(r2))
    comps = [di * inv3 for di in d]
    if gradient:
        inv5 = 3.0 * inv3 / r2
        for i, k in GRADIENT_PAIRS:
            t = -d[i] * d[k] * inv5
            comps.append(t + inv3 if i == k else t)
    return comps


def fill_symmetric(g, red):
    """Write components 3 to 8 of ``red`` (c, ncomp, ...) into the symmetric ``g`` (c, 3, 3,
    ...) in place."""
    for j, (i, k) in enumerate(GRADIENT_PAIRS, 3):
        g[:, i, k] = red[:, j]
        g[:, k, i] = red[:, j]


def self_charge_matrices(radius, z_ends, panels, m_max):
    """D_m (n1, n1): normal H at the collocation points (phi = 0) per unit cos(m phi') density.

    ``radius`` and ``z_ends`` (z_lo, z_hi) of the core, m; ``panels`` (kind, lo, hi, rho_c,
    z_c): each panel's kind (0 side, 1 top, 2 bottom), its extent along the contour and its
    collocation point (m), as :func:`designkit.cores.core_model` lays them out.

    Side panels: the z' integral is done in closed form (a uniform line charge), end-face
    panels by composite Gauss in r'; phi' by Gauss on intervals graded geometrically towards
    phi' = 0 (the integrand is weakly singular there on the panel itself). Integrands are even
    in phi' for the cos modes, so [0, pi] is doubled. The principal value on a panel's own
    surface is what the on-surface integral gives (the +-sigma/2 jump is added by the equation).
    Every source panel of a kind at once: (source, collocation, phi') arrays.
    """
    z_lo, z_hi = z_ends
    kind, lo, hi, rho_c, z_c = panels
    n1 = len(kind)
    ph, wph = _phi_nodes_graded()
    cph, sph = np.cos(ph), np.sin(ph)
    # the collocation points sit at phi = 0: normal (1, 0, 0) on the side, (0, 0, +-1) on the
    # faces, so H_n = n_x H_x + n_z H_z
    nx = (kind == 0).astype(float)[None, :, None]
    nz = np.where(kind == 1, 1.0, np.where(kind == 2, -1.0, 0.0))[None, :, None]
    mw = np.array([np.cos(m * ph) for m in range(1, m_max + 1)]) * wph[None] * 2.0
    hn = np.zeros((n1, n1, len(ph)))  # (source j, collocation i, phi')
    side = np.flatnonzero(kind == 0)
    if len(side):
        # line charges at (R cos phi', R sin phi') from z = lo to hi, unit density per area:
        # lambda = R dphi'
        dx = rho_c[:, None] - radius * cph[None]  # (n1, nph)
        dy = -radius * sph[None]
        b2 = dx * dx + dy * dy
        ua = (z_c[None, :] - lo[side, None])[..., None]  # (ns, n1, 1)
        ub = (z_c[None, :] - hi[side, None])[..., None]
        sa, sb = np.sqrt(b2 + ua * ua), np.sqrt(b2 + ub * ub)
        # (1/b^2) [u/sqrt(b^2+u^2)]_b^a, without 0/0 where b = 0
        with np.errstate(invalid="ignore", divide="ignore"):
            brk = (ua / sa - ub / sb) / b2
        brk = np.where(b2 > 0, brk, 0.0)
        c = radius / (4 * math.pi)
        hn[side] = c * brk * dx * nx + c * (1.0 / sb - 1.0 / sa) * nz
    xg, wg = gauss(8)
    for j in np.flatnonzero(kind != 0):
        zc = z_hi if kind[j] == 1 else z_lo
        pieces = np.linspace(lo[j], hi[j], 5)
        rr = np.concatenate([0.5 * (a + b) + 0.5 * (b - a) * xg for a, b in
                             zip(pieces[:-1], pieces[1:])])
        wr = np.concatenate([0.5 * (b - a) * wg for a, b in zip(pieces[:-1], pieces[1:])])
        # (n1, nr, nph)
        dx = rho_c[:, None, None] - rr[None, :, None] * cph[None, None]
        dy = rr[:, None] * sph[None]  # (nr, nph): only its square enters
        dz = (z_c - zc)[:, None, None]
        r2 = dx * dx + dy * dy + dz * dz
        inv = 1.0 / (4 * math.pi) / (r2 * np.sqrt(r2))
        hn[j] = np.einsum("ikl,k->il", (dx * nx.reshape(-1, 1, 1) + dz * nz.reshape(-1, 1, 1)) * inv, wr * rr)
        hn[j, kind == kind[j]] = 0.0  # a flat face's charges have no normal field in its plane
    return np.einsum("jil,ml->mij", hn, mw)


class ChargeModes:
    """The m >= 1 charge methods of :class:`designkit.cores.core_model.CoreModel` (a mixin:
    it reads the model's radius, z_lo, z_hi, m_max, kind1, lo1, hi1, n1 and far1_* rules)."""

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
            comps = unit_charge_terms(pts[a:a + chunk], src, gradient)
            if pointwise:
                qq = q[:, a:a + chunk].T  # (c, nc)
                red = np.stack([np.einsum("cs,cs->c", t, qq) for t in comps], axis=1)
            else:
                red = np.stack([t @ q for t in comps], axis=1)  # (c, ncomp, k)
            h[a:a + chunk] = red[:, :3]
            if gradient:
                fill_symmetric(g[a:a + chunk], red)
        return (h, g) if gradient else h


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
        got = cache.get(key)  # one lookup: the map's sampling threads share the cache
        if got is not None:
            return got
        x, w = gauss(ng)
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
        cache[key] = got = (pos, wt, phi)
        return got

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
            comps = unit_charge_terms(p, src, gradient)
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
                fill_symmetric(g[a:a + chunk], red)
        return (h, g) if gradient else h
