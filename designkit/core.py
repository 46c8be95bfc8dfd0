"""Soft-iron cores and the models of their magnetization.

Models (``Core.model``):

``"surface-current"`` (default)
    Exact for a linear, homogeneous core up to discretization: the magnetization of a linear
    core with no free current inside has no curl (J_b = curl M = chi curl H = 0), so the core's
    whole field -- inside and outside -- is that of its *bound surface current*
    ``K = M x n`` on its boundary, an azimuthal current density on the side (K = M_z) and on the
    end faces (K = -/+ M_r). The interface condition ``M = chi H`` on the inside of the surface
    gives a second-kind integral equation for K along the meridian contour (side + end faces):

        K(s) = 2 (mu_in - mu_out) / (mu_in + mu_out) * ( H0_t(s) + PV[B_K]_t(s) / mu0 )

    (t = n x phi_hat; the principal-value mean of a current sheet's tangential field, on which
    the field jumps by K). Collocation with piecewise-constant K on panels graded towards the
    rims (where K has the r^(-1/3) corner singularity of a high-mu edge): side panels are exact
    current sheets (:func:`designkit.field.kernels.sheet_rz`), end-face panels are Gauss
    rules of loops (:func:`designkit.field.kernels.loop_rz`). Solved once per design and cached.
    Validated against GetDP (:mod:`designkit.fem`, ``studies/core_vs_fem.py``).

    With a B-H curve (``Core.bh = "steel1010"``) the core is cut into axial slices, each with its
    own secant permeability mu_k = B_k / (mu0 H(B_k)) from the slice-averaged |B|; interfaces
    between slices carry the bound current of the jump in tangential M (same equation with
    mu_in, mu_out of the two slices); a damped fixed-point iteration on 1/mu_k converges in
    ~10-30 solves.

``"thesis-uniform"``
    Thesis appendix A.2.3: the core is uniformly magnetized along its axis with
    ``M = B0 (mu_r - 1) / (mu0 (1 + N (mu_r - 1)))``, where ``B0`` is the winding's flux density at
    the core centre and ``N`` is the *magnetometric* demagnetizing factor of the cylinder for
    chi -> 0 (volume average of the demagnetizing field of a uniformly magnetized cylinder,
    Chen, Brug & Goldfarb, IEEE Trans. Magn. 27, 3601 (1991)); designkit computes it by
    Nagaoka's exact closed form (:func:`demagnetizing_factor`). The
    field outside the core equals a current sheet K = M on its side
    (:func:`designkit.field.magnetized_cylinder_field`). FIELD_MATH.md explains why this model is
    only a first estimate. It ignores ``bh`` (linear), and warns when its M passes the knee.

Field evaluation (:meth:`CoreSolution.field`): the solved currents are grouped (the side in
stretches no longer than four core radii plus the two end stretches; each end face or slice
interface). For a point and a group, the kernel (loop field as a function of the source
coordinate s along the group) is analytic except where the source ring would pass through the
point: s* = z +- i |R - rho| for the side, r* = rho +- i |z - z_face| for a face. The Bernstein
ellipse of the group's interval through s* (parameter rho_s; the bounds use the half-way ellipse
rho = (1 + rho_s) / 2) bounds the error of n-node interpolation by 4 rho^-n / (rho - 1) and of
n-node Gauss quadrature by 64/15 rho^-2n / (rho^2 - 1), relative to the group's contribution
(Trefethen, ATAP ch. 8, 19). Per point and group the cheapest of: a compressed product rule of
4-24 rings (interpolation bound <= :data:`EVAL_RTOL`), else the group's panels: side panels are
closed-form current sheets (exact everywhere), face panels 4-node Gauss rules where their
quadrature bound holds, else a Gauss rule graded geometrically towards the point's projection
(pieces delta, 2 delta, 4 delta, ... with delta the distance to the panel: every piece then sees
the singularity through an ellipse rho_s >= 3.7, 10 nodes each). All distances are in units of
the group's or panel's own size, so the choice holds for any geometry and any point (inside the
core, on its faces: finite principal values). Validated against GetDP all around the coil
(``studies/core_vs_fem.py``, :func:`designkit.fem.compare.probe_set`).

Inductance: the extra flux linkage of the winding due to the core, per unit current, is
``sum over the core's current rings of K ds * Phi_w(r, z) / I^2`` (reciprocity: the mutual
inductance of a ring and the winding is the winding's flux through the ring per ampere),
:meth:`Core.extra_inductance`.

B-H curve ``"steel1010"``: the "1010 Steel" curve of the FEMM 4.2 material library
(D. Meeker, femm.info; the same table is in MPEL/MotorProto ``Materials/Steel1010.m``), extended
beyond 318 kA/m with slope mu0; initial mu_r ~ 670, maximum ~ 930, knee ~ 1.5 T.
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np

from . import _validate as v
from .design import MU0
from .errors import BadInputError

if TYPE_CHECKING:  # pragma: no cover
    from .coil import Coil

CoreModel = Literal["surface-current", "thesis-uniform"]
CORE_MODELS: tuple[str, ...] = ("surface-current", "thesis-uniform")
BHCurveName = Literal["linear", "steel1010"]
BH_CURVES: tuple[str, ...] = ("linear", "steel1010")

# FEMM 4.2 material library, "1010 Steel" (H in A/m, B in T); last point extends with slope mu0.
STEEL1010_H = np.array([0.0, 238.7, 318.3, 358.1, 437.7, 477.5, 636.6, 795.8, 1114.1, 1273.2,
                        1591.5, 2228.2, 3183.1, 4774.6, 6366.2, 7957.7, 15915.5, 47746.5, 63662.0,
                        79577.5, 159155.0, 318310.0, 1909860.0])
STEEL1010_B = np.array([0.0, 0.2003, 0.3204, 0.40045, 0.50055, 0.5606, 0.7908, 0.9310, 1.1014,
                        1.2016, 1.302, 1.4028, 1.524, 1.626, 1.698, 1.73, 1.87, 2.04, 2.07, 2.095,
                        2.2, 2.4, 4.4])
KNEE_T = 1.5
"""Flux density above which low-carbon steel is past the knee of its B-H curve, T."""


class SaturationWarning(UserWarning):
    """The core's flux density passes the knee of the B-H curve: a linear model overestimates."""


