"""Regularized nonlinear least squares of the as-built parameters to field measurements.

Minimizes ``sum_rows |(b_model - b_read) / sigma|^2 + sum_params (theta / tol)^2``: the
readings weighted by their noise, the priors the build tolerances
(:class:`designkit.asbuilt.BuildTolerances`, mean = nominal). Levenberg-Marquardt in the
whitened parameters ``z = theta / tol`` on :class:`ForwardModel`; after it converges the
coupling term is recomputed from an exact coupled solve of the fitted device and the fit
repeated (``coupling_rounds``). Standard errors from the inverse of the whitened normal matrix
(Gauss-Newton, at the solution); a parameter is identifiable when the data shrink its
standard error below :data:`IDENTIFIABLE_RATIO` of its tolerance. Reference: Petruska et al.,
"Model-based calibration for magnetic manipulation", IEEE Trans. Magn. 53 (2017);
docs/calibration.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._progress import tqdm
from ..array import CoilArray
from ..asbuilt import PARAMETERS, AsBuilt, BuildTolerances
from ..errors import BadInputError, DesignkitError
from .measurements import Measurements
from .model import ForwardModel, coupling_term

IDENTIFIABLE_RATIO = 0.5
"""Posterior / prior standard deviation below which the data identify a parameter."""
CHI2_TOLERANCE = 0.1
"""Converged when an accepted step lowers the whitened cost by less than this plus 1e-4 of
the cost (a chi-square change far below 1 carries no information)."""
MAX_ITERATIONS = 40
"""Levenberg-Marquardt iterations per coupling round before the fit counts as not converged."""
LOGMU_SPAN = 0.8
"""ln(mu_r) span of the two coupled solves that give the coupling's permeability slope."""


class FitNotConverged(RuntimeError, DesignkitError):
    """The calibration fit did not converge (nothing is written)."""


@dataclass
class FitResult:
    """The fit: parameters (n_coils, 8) and standard errors, fitted mask, diagnostics."""

    params: np.ndarray
    std_error: np.ndarray
    prior: np.ndarray
    fitted: np.ndarray
    cost_before: float
    cost_after: float
    condition: float
    iterations: int
    residual_before_t: np.ndarray = field(repr=False)
    residual_after_t: np.ndarray = field(repr=False)

    @property
    def identifiable(self) -> np.ndarray:
        """(n_coils, 8) bool: fitted and the data shrink the error below the ratio."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.fitted & (self.std_error < IDENTIFIABLE_RATIO * self.prior)


def fitted_mask(nominal_coils, tolerances: BuildTolerances) -> np.ndarray:
    """(n_coils, 8) bool: parameters with a tolerance > 0 that exist (core ones need a core)."""
    sig = tolerances.sigmas()
    mask = np.repeat((sig > 0)[None], len(nominal_coils), axis=0)
    for k, c in enumerate(nominal_coils):
        if c.core is None:
            mask[k, 6:] = False
    return mask


def check_enough(meas: Measurements, n_params: int) -> None:
    """Refuse a file with fewer independent readings than parameters (before the fit)."""
    rows = np.unique(np.round(np.c_[meas.points_m, meas.currents_a], 9), axis=0)
    if 3 * len(rows) < n_params:
        raise BadInputError("--measurements", f"at least {-(-n_params // 3)} distinct readings "
                            f"(point, currents) for {n_params} parameters (3 axes each)",
                            len(rows))


class _Problem:
    """Whitened residuals and Jacobian of one coupling round."""

    def __init__(self, model: ForwardModel, meas: Measurements, inverse, sig, mask):
        self.model, self.meas, self.inv = model, meas, inverse
        self.sig, self.mask = sig, mask
        self.w = 1.0 / meas.sigma_t[:, None]

    def theta(self, z):
        th = np.zeros(self.mask.shape)
        th[self.mask] = z * self.sig[self.mask]
        return th

    def residual(self, z, jacobian=False):
        res = self.model.columns(self.theta(z), jacobian)
        cols, jac, shared = res if jacobian else (res, None, None)
        pred = np.einsum("nik,nk->ni", cols[self.inv], self.meas.currents_a)
        r = np.concatenate([((pred - self.meas.b_t) * self.w).ravel(), z])
        if not jacobian:
            return r
        jd = np.einsum("nikp,nk->nikp", jac[self.inv], self.meas.currents_a)
        if shared is not None:
            cores = np.array([c.core is not None for c in self.model.nominal_coils])
            jd[:, :, cores, 6] += np.einsum("nik,nk->ni", shared[self.inv],
                                            self.meas.currents_a)[:, :, None]
        jd = jd[:, :, self.mask] * self.sig[self.mask] * self.w[:, :, None]
        return r, np.vstack([jd.reshape(-1, jd.shape[-1]), np.eye(len(z))])


def _levenberg_marquardt(prob: _Problem, z, bar):
    r, j = prob.residual(z, True)
    cost, lam = r @ r, 1e-3
    for it in range(1, MAX_ITERATIONS + 1):
        a, g = j.T @ j, j.T @ r
        step = np.linalg.solve(a + lam * np.diag(np.diag(a)), -g)
        r_new = prob.residual(z + step)
        cost_new = r_new @ r_new
        bar.update(1)
        bar.set_postfix(cost=f"{cost_new:.4g}")
        if cost_new < cost:
            # a chi-square change far below 1 is no information
            small = cost - cost_new < CHI2_TOLERANCE + 1e-4 * cost
            z, lam = z + step, max(lam / 3, 1e-9)
            cost = cost_new
            if small:
                return z, it
            r, j = prob.residual(z, True)
        else:
            # no descent left at the model's numerical precision
            if cost_new - cost < CHI2_TOLERANCE or lam > 1e6:
                return z, it
            lam *= 4
    raise FitNotConverged(f"the calibration fit did not converge in {MAX_ITERATIONS} "
                          f"iterations (cost {cost:.4g}); nothing written")


def fit(nominal_array: CoilArray, meas: Measurements, tolerances: BuildTolerances, *,
        coupling_rounds: int = 2, progress: bool = True) -> FitResult:
    """Fit the as-built parameters of ``nominal_array``'s coils to ``meas``."""
    coils = nominal_array.coils
    mask = fitted_mask(coils, tolerances)
    check_enough(meas, int(mask.sum()))
    sig = np.broadcast_to(tolerances.sigmas(), mask.shape)
    uniq, inv = meas.unique_points()
    zero = np.zeros(mask.shape)
    model = _coupled_model(coils, nominal_array, zero, uniq)
    prob = _Problem(model, meas, inv, sig, mask)
    z = np.zeros(int(mask.sum()))
    r0 = prob.residual(z)
    before = r0[:-len(z)].reshape(-1, 3) / prob.w
    iterations = 0
    with tqdm(total=MAX_ITERATIONS * (coupling_rounds + 1), desc="calibrate", unit="step",
              disable=not progress) as bar:
        for rnd in range(coupling_rounds + 1):
            if rnd:
                th = prob.theta(z)
                built = CoilArray(AsBuilt.from_parameters(coils, th).apply(coils),
                                  sensor_offset_m=nominal_array.sensor_offset_m)
                bar.set_description("calibrate (exact coupled solve)")
                prob.model = _coupled_model(coils, built, th, uniq, prob.model)
                bar.set_description("calibrate")
            z, it = _levenberg_marquardt(prob, z, bar)
            iterations += it
        bar.total = bar.n  # converged: the bar ends full
        bar.refresh()
    r, j = prob.residual(z, True)
    a = j.T @ j
    cov = np.linalg.inv(a)
    se = np.zeros(mask.shape)
    se[mask] = np.sqrt(np.diag(cov)) * sig[mask]
    eig = np.linalg.eigvalsh(a)
    return FitResult(prob.theta(z), se, np.array(sig), mask, float(r0 @ r0), float(r @ r),
                     float(eig[-1] / eig[0]), iterations, before,
                     r[:-len(z)].reshape(-1, 3) / prob.w)


