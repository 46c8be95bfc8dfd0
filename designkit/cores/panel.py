"""Soft-iron cores: the :class:`Core` type and its two magnetization models.

``"surface-current"`` (default): a linear core's whole field is that of its bound azimuthal
surface current K = M x n, solved from a second-kind integral equation collocated on meridian
panels (:mod:`designkit.cores.discretization`); with the 1010 steel B-H curve the core is cut
into axial slices with secant permeabilities, iterated to a fixed point. Validated against
GetDP (:mod:`designkit.fem`, ``studies/core_vs_fem.py``).

``"thesis-uniform"``: thesis appendix A.2.3, a uniform axial magnetization
M = B0 (mu_r - 1) / (mu0 (1 + N (mu_r - 1))) with B0 the winding's flux density at the core
centre and N the magnetometric demagnetizing factor (:mod:`designkit.cores.nagaoka`); a first
estimate only, linear, warning past the knee.

Inputs: the core (m, relative mu_r) and the driving winding's geometry
(:class:`designkit.geometry.winding.WindingGeometry`; a Coil works too), currents in A. Outputs: a
:class:`designkit.cores.solution.CoreSolution` (K in A/m, local frame), fields in T, H.
Derivations and measured accuracy: docs/core_model.md.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..constants import MU0
from ..errors import BadInputError
from ..geometry.winding import WindingGeometry
from ..support import validate as v
from ..support.blas import one_blas_thread
from .discretization import (N_SIDE, influence_system, interface_factor, panel_basis_rz,
                             panel_geometry)
from .material import BH_CURVES, KNEE_T, BHCurveName, steel1010_mu_r
from .nagaoka import demagnetizing_factor
from .solution import CoreSolution

CoreModelName = Literal["surface-current", "thesis-uniform"]
CORE_MODELS: tuple[str, ...] = ("surface-current", "thesis-uniform")
N_SLICES = 11
"""Axial slices of a nonlinear (B-H curve) core, each with its own secant permeability."""


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

    The methods take the driving winding as ``winding``: a
    :class:`designkit.geometry.winding.WindingGeometry` or anything with its four attributes (a Coil).
    """

    radius: float
    length: float
    relative_permeability: float = 1000.0
    offset: float = 0.0
    model: CoreModelName = "surface-current"
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
    def magnetization(self, winding, current: float) -> float:
        """Uniform axial magnetization of the thesis model, A/m.

        Applied field: the winding's B0 at the core centre; N: magnetometric factor, chi -> 0.
        """
        geo = WindingGeometry.of(winding)
        h0 = geo.h_rz(np.array([0.0]), np.array([self.offset]))[1][0]
        n = demagnetizing_factor(self.length / (2 * self.radius))
        chi = self.relative_permeability - 1.0
        return float(h0 * current * chi / (1.0 + n * chi))

    # ------------------------------------------------------------------ public API
    def solution(self, winding, current: float = 1.0) -> CoreSolution:
        """Bound-current solution of the core driven by ``winding`` at ``current`` (A).

        Linear cores: the solution per ampere (cached, scaled by ``current``). Nonlinear
        (``bh='steel1010'``): solved at that current (cached by current).
        """
        current = v.finite("current", current, "A")
        key = WindingGeometry.of(winding)
        if self.model == "thesis-uniform":
            m1 = self.magnetization(key, 1.0)
            sol = _uniform_solution(self.radius, self.length, self.offset, m1)
            return sol.scaled(current, self)
        if self.bh == "linear":
            sol = _solve_linear(self.radius, self.length, self.offset,
                                float(self.relative_permeability), key)
            return sol.scaled(current, self)
        sol = _solve_nonlinear(self.radius, self.length, self.offset, self.bh, key,
                               round(float(abs(current)), 12))
        return sol.scaled(current, self)

    def field_local(self, points_local: np.ndarray, winding, current: float, *,
                    gradient: bool = False):
        """Core field at points given in the winding's local frame.

        Parameters
        ----------
        points_local : ndarray, shape (n, 3), m
        winding : WindingGeometry or Coil
            The winding that drives the core.
        current : float, A

        Returns
        -------
        B : ndarray (n, 3), T, and G : ndarray (n, 3, 3), T/m when gradient=True.
        Warns :class:`SaturationWarning` when a linear model's core flux density exceeds
        :attr:`knee_t`.
        """
        sol = self.solution(winding, current)
        sol.warn_if_saturated(self.knee_t)
        return sol.field(points_local, gradient=gradient)

    def extra_inductance(self, winding, current: float | None = None) -> float:
        """Inductance the core adds to the winding's air-core inductance, H.

        Flux linkage of the core's field with the winding's turns per unit current, for this
        core's model. For ``bh='steel1010'`` it is the secant (flux-linkage / current) value at
        ``current`` (A; default: the small-signal limit at 0.01 A).
        """
        if self.bh != "linear" and self.model != "thesis-uniform":
            i = 0.01 if current is None else abs(v.finite("current", current, "A"))
            i = max(i, 1e-6)
            return self.solution(winding, i).flux_linkage(winding) / i
        return self.solution(winding, 1.0).flux_linkage(winding)

    def peak_flux_density(self, winding, current: float) -> float:
        """Largest slice-averaged |B| in the core at ``current``, T (saturation check)."""
        return self.solution(winding, current).peak_b


# ====================================================================== solvers
def _uniform_solution(radius, length, offset, m1) -> CoreSolution:
    lo, hi = offset - length / 2, offset + length / 2
    b_in = MU0 * m1  # order of the core's own flux density per ampere (flag only)
    return CoreSolution(radius, np.array([lo]), np.array([hi]), np.array([m1]), np.zeros(0),
                        np.zeros(0), np.zeros(0), np.zeros(0), abs(b_in), True, "thesis-uniform")