def steel1010_h(b: np.ndarray) -> np.ndarray:
    """H(|B|) of the 1010 steel curve, A/m (linear interpolation; slope mu0 beyond the table)."""
    b = np.abs(np.asarray(b, dtype=float))
    h = np.interp(b, STEEL1010_B, STEEL1010_H)
    over = b > STEEL1010_B[-1]
    h[over] = STEEL1010_H[-1] + (b[over] - STEEL1010_B[-1]) / MU0
    return h


def steel1010_mu_r(b: np.ndarray) -> np.ndarray:
    """Secant relative permeability B / (mu0 H) of the 1010 steel curve at |B| (T)."""
    b = np.maximum(np.abs(np.asarray(b, dtype=float)), 1e-3)
    return b / (MU0 * steel1010_h(b))


@dataclass(frozen=True)
class Core:
    """Cylindrical soft-iron core on the coil axis.

    Parameters
    ----------
    radius : float, m
    length : float, m
    relative_permeability : float
        Linear relative permeability mu_r (>= 1); used when ``bh == "linear"``.
    offset : float, m
        Axial position of the core centre relative to the winding centre (local frame).
    model : {'surface-current', 'thesis-uniform'}
        Magnetization model (module docs). Default: the FEM-validated surface-current model.
    bh : {'linear', 'steel1010'}
        Material law: linear ``relative_permeability`` or the 1010 steel B-H curve (saturation).
    """

    radius: float
    length: float
    relative_permeability: float = 1000.0
    offset: float = 0.0
    model: CoreModel = "surface-current"
    bh: BHCurveName = "linear"

    def __post_init__(self):
        v.positive("core.radius", self.radius)
        v.positive("core.length", self.length)
        v.in_range("core.relative_permeability", self.relative_permeability, 1.0, 1e7)
        v.finite("core.offset", self.offset, "m")
        if self.model not in CORE_MODELS:
            raise BadInputError("core.model", f"one of {CORE_MODELS}", self.model)
        if self.bh not in BH_CURVES:
            raise BadInputError("core.bh", f"one of {BH_CURVES}", self.bh)

    # ------------------------------------------------------------------ thesis model
    def magnetization(self, coil: "Coil", current: float) -> float:
        """Uniform axial magnetization of the thesis model, A/m.

        Applied field: the winding's B0 at the core centre; N: magnetometric factor, chi -> 0.
        """
        h0 = _applied_h(_winding_key(coil), np.array([0.0]), np.array([self.offset]))[1][0]
        n = demagnetizing_factor(self.length / (2 * self.radius))
        chi = self.relative_permeability - 1.0
        return float(h0 * current * chi / (1.0 + n * chi))

    # ------------------------------------------------------------------ public API
    def solution(self, coil: "Coil", current: float = 1.0) -> "CoreSolution":
        """Bound-current solution of the core driven by ``coil`` at ``current`` (A).

        Linear cores: the solution per ampere (cached, scaled by ``current``). Nonlinear
        (``bh='steel1010'``): solved at that current (cached by current).
        """
        current = v.finite("current", current, "A")
        key = _winding_key(coil)
        if self.model == "thesis-uniform":
            m1 = self.magnetization(coil, 1.0)
            sol = _uniform_solution(self.radius, self.length, self.offset, m1)
            return sol.scaled(current, self)
        if self.bh == "linear":
            sol = _solve_linear(self.radius, self.length, self.offset,
                                float(self.relative_permeability), key)
            return sol.scaled(current, self)
        sol = _solve_nonlinear(self.radius, self.length, self.offset, self.bh, key,
                               round(float(abs(current)), 12))
        return sol.scaled(current, self)

    def field_local(self, points_local: np.ndarray, coil: "Coil", current: float, *,
                    gradient: bool = False):
        """Core field at points given in the winding's local frame.

        Parameters
        ----------
        points_local : ndarray, shape (n, 3), m
        coil : Coil
            The coil whose winding drives the core.
        current : float, A

        Returns
        -------
        B : ndarray (n, 3), T, and G : ndarray (n, 3, 3), T/m when gradient=True.
        Warns :class:`SaturationWarning` when a linear model's core flux density exceeds
        :data:`KNEE_T`.
        """
        sol = self.solution(coil, current)
        sol.warn_if_saturated()
        return sol.field(points_local, gradient=gradient)

    def extra_inductance(self, coil: "Coil", current: float | None = None) -> float:
        """Inductance the core adds to the winding's air-core inductance, H.

        Flux linkage of the core's field with the winding's turns per unit current, for this
        core's model. For ``bh='steel1010'`` it is the secant (flux-linkage / current) value at
        ``current`` (A; default: the small-signal limit at 0.01 A).
        """
        if self.bh != "linear" and self.model != "thesis-uniform":
            i = 0.01 if current is None else abs(v.finite("current", current, "A"))
            i = max(i, 1e-6)
            return self.solution(coil, i).flux_linkage(coil) / i
        return self.solution(coil, 1.0).flux_linkage(coil)

    def peak_flux_density(self, coil: "Coil", current: float) -> float:
        """Largest slice-averaged |B| in the core at ``current``, T (saturation check)."""
        return self.solution(coil, current).peak_b


