"""The calibration's forward model: each coil's field per ampere as a function of its as-built
parameters, with its Jacobian.

Column k of the field (T/A) at points p (n, 3) m is

    b_k(p; theta) = (1 + turns_rel_k) [ b_single_k(p; pose_k, mu_r_k, core offset_k) + c_k(p) ],

``b_single_k`` the coil with its own core alone (exact single-coil model), ``c_k`` the coupling
term (the field of the other cores magnetized by coil k, and the feedback on its own core),
from an exact coupled solve (:meth:`designkit.model.array.CoilArray.actuation_matrix`) at theta_0 and
linear in every core's ln(mu_r) about it. Its slope is exact: the cores' interface factors
F_j = 2 (mu_j - 1) / (mu_j + 1) scale core j's rows of the system M x = F P s, so
dx / d ln mu_j = (d ln F_j / d ln mu_j) M^-1 (x restricted to core j) and the field's derivative
at the points is that with the adjoint Y = M^-T E^T (:meth:`designkit.cores.ArraySystem.adjoint`),
one solve for all cores. The field is linear in the currents: a reading is ``sum_k b_k(p) I_k``.
Jacobian: translations and tilts exactly from the field gradient (dB/dd = -G d; a small rotation
w about the winding centre c gives dB = w x B - G (w x (p - c))), turns exactly, the own core's
mu_r and axial offset by one-sided differences of the core's field alone, plus the coupling's
slope. Parameters: :data:`designkit.design.asbuilt.PARAMETERS`. Reference: docs/calibration.md.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..design.asbuilt import AsBuilt, CoilDeviation
from ..model.array import CoilArray

LOG_MU_STEP = 0.05
"""Difference step of ln(mu_r)."""
CORE_DZ_STEP_M = 2e-4
"""Difference step of the core's axial offset, m."""


def _coil_at(nominal, theta):
    """The nominal coil moved and tilted, its core as in ``theta`` (turns stay nominal)."""
    dev = CoilDeviation(*theta[:5], turns=None,
                        core_relative_permeability=(None if nominal.core is None else
                                                    nominal.core.relative_permeability
                                                    * float(np.exp(theta[6]))),
                        core_offset_m=theta[7] if nominal.core is not None else 0.0)
    return AsBuilt((dev,)).apply((nominal,))[0]


def single_columns(nominal_coils, points, params, jacobian: bool = False, core_jac=None):
    """Each coil alone (own core, nominal turns) per ampere at ``points`` (n, 3) m.

    Returns B (n, 3, n_coils) T/A [, dB/dtheta (n, 3, n_coils, 8), turns column left 0].
    ``core_jac`` (n, 3, n_coils, 2): the mu_r and core-offset columns to use instead of new
    differences (each difference is a new core solve; Gauss-Newton converges with columns
    from a nearby point).
    """
    n, nc = len(points), len(nominal_coils)
    b = np.empty((n, 3, nc))
    jac = np.zeros((n, 3, nc, 8)) if jacobian else None
    for k, (c0, th) in enumerate(zip(nominal_coils, params)):
        coil = _coil_at(c0, th)
        if not jacobian:
            b[:, :, k] = coil.field(points, 1.0)
            continue
        bk, g = coil.field(points, 1.0, gradient=True)
        b[:, :, k] = bk
        jac[:, :, k, :3] = -g
        rel = points - np.asarray(coil.pose.position)
        for a in range(2):
            w = np.zeros(3)
            w[a] = 1.0
            jac[:, :, k, 3 + a] = np.cross(w, bk) - np.einsum("nij,nj->ni", g,
                                                               np.cross(w, rel))
        if core_jac is not None:
            jac[:, :, k, 6:] = core_jac[:, :, k]
        elif coil.core is not None:
            base = coil.field(points, 1.0, include="core")
            for j, step in ((6, LOG_MU_STEP), (7, CORE_DZ_STEP_M)):
                th2 = np.array(th, dtype=float)
                th2[j] += step
                moved = _coil_at(c0, th2)
                jac[:, :, k, j] = (moved.field(points, 1.0, include="core") - base) / step
    return (b, jac) if jacobian else b