def _coupled_model(coils, array: CoilArray, params, points, previous=None) -> ForwardModel:
    """The forward model with the coupling of ``array`` (built with ``params``) and its
    derivative by the cores' mean ln(mu_r) (from ``previous``, else two solves of ``array``'s
    geometry at its permeabilities and e^-LOGMU_SPAN times them)."""
    cores = [k for k, c in enumerate(coils) if c.core is not None]
    ref = float(np.mean(params[cores, 6])) if cores else 0.0
    c0 = coupling_term(coils, array, params, points)
    if previous is not None or not cores:
        return ForwardModel(coils, points, c0, None if previous is None
                            else previous.coupling_dlogmu, ref)
    p2 = np.array(params, dtype=float)
    p2[cores, 6] -= LOGMU_SPAN
    other = CoilArray(AsBuilt.from_parameters(coils, p2).apply(coils),
                      sensor_offset_m=array.sensor_offset_m)
    return ForwardModel(coils, points, c0, (c0 - coupling_term(coils, other, p2, points))
                        / LOGMU_SPAN, ref)


def actuation_error(a_model: np.ndarray, a_true: np.ndarray) -> np.ndarray:
    """Error of A(p) (n, 8, n_coils) per point and row, relative to the row's largest value
    over the points and coils of ``a_true``: max_k |dA[p, r, k]| / max |A_true[:, r, :]|,
    shape (n, 8)."""
    scale = np.abs(a_true).max(axis=(0, 2))
    return np.abs(a_model - a_true).max(axis=2) / scale


def posterior_std(jac_data: np.ndarray, prior: np.ndarray) -> np.ndarray:
    """Posterior standard deviations from a whitened data Jacobian (m, p) and the priors (p,)."""
    a = (jac_data * prior).T @ (jac_data * prior) + np.eye(len(prior))
    return np.sqrt(np.diag(np.linalg.inv(a))) * prior


__all__ = ["FitNotConverged", "actuation_error", "FitResult", "IDENTIFIABLE_RATIO", "PARAMETERS", "check_enough",
           "fit", "fitted_mask", "posterior_std"]