# ====================================================================== solution object
@dataclass(frozen=True)
class CoreSolution:
    """Bound azimuthal surface currents of a solved core (A/m), in the winding's local frame.

    ``side_*``: current-sheet panels at r = radius spanning [z_lo, z_hi]; ``disc_*``: annular
    panels in planes z with [r_lo, r_hi]; ``k_*`` the azimuthal surface current density.
    """

    radius: float
    side_z_lo: np.ndarray
    side_z_hi: np.ndarray
    k_side: np.ndarray
    disc_z: np.ndarray
    disc_r_lo: np.ndarray
    disc_r_hi: np.ndarray
    k_disc: np.ndarray
    peak_b: float
    linear_model: bool = True
    model: str = "surface-current"

    def scaled(self, factor: float, core: Core) -> "CoreSolution":
        return CoreSolution(self.radius, self.side_z_lo, self.side_z_hi, self.k_side * factor,
                            self.disc_z, self.disc_r_lo, self.disc_r_hi, self.k_disc * factor,
                            abs(self.peak_b * factor), core.bh == "linear" or
                            core.model == "thesis-uniform", core.model)

    def warn_if_saturated(self) -> None:
        if self.linear_model and self.peak_b > KNEE_T:
            warnings.warn(
                f"core flux density {self.peak_b:.2f} T exceeds the {KNEE_T} T knee of "
                "low-carbon steel: the linear core model overestimates the field; for the "
                "saturating B-H curve use Core(bh='steel1010') or, in a design file, "
                "[core] bh = \"steel1010\"", SaturationWarning, stacklevel=4)

    def field(self, points_local: np.ndarray, *, gradient: bool = False,
              rule: Literal["auto", "panels"] = "auto"):
        """B (n, 3) T [, G (n, 3, 3) T/m] of the bound currents at local Cartesian points.

        ``rule='auto'``: for every point and every *source group* (three stretches of the side,
        each end face or slice interface) the cheapest quadrature whose error bound holds at
        that point is used (module section "Field evaluation"): a compressed product rule of
        6, 10 or 16 rings per group when the point is far from the group *in units of the
        group's own length*, else the group's exact panels (side: closed-form current sheets;
        faces: Gauss rules of loops, refined geometrically towards the point's projection when
        the point is near the panel). ``'panels'`` always sums the panels (with the same near
        refinement): the reference for the compressed rules.
        """
        p = np.asarray(points_local, dtype=float)
        rho = np.hypot(p[:, 0], p[:, 1])
        z = p[:, 2]
        nout = 7 if gradient else 2
        if rule not in ("auto", "panels"):
            raise BadInputError("rule", "'auto' or 'panels'", rule)
        if rule == "panels" or len(self.k_disc) == 0:
            comps = _currents_rz(self, rho, z, gradient)
            return _rz_to_xyz(p, rho, comps, gradient, MU0)
        from .field.kernels import loop_rz

        comps = [np.zeros(len(z)) for _ in range(nout)]
        ring_pt, ring_r, ring_z, ring_w = [], [], [], []
        for grp in self.groups():
            # singularity of the kernel as a function of the source coordinate: where the
            # source ring would pass through the point (complex for points off the contour)
            if grp["kind"] == "side":
                s = z + 1j * np.abs(self.radius - rho)
            else:
                s = rho + 1j * np.abs(z - grp["fixed"])
            bound_rho = _usable_rho(grp["lo"], grp["hi"], s)
            # a face's kernel grows like r'^2 (its dipole moment) off the interval: its size on
            # the ellipse exceeds that on [0, R] by up to the Chebyshev growth ((rho+1/rho)/2)^2
            growth = (0.5 * (bound_rho + 1.0 / bound_rho)) ** 2 if grp["kind"] == "disc" else 1.0
            todo = np.ones(len(z), dtype=bool)
            for nodes, (rq, zq, wq) in grp["rules"].items():
                sel = todo & (_interp_bound(bound_rho, nodes) * grp["cancel"] * growth
                              <= EVAL_RTOL)
                if not np.any(sel):
                    continue
                todo &= ~sel
                idx = np.flatnonzero(sel)
                ring_pt.append(np.repeat(idx, len(rq)))
                ring_r.append(np.tile(rq, len(idx)))
                ring_z.append(np.tile(zq, len(idx)))
                ring_w.append(np.tile(wq, len(idx)))
            if np.any(todo):
                idx = np.flatnonzero(todo)
                near = _panels_rz(self, grp["side"], grp["disc"], rho[idx], z[idx], gradient)
                for q in range(nout):
                    comps[q][idx] += near[q]
        if ring_pt:
            pt = np.concatenate(ring_pt)
            ww = np.concatenate(ring_w)
            res = loop_rz(np.concatenate(ring_r), rho[pt], z[pt] - np.concatenate(ring_z),
                          gradient=gradient)
            for q in range(nout):
                comps[q] += np.bincount(pt, weights=res[q] * ww, minlength=len(z))
        return _rz_to_xyz(p, rho, comps, gradient, MU0)

    def groups(self) -> list[dict]:
        """Source groups of the compressed rule (cached on the instance).

        Each: ``kind`` ('side' or 'disc'), source-coordinate interval ``lo``, ``hi`` (z for the
        side, r for a face), ``fixed`` (the face's z), the panel indices ``side`` / ``disc`` it
        covers, and ``rules``: {nodes: (r, z, current per ring)} product rules (the loop field
        interpolated at Gauss nodes, the piecewise-constant K with its rim singularity
        integrated exactly in the weights).
        """
        cached = self.__dict__.get("_groups")
        if cached is not None:
            return cached
        lo, hi = float(self.side_z_lo.min()), float(self.side_z_hi.max())
        length = hi - lo
        end = min(0.15 * length, 2 * self.radius)
        # group edges on panel edges, so a group that falls back to panels owns whole panels
        edges = np.unique(np.concatenate([self.side_z_lo, self.side_z_hi]))
        # middle stretch cut into pieces <= 4 radii: a group's length sets how far away a
        # point must be for its compressed rule, so shorter groups serve nearer points
        n_mid = max(1, int(math.ceil((length - 2 * end) / (4 * self.radius))))
        want = np.concatenate([[lo], lo + end + (length - 2 * end) * np.arange(n_mid + 1)
                               / n_mid, [hi]])
        cut = sorted(set(float(edges[np.argmin(np.abs(edges - c))]) for c in want))
        out = []
        mid = 0.5 * (self.side_z_lo + self.side_z_hi)
        for a, b in zip(cut[:-1], cut[1:]):
            sel = np.flatnonzero((mid > a) & (mid < b))
            out.append({"kind": "side", "lo": a, "hi": b, "fixed": self.radius, "side": sel,
                        "disc": np.zeros(0, dtype=int),
                        "cancel": _cancellation(self.k_side[sel], self.side_z_hi[sel]
                                                - self.side_z_lo[sel]),
                        "rules": {n: _product_rule(self.side_z_lo[sel], self.side_z_hi[sel],
                                                   self.k_side[sel], a, b, n, "side",
                                                   self.radius) for n in FAR_NODES}})
        for zp in np.unique(self.disc_z):
            sel = np.flatnonzero(self.disc_z == zp)
            r_lo = float(self.disc_r_lo[sel].min())
            r_hi = float(self.disc_r_hi[sel].max())
            # a face's far field is that of its dipole moment: weights ~ r^2 dr
            mom = (self.disc_r_hi[sel] ** 3 - self.disc_r_lo[sel] ** 3) / 3.0
            out.append({"kind": "disc", "lo": r_lo, "hi": r_hi, "fixed": float(zp),
                        "side": np.zeros(0, dtype=int), "disc": sel,
                        "cancel": max(_cancellation(self.k_disc[sel], mom),
                                      _cancellation(self.k_disc[sel], self.disc_r_hi[sel]
                                                    - self.disc_r_lo[sel])),
                        "rules": {n: _product_rule(self.disc_r_lo[sel], self.disc_r_hi[sel],
                                                   self.k_disc[sel], r_lo, r_hi, n, "disc",
                                                   float(zp)) for n in FAR_NODES}})
        object.__setattr__(self, "_groups", out)  # frozen dataclass: cache the derived rules
        return out

    def flux_linkage(self, coil: "Coil") -> float:
        """Flux linkage of these currents with the winding, Wb (per the coil's turns)."""
        key = _winding_key(coil)
        total = 0.0
        xg, wg = np.polynomial.legendre.leggauss(4)
        if len(self.k_side):
            h = 0.5 * (self.side_z_hi - self.side_z_lo)
            c = 0.5 * (self.side_z_hi + self.side_z_lo)
            zq = (c[:, None] + h[:, None] * xg[None, :]).ravel()
            wq = (h[:, None] * wg[None, :]).ravel() * np.repeat(self.k_side, len(xg))
            phi = _disc_flux(key, np.full_like(zq, self.radius), zq)
            total += float(np.sum(wq * phi))
        if len(self.k_disc):
            h = 0.5 * (self.disc_r_hi - self.disc_r_lo)
            c = 0.5 * (self.disc_r_hi + self.disc_r_lo)
            rq = (c[:, None] + h[:, None] * xg[None, :]).ravel()
            zq = np.repeat(self.disc_z, len(xg))
            wq = (h[:, None] * wg[None, :]).ravel() * np.repeat(self.k_disc, len(xg))
            phi = _disc_flux(key, rq, zq)
            total += float(np.sum(wq * phi))
        return total