@dataclasses.dataclass
class ForwardModel:
    """Field per ampere of every coil at fixed points, for parameters (n_coils, 8).

    nominal_coils : the design's nominal coils; points : (n, 3) m; coupling : (n, 3, n_coils)
    T/A, the coupling term per unit turns scale at ``logmu_ref`` (:func:`coupling_term`).
    """

    nominal_coils: tuple
    points: np.ndarray
    coupling: np.ndarray
    coupling_dlogmu: np.ndarray | None = None
    """d coupling[:, :, k] / d ln(mu_r) of core j, (n, 3, n_coils k, n_coils j) T/A, or None."""
    logmu_ref: np.ndarray | float = 0.0
    """Each coil's ln(mu_r / nominal) (n_coils,) at which ``coupling`` was computed."""
    refresh_every: int = 4
    """New mu_r / core-offset differences every this many Jacobians."""
    _core_jac: np.ndarray | None = dataclasses.field(default=None, repr=False)
    _age: int = 0

    def columns(self, params, jacobian: bool = False):
        """B (n, 3, n_coils) T/A [, Jacobian (n, 3, n_coils, 8) of column k by coil k's
        parameters, and the columns' derivative by each core's ln(mu_r) through the coupling
        (n, 3, n_coils k, n_coils j) or None]."""
        params = np.asarray(params, dtype=float)
        reuse = None
        if jacobian and self._core_jac is not None and self._age < self.refresh_every:
            reuse, self._age = self._core_jac, self._age + 1
        res = single_columns(self.nominal_coils, self.points, params, jacobian, reuse)
        b0, jac = res if jacobian else (res, None)
        if jacobian and reuse is None:
            self._core_jac, self._age = jac[:, :, :, 6:].copy(), 1
        coupling = self.coupling
        if self.coupling_dlogmu is not None:
            coupling = coupling + self.coupling_dlogmu @ (params[:, 6] - self.logmu_ref)
        scale = 1.0 + params[:, 5]
        base = b0 + coupling
        b = base * scale
        if not jacobian:
            return b
        jac *= scale[None, None, :, None]
        jac[:, :, :, 5] = base
        cross = None
        if self.coupling_dlogmu is not None:
            cross = self.coupling_dlogmu * scale[:, None]
        return b, jac, cross


def coupling_term(nominal_coils, array: CoilArray, params, points, single=None) -> np.ndarray:
    """c_k of the module docstring at ``points`` (n, 3) m for the device ``array`` (built with
    ``params``): its exact coupled columns / its turns ratio less each coil alone, T/A
    (``single``: :func:`single_columns` at ``params`` if already at hand)."""
    a = array.actuation_matrix(points)[:, :3, :]
    turns = np.array([c.turns / c0.turns for c, c0 in zip(array.coils, nominal_coils)])
    if single is None:
        single = single_columns(nominal_coils, points, np.asarray(params, dtype=float))
    return a / turns - single


def coupled_dlogmu(nominal_coils, array: CoilArray, points) -> np.ndarray | None:
    """d b_k / d ln(mu_j) of the exact coupled columns per unit turns scale, (n, 3, n_coils k,
    n_coils j) T/A, at ``points`` (n, 3) m, or None without coupled cores (module docstring:
    d ln F_j / d ln mu_j = 2 mu_j / (mu_j^2 - 1), one adjoint solve)."""
    system = array.coupled()
    if system is None:
        return None
    n, nc = len(points), len(array.coils)
    y = system.adjoint(points)  # (n_unknowns, 3 n)
    x = system.coil_solution()  # (n_unknowns, n_coils)
    out = np.zeros((n, 3, nc, nc))
    for jj, j in enumerate(system.core_index):
        rows = slice(system.offsets[jj], system.offsets[jj + 1])
        mu = float(array.coils[j].core.relative_permeability)
        out[:, :, :, j] = (2.0 * mu / (mu * mu - 1.0)) * (y[rows].T @ x[rows]).reshape(n, 3, nc)
    turns = np.array([c.turns / c0.turns for c, c0 in zip(array.coils, nominal_coils)])
    return out / turns[None, None, :, None]


def coupled_forward_model(coils, array: CoilArray, params, points, previous=None) -> ForwardModel:
    """The forward model with the exact coupling of ``array`` (built with ``params``) and its
    slope in each core's ln(mu_r): :func:`coupled_dlogmu` less the own core's single-core
    difference that the model adds back (``previous``'s while it is fresh), so that the
    model's Jacobian by ln(mu_r) is the coupled model's at ``params``."""
    slope = coupled_dlogmu(coils, array, points)
    if slope is None:
        return ForwardModel(coils, points, coupling_term(coils, array, params, points))
    if previous is not None and previous._core_jac is not None and \
            previous._age < previous.refresh_every:
        core_jac, age = previous._core_jac, previous._age
        single = single_columns(coils, points, params)
    else:
        single, jac = single_columns(coils, points, params, jacobian=True)
        core_jac, age = jac[:, :, :, 6:].copy(), 1
    c0 = coupling_term(coils, array, params, points, single)
    for k in range(len(coils)):
        slope[:, :, k, k] -= core_jac[:, :, k, 0]
    model = ForwardModel(coils, points, c0, slope, np.array(params[:, 6], dtype=float))
    model._core_jac, model._age = core_jac, age
    return model
