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
    (:func:`designkit.field.magnetized_cylinder_field`). It is only a first estimate: real
    magnetization is far from uniform in a finite core (44-48 % off in Bz against GetDP FEM,
    ``studies/core_vs_fem.py``). It ignores ``bh`` (linear), and warns when its M passes the knee.

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
from .constants import MU0
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
"""Flux density above which low-carbon steel is past the knee of its B-H curve, T (default of
:attr:`Core.knee_t`; a design file sets it as ``[core] saturation_t``)."""


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
    knee_t : float, T
        A linear model warns (:class:`SaturationWarning`) when the core's flux density passes it.
    """

    radius: float
    length: float
    relative_permeability: float = 1000.0
    offset: float = 0.0
    model: CoreModel = "surface-current"
    bh: BHCurveName = "linear"
    knee_t: float = KNEE_T

    def __post_init__(self):
        v.positive("core.radius", self.radius)
        v.positive("core.length", self.length)
        v.in_range("core.relative_permeability", self.relative_permeability, 1.0, 1e7)
        v.finite("core.offset", self.offset, "m")
        v.positive("core.knee_t", self.knee_t, "T")
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
        :attr:`knee_t`.
        """
        sol = self.solution(coil, current)
        sol.warn_if_saturated(self.knee_t)
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

    def warn_if_saturated(self, knee_t: float = KNEE_T) -> None:
        if self.linear_model and self.peak_b > knee_t:
            warnings.warn(
                f"core flux density {self.peak_b:.2f} T exceeds the {knee_t:g} T knee of "
                "low-carbon steel: the linear core model overestimates the field; for the "
                "saturating B-H curve use Core(bh='steel1010') or, in a design file, "
                "[core] bh = \"steel1010\"", SaturationWarning, stacklevel=4)

    def field(self, points_local: np.ndarray, *, gradient: bool = False,
              rule: Literal["auto", "panels"] = "auto"):
        """B (n, 3) T [, G (n, 3, 3) T/m] of the bound currents at local Cartesian points.

        ``rule='auto'``: points farther than :data:`FAR_DISTANCE` from the core use the
        compressed ring rule (:meth:`far_rings`, ~20 loops per point); nearer points sum the
        panels exactly. ``'panels'`` always sums the panels.
        """
        p = np.asarray(points_local, dtype=float)
        rho = np.hypot(p[:, 0], p[:, 1])
        z = p[:, 2]
        if rule == "panels" or len(self.k_disc) == 0:
            comps = _currents_rz(self, rho, z, gradient)
            return _rz_to_xyz(p, rho, comps, gradient, MU0)
        lo, hi = float(self.side_z_lo.min()), float(self.side_z_hi.max())
        far = (z - hi >= FAR_DISTANCE) | (lo - z >= FAR_DISTANCE) | (rho - self.radius
                                                                      >= FAR_DISTANCE)
        nout = 7 if gradient else 2
        comps = [np.zeros(len(z)) for _ in range(nout)]
        if np.any(~far):
            near = _currents_rz(self, rho[~far], z[~far], gradient)
            for q in range(nout):
                comps[q][~far] = near[q]
        if np.any(far):
            from .field.kernels import loop_rz

            rq, zq, wq = self.far_rings()
            nf = int(far.sum())
            m = len(rq)
            res = loop_rz(np.tile(rq, nf), np.repeat(rho[far], m),
                          np.repeat(z[far], m) - np.tile(zq, nf), gradient=gradient)
            ww = np.tile(wq, nf)
            for q in range(nout):
                comps[q][far] = (res[q] * ww).reshape(nf, m).sum(axis=1)
        return _rz_to_xyz(p, rho, comps, gradient, MU0)

    def far_rings(self):
        """Compressed ring rule for far points: (r, z, current per ring) arrays, SI.

        Product integration: on a few intervals per face the loop field is interpolated at
        Gauss points, the piecewise-constant K (with its rim singularity) goes into the weights
        exactly. Cached on the instance.
        """
        cached = self.__dict__.get("_far")
        if cached is not None:
            return cached
        lo, hi = float(self.side_z_lo.min()), float(self.side_z_hi.max())
        length = hi - lo
        end = min(0.15 * length, 2 * self.radius)
        rings_r, rings_z, rings_w = [], [], []
        side_iv = [(lo, lo + end), (lo + end, hi - end), (hi - end, hi)]
        _product_rule(self.side_z_lo, self.side_z_hi, self.k_side, side_iv, FAR_NODES,
                      lambda s: (np.full_like(s, self.radius), s), rings_r, rings_z, rings_w)
        for zp in np.unique(self.disc_z):
            sel = self.disc_z == zp
            _product_rule(self.disc_r_lo[sel], self.disc_r_hi[sel], self.k_disc[sel],
                          [(0.0, self.radius)], FAR_NODES,
                          lambda s, zp=zp: (s, np.full_like(s, zp)), rings_r, rings_z, rings_w)
        out = (np.concatenate(rings_r), np.concatenate(rings_z), np.concatenate(rings_w))
        object.__setattr__(self, "_far", out)  # frozen dataclass: cache the derived rule
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