EVAL_RTOL = 1e-5
"""Quadrature error bound of the field evaluation, relative to the size of each source group's
contribution (module section "Field evaluation"); far below the model's discretization error."""
FAR_NODES = (4, 6, 8, 12, 16, 24)
"""Ring counts of the compressed product rules, tried in this order."""
PANEL_NODES = 4
"""Gauss nodes per end-face panel when the point is far from the panel (else refined)."""
NEAR_NODES = 10
"""Gauss nodes per piece of the geometric near-point refinement of a face panel."""
RHO_CAP = 1e3


def _usable_rho(lo, hi, s):
    """Usable Bernstein-ellipse parameter of [lo, hi] for the kernel singularity ``s`` (complex).

    rho_s is the ellipse (foci lo, hi) through s; the bounds use the ellipse half-way in,
    rho = (1 + rho_s) / 2, on which the kernel stays within a small factor of its size on the
    interval (Trefethen, Approximation Theory and Approximation Practice, ch. 8 and 19)."""
    x = (2.0 * np.asarray(s) - lo - hi) / (hi - lo)
    w = x + np.sqrt(x - 1.0 + 0j) * np.sqrt(x + 1.0 + 0j)
    r = np.abs(w)
    r = np.maximum(r, 1.0 / np.maximum(r, 1e-300))
    return np.minimum(0.5 * (1.0 + r), RHO_CAP)