def _solve_with_mu(side, side_slice, discs, mus, a, h_t):
    """Panel currents (side, discs) for the slices' relative permeabilities ``mus``."""
    ns = len(side)
    mu_of = lambda k: np.where(k < 0, 1.0, mus[np.maximum(k, 0).astype(int)])  # noqa: E731
    f_side = interface_factor(mu_of(side_slice), 1.0)
    below = discs[:, 3].astype(int)
    above = discs[:, 4].astype(int)
    f_disc = interface_factor(mu_of(below), mu_of(above))
    f = np.concatenate([f_side, f_disc])
    mat = np.eye(len(f)) - f[:, None] * a
    k = np.linalg.solve(mat, f * h_t)
    return k[:ns], k[ns:]


def _slice_probe(radius, side, discs, slice_edges, winding, nr=4, nz=3):
    """Quadrature points of every slice and the linear maps from panel currents to B there.

    Returns (weights, slice_index, Pr, Pz, hr, hz), one row per quadrature point: B/mu0
    there is ``P @ k + h * current`` (h the applied field per ampere); the weights sum to 1
    over each slice.
    """
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
    p_r, p_z = panel_basis_rz(radius, side, discs, pr, pz, 8)
    hr, hz = winding.h_rz(pr, pz)
    return (np.concatenate(weights), np.concatenate(which), p_r, p_z, hr, hz)


@functools.lru_cache(maxsize=512)
def _solve_linear(radius, length, offset, mu_r, key) -> CoreSolution:
    """Surface-current solution per ampere of a linear homogeneous core (cached per design).

    ``key``: the driving :class:`WindingGeometry`."""
    key = WindingGeometry(*key)
    side, side_slice, discs = panel_geometry(radius, length, offset)
    a, h_t, _, _ = influence_system(radius, side, discs, key)
    ks, kd = _solve_with_mu(side, side_slice, discs, np.array([mu_r]), a, h_t)
    # peak |B| per ampere: centre of the core (axis), where the flux of a rod core peaks
    tmp = CoreSolution(radius, side[:, 0], side[:, 1], ks, discs[:, 0], discs[:, 1],
                       discs[:, 2], kd, 0.0)
    cr, cz = tmp.currents_rz(np.array([0.0]), np.array([offset]), False)
    hr, hz = key.h_rz(np.array([0.0]), np.array([offset]))
    peak = float(MU0 * abs(cz[0] + hz[0]))
    return CoreSolution(radius, side[:, 0].copy(), side[:, 1].copy(), ks, discs[:, 0].copy(),
                        discs[:, 1].copy(), discs[:, 2].copy(), kd, peak)


@functools.lru_cache(maxsize=8)
def _nonlinear_setup(radius, length, offset, key, n_slices):
    """What the slice iteration reuses for every current: panels, influence system, probes."""
    lo, hi = offset - length / 2, offset + length / 2
    slice_edges = np.linspace(lo, hi, n_slices + 1)
    side, side_slice, discs = panel_geometry(radius, length, offset, slice_edges,
                                             n_side=max(N_SIDE, 8 * n_slices))
    a, h_t, _, _ = influence_system(radius, side, discs, key)
    return side, side_slice, discs, a, h_t, _slice_probe(radius, side, discs, slice_edges, key)


NONLINEAR_MAX_ITER = 100
"""Iterations of the secant-permeability iteration at most."""
NONLINEAR_TOL = 1e-5
"""... until the slices' reluctivities change by less than this (relative)."""


@functools.lru_cache(maxsize=256)
def _solve_nonlinear(radius, length, offset, bh, key, current,
                     n_slices=N_SLICES) -> CoreSolution:
    """Secant-permeability iteration over axial slices with the B-H curve (docs/core_model.md).

    A damped fixed-point iteration on the slices' reluctivities 1/mu_k. Returns the solution
    *per ampere* at ``current`` (A, > 0); ``key``: the driving :class:`WindingGeometry`.
    """
    key = WindingGeometry(*key)
    side, side_slice, discs, a, h_t, probe = _nonlinear_setup(radius, length, offset, key,
                                                              n_slices)
    w, which, p_r, p_z, hr, hz = probe
    wsum = np.bincount(which, weights=w, minlength=n_slices)
    current = max(current, 1e-6)
    mus = np.full(n_slices, float(steel1010_mu_r(np.array([0.3]))[0]))
    b = np.zeros(n_slices)
    with one_blas_thread():  # small dense solves: threads wait longer than they compute
        for _ in range(NONLINEAR_MAX_ITER):
            ks, kd = _solve_with_mu(side, side_slice, discs, mus, a, h_t * current)
            k = np.concatenate([ks, kd])
            bmag = MU0 * np.hypot(p_r @ k + hr * current, p_z @ k + hz * current)
            b = np.bincount(which, weights=bmag * w, minlength=n_slices) / wsum
            nu = 1.0 / mus
            # damped update of the reluctivity: the undamped map overshoots past the knee
            nu_new = 0.5 * nu + 0.5 / steel1010_mu_r(b)
            mus = 1.0 / nu_new
            if np.max(np.abs(nu_new - nu) / nu) < NONLINEAR_TOL:
                break
        ks, kd = _solve_with_mu(side, side_slice, discs, mus, a, h_t * current)
    return CoreSolution(radius, side[:, 0].copy(), side[:, 1].copy(), ks / current,
                        discs[:, 0].copy(), discs[:, 1].copy(), discs[:, 2].copy(), kd / current,
                        float(np.max(b)) / current, False)