FAR_DISTANCE = 8e-3
"""Points at least this far (m) outside the core's bounding cylinder use the compressed rule."""
FAR_NODES = 6


def _product_rule(lo_e, hi_e, k, intervals, n, place, out_r, out_z, out_w):
    """Gauss-node rings whose weights integrate piecewise-constant K times the interpolant."""
    x, w = np.polynomial.legendre.leggauss(n)
    xf, wf = np.polynomial.legendre.leggauss(n + 2)
    for a, b in intervals:
        nodes = 0.5 * (a + b) + 0.5 * (b - a) * x
        weights = np.zeros(n)
        for j in range(len(k)):
            p0, p1 = max(lo_e[j], a), min(hi_e[j], b)
            if p1 <= p0:
                continue
            s = 0.5 * (p0 + p1) + 0.5 * (p1 - p0) * xf
            ws = 0.5 * (p1 - p0) * wf
            for q in range(n):
                others = np.delete(nodes, q)
                lag = np.prod((s[:, None] - others[None, :]) / (nodes[q] - others[None, :]),
                              axis=1)
                weights[q] += k[j] * np.sum(ws * lag)
        r, z = place(nodes)
        out_r.append(r)
        out_z.append(z)
        out_w.append(weights)


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
    """Sum of the panels' fields per mu0 at (rho, z): list of the 2 or 7 rz components."""
    from .field.kernels import loop_rz, sheet_rz

    n = rho.shape[0]
    nout = 7 if gradient else 2
    acc = [np.zeros(n) for _ in range(nout)]
    if len(sol.k_side):
        h = 0.5 * (sol.side_z_hi - sol.side_z_lo)
        c = 0.5 * (sol.side_z_hi + sol.side_z_lo)
        ns = len(h)
        res = sheet_rz(sol.radius, np.tile(h, n), np.repeat(rho, ns),
                       np.repeat(z, ns) - np.tile(c, n), gradient=gradient)
        kk = np.tile(sol.k_side, n)
        for q in range(nout):
            acc[q] += (res[q] * kk).reshape(n, ns).sum(axis=1)
    if len(sol.k_disc):
        nq = 4
        rq, wq = _disc_nodes(sol.disc_r_lo, sol.disc_r_hi, nq)
        wk = (wq * sol.k_disc[:, None]).ravel()
        zq = np.repeat(sol.disc_z, nq)
        rq = rq.ravel()
        m = len(rq)
        res = loop_rz(np.tile(rq, n), np.repeat(rho, m), np.repeat(z, m) - np.tile(zq, n),
                      gradient=gradient)
        ww = np.tile(wk, n)
        for q in range(nout):
            acc[q] += (res[q] * ww).reshape(n, m).sum(axis=1)
    return acc


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
        # every slice is graded towards both of its ends, not only the core's: each interface
        # between slices carries disc currents too, and the side current varies fastest there
        e = _graded(slice_edges[k], slice_edges[k + 1], per, "both")
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

    Returns (weights, slice_index, Pr, Pz, hr, hz), one row per quadrature point: B/mu0
    there is ``P @ k + h * current`` (h the applied field per ampere); the weights sum to 1
    over each slice.
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