def _cancellation(k, w, cap=1e4):
    """sum |k| w / |sum k w| (>= 1, capped): the interpolation error scales with the integral of
    |K| while the group's contribution may be the much smaller integral of K (currents of both
    signs), so the bound is multiplied by this factor."""
    total = abs(float(np.sum(k * w)))
    mag = float(np.sum(np.abs(k) * w))
    return min(mag / total, cap) if total > 0 else cap


def _interp_bound(rho, n):
    """Relative error bound of n-point Gauss-node interpolation: 4 rho^-n / (rho - 1)."""
    with np.errstate(divide="ignore", over="ignore"):
        return 4.0 * rho ** (-float(n)) / np.maximum(rho - 1.0, 1e-300)


def _quad_bound(rho, n):
    """Relative error bound of n-point Gauss-Legendre quadrature: 64/15 rho^-2n / (rho^2 - 1)."""
    with np.errstate(divide="ignore", over="ignore"):
        return 64.0 / 15.0 * rho ** (-2.0 * n) / np.maximum(rho * rho - 1.0, 1e-300)


def _product_rule(lo_e, hi_e, k, a, b, n, kind, fixed):
    """n rings at the Gauss nodes of [a, b] whose weights integrate the piecewise-constant K
    (panels [lo_e, hi_e]) times the Lagrange interpolant of the loop field exactly.

    Returns (r, z, current per ring) arrays, m and A."""
    x, _ = np.polynomial.legendre.leggauss(n)
    xf, wf = np.polynomial.legendre.leggauss(n + 2)  # exact for K * (degree n-1) per panel
    nodes = 0.5 * (a + b) + 0.5 * (b - a) * x
    p0 = np.maximum(lo_e, a)
    p1 = np.minimum(hi_e, b)
    keep = p1 > p0
    p0, p1, kk = p0[keep], p1[keep], k[keep]
    s = (0.5 * (p0 + p1)[:, None] + 0.5 * (p1 - p0)[:, None] * xf[None, :]).ravel()
    ws = ((0.5 * (p1 - p0) * kk)[:, None] * wf[None, :]).ravel()
    # Lagrange basis at s, scaled to [-1, 1] for conditioning
    t = (2.0 * s - a - b) / (b - a)
    lag = np.ones((len(s), n))
    for q in range(n):
        for j in range(n):
            if j != q:
                lag[:, q] *= (t - x[j]) / (x[q] - x[j])
    weights = ws @ lag
    if kind == "side":
        return np.full(n, fixed), nodes, weights
    return nodes, np.full(n, fixed), weights


def _near_rule(lo, hi, s_re, delta, n=NEAR_NODES):
    """Gauss rule on [lo, hi] graded geometrically towards x0 = clip(s_re): pieces of length
    delta, 2 delta, 4 delta, ... on each side, so every piece sees the singularity (at distance
    >= delta from x0) through an ellipse of parameter >= 3.7 (module docs). Returns (x, w)."""
    x, w = np.polynomial.legendre.leggauss(n)
    x0 = min(max(s_re, lo), hi)
    edges = [x0]
    step = delta
    while edges[-1] < hi:
        edges.append(min(edges[-1] + step, hi))
        step *= 2.0
    left = [x0]
    step = delta
    while left[-1] > lo:
        left.append(max(left[-1] - step, lo))
        step *= 2.0
    e = np.array(left[::-1] + edges[1:])
    e = e[np.concatenate([[True], np.diff(e) > 0])]
    a, b = e[:-1], e[1:]
    xs = (0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * x[None, :]).ravel()
    ws = (0.5 * (b - a)[:, None] * w[None, :]).ravel()
    return xs, ws


def _panels_rz(sol, side_idx, disc_idx, rho, z, gradient):
    """Exact panel sum of the given side and face panels per mu0 at (rho, z).

    Side panels: closed-form current sheets. Face panels: PANEL_NODES-point Gauss rules of
    loops where their quadrature bound holds, else the geometric near rule."""
    from .field.kernels import loop_rz, sheet_rz

    n = rho.shape[0]
    nout = 7 if gradient else 2
    acc = [np.zeros(n) for _ in range(nout)]
    if n == 0:
        return acc
    if len(side_idx):
        lo, hi, k = sol.side_z_lo[side_idx], sol.side_z_hi[side_idx], sol.k_side[side_idx]
        h = 0.5 * (hi - lo)
        c = 0.5 * (hi + lo)
        ns = len(h)
        res = sheet_rz(sol.radius, np.tile(h, n), np.repeat(rho, ns),
                       np.repeat(z, ns) - np.tile(c, n), gradient=gradient)
        kk = np.tile(k, n)
        for q in range(nout):
            acc[q] += (res[q] * kk).reshape(n, ns).sum(axis=1)
    if len(disc_idx):
        r_lo, r_hi = sol.disc_r_lo[disc_idx], sol.disc_r_hi[disc_idx]
        zp, kd = sol.disc_z[disc_idx], sol.k_disc[disc_idx]
        nd = len(disc_idx)
        dz = np.abs(z[:, None] - zp[None, :])
        rho_b = _usable_rho(r_lo[None, :], r_hi[None, :], rho[:, None] + 1j * dz)
        ok = _quad_bound(rho_b, PANEL_NODES) <= EVAL_RTOL
        nq = PANEL_NODES
        rq, wq = _disc_nodes(r_lo, r_hi, nq)
        wk = (wq * kd[:, None])  # (nd, nq)
        m = nd * nq
        res = loop_rz(np.tile(rq.ravel(), n), np.repeat(rho, m),
                      np.repeat(z, m) - np.tile(np.repeat(zp, nq), n), gradient=gradient)
        ww = (ok[:, :, None] * wk[None, :, :]).ravel()
        for q in range(nout):
            acc[q] += (res[q] * ww).reshape(n, m).sum(axis=1)
        bad_i, bad_j = np.nonzero(~ok)
        if len(bad_i):
            xs, ws, pt, zs = [], [], [], []
            for i, j in zip(bad_i, bad_j):
                span = r_hi[j] - r_lo[j]
                gap = max(r_lo[j] - rho[i], rho[i] - r_hi[j], 0.0)
                # floor: a point on the face itself gets the principal value (finite)
                delta = max(dz[i, j], gap, 1e-9 * span)
                x, w = _near_rule(r_lo[j], r_hi[j], rho[i], delta)
                xs.append(x)
                ws.append(w * kd[j])
                pt.append(np.full(len(x), i))
                zs.append(np.full(len(x), zp[j]))
            xs, ws, pt, zsrc = (np.concatenate(a) for a in (xs, ws, pt, zs))
            res = loop_rz(xs, rho[pt], z[pt] - zsrc, gradient=gradient)
            for q in range(nout):
                acc[q] += np.bincount(pt, weights=res[q] * ws, minlength=n)
    return acc


# ====================================================================== winding (applied) field
def _winding_key(coil: "Coil") -> tuple[float, float, float, int]:
    return (float(coil.inner_radius), float(coil.outer_radius), float(coil.length),
            int(coil.turns))


def _applied_h(key, rho, z, gradient=False):
    """The winding's H = B/mu0 per ampere at local (rho, z): (hr, hz) in 1/m [, derivatives]."""
    from .field.winding import winding_rz

    ri, ro, length, turns = key
    j = turns / ((ro - ri) * length)
    res = winding_rz(ri, ro, length / 2, np.ascontiguousarray(rho, dtype=float),
                     np.ascontiguousarray(z, dtype=float), gradient=gradient, rtol=1e-9)
    return tuple(np.asarray(r) * j for r in res)


def _disc_flux(key, r, z, nodes: int = 10) -> np.ndarray:
    """Flux of the winding's B through the discs of radius r at heights z, Wb per ampere.

    Gauss-Legendre in s = (r'/r)^2 (area coordinate): the integrand B_z is smooth inside the
    bore, and r <= inner radius here.
    """
    x, w = np.polynomial.legendre.leggauss(nodes)
    s = 0.5 * (x + 1.0)
    rr = (np.sqrt(s)[None, :] * np.asarray(r)[:, None]).ravel()
    zz = np.repeat(np.asarray(z), nodes)
    hz = _applied_h(key, rr, zz)[1].reshape(-1, nodes)
    # int_0^r Bz 2 pi r' dr' = pi r^2 int_0^1 Bz ds
    return MU0 * math.pi * np.asarray(r) ** 2 * (hz @ (0.5 * w))


# ====================================================================== kernels of the currents
_GL4 = np.polynomial.legendre.leggauss(4)


def _disc_nodes(r_lo, r_hi, n):
    x, w = np.polynomial.legendre.leggauss(n)
    h = 0.5 * (r_hi - r_lo)
    c = 0.5 * (r_hi + r_lo)
    return c[:, None] + h[:, None] * x[None, :], h[:, None] * w[None, :]


def _currents_rz(sol: CoreSolution, rho, z, gradient):
    """Sum of all panels' fields per mu0 at (rho, z): list of the 2 or 7 rz components."""
    return _panels_rz(sol, np.arange(len(sol.k_side)), np.arange(len(sol.k_disc)), rho, z,
                      gradient)


def _rz_to_xyz(p, rho, comps, gradient, scale):
    """Cylindrical components (per unit) -> Cartesian B (n,3) and G (n,3,3), times ``scale``."""
    from .field import cylindrical_to_cartesian

    with np.errstate(invalid="ignore", divide="ignore"):
        cphi = np.where(rho > 0, p[:, 0] / np.where(rho > 0, rho, 1.0), 1.0)
        sphi = np.where(rho > 0, p[:, 1] / np.where(rho > 0, rho, 1.0), 0.0)
    return cylindrical_to_cartesian(cphi, sphi, scale, comps[:7] if gradient else comps[:2],
                                    gradient)


# ====================================================================== solvers
N_SIDE = 48
N_CAP = 16
N_SLICES = 11


def _graded(lo, hi, n, ends="both"):
    """Panel edges on [lo, hi] clustered like Chebyshev points towards the rims."""
    u = np.linspace(0.0, 1.0, n + 1)
    if ends == "both":
        t = 0.5 * (1.0 - np.cos(np.pi * u))
    else:  # clustered at hi only
        t = np.sin(0.5 * np.pi * u)
    e = lo + (hi - lo) * t
    e[0], e[-1] = lo, hi
    return e


def _uniform_solution(radius, length, offset, m1) -> CoreSolution:
    lo, hi = offset - length / 2, offset + length / 2
    b_in = MU0 * m1  # order of the core's own flux density per ampere (flag only)
    return CoreSolution(radius, np.array([lo]), np.array([hi]), np.array([m1]), np.zeros(0),
                        np.zeros(0), np.zeros(0), np.zeros(0), abs(b_in), True, "thesis-uniform")


def _geometry(radius, length, offset, slice_edges=None, n_side=N_SIDE, n_cap=N_CAP):
    """Panels of the core contour (and of the interfaces between axial slices)."""
    lo, hi = offset - length / 2, offset + length / 2
    if slice_edges is None:
        slice_edges = np.array([lo, hi])
    nsl = len(slice_edges) - 1
    side_edges = []
    side_slice = []
    per = max(4, int(round(n_side / nsl))) if nsl > 1 else n_side
    for k in range(nsl):
        if nsl == 1:
            e = _graded(slice_edges[k], slice_edges[k + 1], per, "both")
        else:
            # slices: grade only at the core's ends, uniform-ish elsewhere
            e = _graded(slice_edges[k], slice_edges[k + 1], per, "both" if k in (0, nsl - 1)
                        else "both")
        side_edges.append(np.column_stack([e[:-1], e[1:]]))
        side_slice.append(np.full(len(e) - 1, k))
    side = np.concatenate(side_edges)
    side_slice = np.concatenate(side_slice)
    re = _graded(0.0, radius, n_cap, "hi")
    discs = []  # (z, r_lo, r_hi, slice_below, slice_above)  (-1 = air)
    for j, ze in enumerate(slice_edges):
        below = j - 1 if j > 0 else -1
        above = j if j < nsl else -1
        for i in range(n_cap):
            discs.append((ze, re[i], re[i + 1], below, above))
    discs = np.array(discs)
    return side, side_slice, discs


def _system(radius, side, discs, key):
    """Influence matrix A (tangential field per mu0 per unit K) and applied H_t per ampere."""
    from .field.kernels import loop_rz, sheet_rz

    ns, nd = len(side), len(discs)
    # collocation points and tangents
    cz_side = 0.5 * (side[:, 0] + side[:, 1])
    cr_disc = 0.5 * (discs[:, 1] + discs[:, 2])
    rho = np.concatenate([np.full(ns, radius), cr_disc])
    z = np.concatenate([cz_side, discs[:, 0]])
    n = ns + nd
    a = np.empty((n, n))
    # side panels: exact sheets (mean of the two sides on the sheet = PV)
    h = 0.5 * (side[:, 1] - side[:, 0])
    br, bz = sheet_rz(radius, np.tile(h, n), np.repeat(rho, ns),
                      np.repeat(z, ns) - np.tile(cz_side, n))
    br = br.reshape(n, ns)
    bz = bz.reshape(n, ns)
    a[:ns, :ns] = bz[:ns]
    a[ns:, :ns] = -br[ns:]
    # disc panels: composite Gauss rules of loops (16 nodes, graded near the collocation point)
    nq = 16
    rq, wq = _disc_nodes(discs[:, 1], discs[:, 2], nq)
    rq = rq.ravel()
    wq = wq.ravel()
    zq = np.repeat(discs[:, 0], nq)
    m = len(rq)
    lbr, lbz = loop_rz(np.tile(rq, n), np.repeat(rho, m), np.repeat(z, m) - np.tile(zq, n))
    lbr = (lbr * np.tile(wq, n)).reshape(n, nd, nq).sum(axis=2)
    lbz = (lbz * np.tile(wq, n)).reshape(n, nd, nq).sum(axis=2)
    a[:ns, ns:] = lbz[:ns]
    a[ns:, ns:] = -lbr[ns:]
    # same-plane disc-disc: tangential (radial) field of a loop vanishes in its own plane
    same = np.abs(discs[:, 0][:, None] - discs[:, 0][None, :]) < 1e-15
    a[ns:, ns:][same] = 0.0
    hr, hz = _applied_h(key, rho, z)
    h_t = np.concatenate([hz[:ns], -hr[ns:]])
    return a, h_t, rho, z


def _interface_factor(mu_in, mu_out):
    return 2.0 * (mu_in - mu_out) / (mu_in + mu_out)


def _solve_with_mu(radius, side, side_slice, discs, mus, a, h_t):
    ns = len(side)
    mu_of = lambda k: np.where(k < 0, 1.0, mus[np.maximum(k, 0).astype(int)])  # noqa: E731
    f_side = _interface_factor(mu_of(side_slice), 1.0)
    below = discs[:, 3].astype(int)
    above = discs[:, 4].astype(int)
    f_disc = _interface_factor(mu_of(below), mu_of(above))
    f = np.concatenate([f_side, f_disc])
    mat = np.eye(len(f)) - f[:, None] * a
    k = np.linalg.solve(mat, f * h_t)
    return k[:ns], k[ns:]


def _slice_probe(radius, side, discs, slice_edges, key, nr=4, nz=3):
    """Quadrature points of every slice and the linear maps from panel currents to B there.

    Returns (pr, pz, weights, slice_index, Pr, Pz, hr, hz): B/mu0 at the points is
    ``P @ k + h * current`` (h the applied field per ampere).
    """
    from .field.kernels import loop_rz, sheet_rz

    xr, wr = np.polynomial.legendre.leggauss(nr)
    xz, wz = np.polynomial.legendre.leggauss(nz)
    rr = radius * np.sqrt(0.5 * (xr + 1.0))  # area coordinate: equal-weight rings
    pts_r, pts_z, weights, which = [], [], [], []
    for k in range(len(slice_edges) - 1):
        lo, hi = slice_edges[k], slice_edges[k + 1]
        zz = 0.5 * (lo + hi) + 0.5 * (hi - lo) * xz
        R, Z = np.meshgrid(rr, zz, indexing="ij")
        pts_r.append(R.ravel())
        pts_z.append(Z.ravel())
        weights.append(np.outer(0.5 * wr, 0.5 * wz).ravel())
        which.append(np.full(R.size, k))
    pr = np.concatenate(pts_r)
    pz = np.concatenate(pts_z)
    n = len(pr)
    ns = len(side)
    h = 0.5 * (side[:, 1] - side[:, 0])
    c = 0.5 * (side[:, 1] + side[:, 0])
    sbr, sbz = sheet_rz(radius, np.tile(h, n), np.repeat(pr, ns), np.repeat(pz, ns) - np.tile(c, n))
    nq = 8
    rq, wq = _disc_nodes(discs[:, 1], discs[:, 2], nq)
    rq, wq = rq.ravel(), wq.ravel()
    zq = np.repeat(discs[:, 0], nq)
    m = len(rq)
    lbr, lbz = loop_rz(np.tile(rq, n), np.repeat(pr, m), np.repeat(pz, m) - np.tile(zq, n))
    nd = len(discs)
    p_r = np.hstack([sbr.reshape(n, ns), (lbr * np.tile(wq, n)).reshape(n, nd, nq).sum(axis=2)])
    p_z = np.hstack([sbz.reshape(n, ns), (lbz * np.tile(wq, n)).reshape(n, nd, nq).sum(axis=2)])
    hr, hz = _applied_h(key, pr, pz)
    return (np.concatenate(weights), np.concatenate(which), p_r, p_z, hr, hz)


@functools.lru_cache(maxsize=512)
def _solve_linear(radius, length, offset, mu_r, key) -> CoreSolution:
    """Surface-current solution per ampere of a linear homogeneous core (cached per design)."""
    side, side_slice, discs = _geometry(radius, length, offset)
    a, h_t, _, _ = _system(radius, side, discs, key)
    ks, kd = _solve_with_mu(radius, side, side_slice, discs, np.array([mu_r]), a, h_t)
    # peak |B| per ampere: centre of the core (axis), where the flux of a rod core peaks
    tmp = CoreSolution(radius, side[:, 0], side[:, 1], ks, discs[:, 0], discs[:, 1],
                       discs[:, 2], kd, 0.0)
    cr, cz = _currents_rz(tmp, np.array([0.0]), np.array([offset]), False)
    hr, hz = _applied_h(key, np.array([0.0]), np.array([offset]))
    peak = float(MU0 * abs(cz[0] + hz[0]))
    return CoreSolution(radius, side[:, 0].copy(), side[:, 1].copy(), ks, discs[:, 0].copy(),
                        discs[:, 1].copy(), discs[:, 2].copy(), kd, peak)


@functools.lru_cache(maxsize=256)
def _solve_nonlinear(radius, length, offset, bh, key, current, n_slices=N_SLICES,
                     max_iter=100, tol=1e-5) -> CoreSolution:
    """Secant-permeability iteration over axial slices with the B-H curve (module docs).

    Returns the solution *per ampere* at ``current`` (A, > 0).
    """
    lo, hi = offset - length / 2, offset + length / 2
    slice_edges = np.linspace(lo, hi, n_slices + 1)
    side, side_slice, discs = _geometry(radius, length, offset, slice_edges,
                                        n_side=max(N_SIDE, 8 * n_slices))
    a, h_t, _, _ = _system(radius, side, discs, key)
    w, which, p_r, p_z, hr, hz = _slice_probe(radius, side, discs, slice_edges, key)
    wsum = np.bincount(which, weights=w, minlength=n_slices)
    current = max(current, 1e-6)
    mus = np.full(n_slices, float(steel1010_mu_r(np.array([0.3]))[0]))
    b = np.zeros(n_slices)
    for _ in range(max_iter):
        ks, kd = _solve_with_mu(radius, side, side_slice, discs, mus, a, h_t * current)
        k = np.concatenate([ks, kd])
        bmag = MU0 * np.hypot(p_r @ k + hr * current, p_z @ k + hz * current)
        b = np.bincount(which, weights=bmag * w, minlength=n_slices) / wsum
        nu = 1.0 / mus
        # damped update of the reluctivity: the undamped map overshoots past the knee
        nu_new = 0.5 * nu + 0.5 / steel1010_mu_r(b)
        mus = 1.0 / nu_new
        if np.max(np.abs(nu_new - nu) / nu) < tol:
            break
    ks, kd = _solve_with_mu(radius, side, side_slice, discs, mus, a, h_t * current)
    return CoreSolution(radius, side[:, 0].copy(), side[:, 1].copy(), ks / current,
                        discs[:, 0].copy(), discs[:, 1].copy(), discs[:, 2].copy(), kd / current,
                        float(np.max(b)) / current, False)


def demagnetizing_factor(aspect_ratio: float) -> float:
    """Magnetometric (volume-averaged) axial demagnetizing factor of a cylinder, chi -> 0.

    Exact closed form: the field energy of a uniformly magnetized cylinder is
    (mu0/2) M^2 V (1 - N_m), and it equals that of its equivalent current sheet (K = M), whose
    inductance is Nagaoka's k_N mu0 pi R^2 / L; hence N_m = 1 - k_N with
    k_N = 4 / (3 pi k') [k'^2 (K - E) / k^2 + E - k], k = D / sqrt(D^2 + L^2), k' = L / sqrt(D^2 + L^2).
    (K - E) / k^2 is Bulirsch's cel(k', 1, 0, 1), free of cancellation for long rods.
    Chen, Brug & Goldfarb, IEEE Trans. Magn. 27, 3601 (1991) tabulate the same values.

    Parameters
    ----------
    aspect_ratio : float
        Length / diameter (> 0).

    Returns
    -------
    float
        N_m in (0, 1).
    """
    from scipy.special import ellipe

    from .field.kernels import cel

    aspect = float(aspect_ratio)
    d2 = 1.0 / (1.0 + aspect * aspect)  # k^2 with D = 1, L = aspect
    k = math.sqrt(d2)
    kp = aspect * k
    k_minus_e_over_k2 = float(cel(kp, 1.0, 0.0, 1.0))
    e = float(ellipe(d2))
    k_n = 4.0 / (3.0 * math.pi * kp) * (kp * kp * k_minus_e_over_k2 + e - k)
    return 1.0 - k_n
