"""Regularized nonlinear least squares of the as-built parameters to field measurements.

Minimizes ``sum_rows |(b_model - b_read) / sigma|^2 + sum_params (theta / tol)^2``: the
readings weighted by their noise, the priors the build tolerances
(:class:`designkit.design.asbuilt.BuildTolerances`, mean = nominal). Levenberg-Marquardt in the
whitened parameters ``z = theta / tol`` on :class:`ForwardModel`, whose coupling term is exact
at the last coupled solve and linear in each core's ln(mu_r) about it (exact slope, one adjoint
solve); after it converges the fitted device is solved exactly again and the fit repeated until
a new solve stops moving the cost. Standard errors: the whitened Gauss-Newton covariance of the
full Jacobian at the solution (times the reduced chi-square when above 1) plus, for the
model's own error, the parameter shift of the last coupling update. A
parameter is identifiable when the data shrink its standard error below
:data:`IDENTIFIABLE_RATIO` of its tolerance and its posterior correlation with every other
stays below :data:`CORRELATION_LIMIT`; nearly collinear pairs are reported as one combined
quantity. Reference: Petruska et al.,
"Model-based calibration for magnetic manipulation", IEEE Trans. Magn. 53 (2017);
docs/calibration.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..design.asbuilt import PARAMETERS, AsBuilt, BuildTolerances
from ..errors import BadInputError, DesignkitError
from ..model.array import CoilArray
from ..support.progress import tqdm
from .measurements import Measurements
from .model import ForwardModel, coupled_forward_model

IDENTIFIABLE_RATIO = 0.5
"""Posterior / prior standard deviation below which the data identify a parameter."""
CHI2_TOLERANCE = 0.1
"""Converged when an accepted step lowers the whitened cost by less than this plus 1e-4 of
the cost (a chi-square change far below 1 carries no information)."""
MAX_ITERATIONS = 40
"""Levenberg-Marquardt iterations per coupling round before the fit counts as not converged."""
COUPLING_CHI2 = 1.0
"""The coupling has converged when a new exact solve moves the whitened cost by less than this."""
CORRELATION_LIMIT = 0.9
"""|Posterior correlation| from which two parameters count as one combined quantity."""


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
    correlation: np.ndarray = field(default=None, repr=False)
    """(n_coils, 8) each parameter's largest posterior correlation with another (signed)."""
    partner: np.ndarray = field(default=None, repr=False)
    """(n_coils, 8) flat index (coil * 8 + parameter) of that other parameter, -1 if unfitted."""
    combined: list = field(default_factory=list, repr=False)
    """Pairs with |correlation| >= CORRELATION_LIMIT, identifiable only together
    (:func:`_combined`)."""

    @property
    def identifiable(self) -> np.ndarray:
        """(n_coils, 8) bool: fitted, the data shrink the error below the ratio, and not
        nearly one quantity with another parameter (those are in :attr:`combined`)."""
        with np.errstate(invalid="ignore", divide="ignore"):
            ok = self.fitted & (self.std_error < IDENTIFIABLE_RATIO * self.prior)
        if self.correlation is not None:
            ok &= np.abs(self.correlation) < CORRELATION_LIMIT
        return ok


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


class WhitenedProblem:
    """Whitened residuals and Jacobian of one coupling round: the fields' misfit divided by
    their noise sigma (T / T) and the prior z = theta / tolerance, in the fitted parameters
    ``mask`` (n_coils, 8) bool; ``inverse`` maps each measurement to its point."""

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
        cols, jac, cross = res if jacobian else (res, None, None)
        pred = np.einsum("nik,nk->ni", cols[self.inv], self.meas.currents_a)
        r = np.concatenate([((pred - self.meas.b_t) * self.w).ravel(), z])
        if not jacobian:
            return r
        jd = np.einsum("nikp,nk->nikp", jac[self.inv], self.meas.currents_a)
        if cross is not None:  # every column's coupling by each core's ln(mu_r)
            jd[:, :, :, 6] += np.einsum("nikj,nk->nij", cross[self.inv], self.meas.currents_a)
        jd = jd[:, :, self.mask] * self.sig[self.mask] * self.w[:, :, None]
        return r, np.vstack([jd.reshape(-1, jd.shape[-1]), np.eye(len(z))])


def _levenberg_marquardt(prob: WhitenedProblem, z, bar):
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
    """Fit the as-built parameters of ``nominal_array``'s coils to ``meas``.

    ``coupling_rounds``: at most this many exact coupled solves of the fitted device after the
    first fit (fewer when the coupling has converged, :data:`COUPLING_CHI2`)."""
    coils = nominal_array.coils
    mask = fitted_mask(coils, tolerances)
    check_enough(meas, int(mask.sum()))
    sig = np.broadcast_to(tolerances.sigmas(), mask.shape)
    uniq, inv = meas.unique_points()
    zero = np.zeros(mask.shape)
    model = coupled_forward_model(coils, nominal_array, zero, uniq)
    prob = WhitenedProblem(model, meas, inv, sig, mask)
    z = np.zeros(int(mask.sum()))
    r0 = prob.residual(z)
    before = r0[:-len(z)].reshape(-1, 3) / prob.w
    iterations, shift = 0, np.zeros_like(z)
    with tqdm(total=MAX_ITERATIONS * (coupling_rounds + 1), desc="calibrate", unit="step",
              disable=not progress) as bar:
        for rnd in range(coupling_rounds + 1):
            if rnd:
                th = prob.theta(z)
                built = CoilArray(AsBuilt.from_parameters(coils, th).apply(coils),
                                  sensor_offset_m=nominal_array.sensor_offset_m)
                bar.set_description("calibrate (exact coupled solve)")
                r_old = prob.residual(z)
                prob.model = coupled_forward_model(coils, built, th, uniq, prob.model)
                r_new, j = prob.residual(z, True)
                # the new coupling's pull on the parameters: what the last one got wrong
                shift = np.linalg.lstsq(j, r_old - r_new, rcond=None)[0]
                bar.set_description("calibrate")
                if np.sum(np.square(r_new - r_old)) < COUPLING_CHI2:
                    break
            z, it = _levenberg_marquardt(prob, z, bar)
            iterations += it
        bar.total = bar.n  # converged: the bar ends full
        bar.refresh()
    return _result(prob, z, r0, before, shift, iterations)


def _result(prob, z, r0, before, shift, iterations) -> FitResult:
    """Standard errors: Gauss-Newton covariance, scaled by the reduced chi-square when the
    residuals exceed the noise, plus the last coupling update's shift (model error)."""
    mask, sig = prob.mask, prob.sig
    r, j = prob.residual(z, True)
    a = j.T @ j
    cov = np.linalg.inv(a)
    n_data = len(r) - len(z)
    chi2 = float(np.sum(np.square(r[:n_data])))
    cov = cov * max(1.0, chi2 / max(n_data - len(z), 1))
    var = np.diag(cov) + np.square(shift)
    se = np.zeros(mask.shape)
    se[mask] = np.sqrt(var) * sig[mask]
    sd = np.sqrt(np.diag(cov))
    corr = cov / np.outer(sd, sd)
    np.fill_diagonal(corr, 0.0)
    partner = np.full(mask.shape, -1)
    rho = np.zeros(mask.shape)
    best = np.argmax(np.abs(corr), axis=1)
    flat = np.flatnonzero(mask.ravel())
    partner[mask] = flat[best]
    rho[mask] = corr[np.arange(len(z)), best]
    eig = np.linalg.eigvalsh(a)
    return FitResult(prob.theta(z), se, np.array(sig), mask, float(r0 @ r0), float(r @ r),
                     float(eig[-1] / eig[0]), iterations, before,
                     r[:n_data].reshape(-1, 3) / prob.w, rho, partner, _combined(
                         prob.theta(z), cov, shift, mask, sig, flat, corr))


def _combined(theta, cov, shift, mask, sig, flat, corr) -> list:
    """The parameter pairs with |posterior correlation| >= CORRELATION_LIMIT: each pair's
    best-determined combination ``sum c_i theta_i`` (c in 1/parameter unit, unit norm in
    tolerances, so its prior standard deviation is 1), its value and standard error (model
    error included), identifiable when that is below IDENTIFIABLE_RATIO."""
    out = []
    for a, b in zip(*np.nonzero(np.triu(np.abs(corr) >= CORRELATION_LIMIT))):
        sub = cov[np.ix_([a, b], [a, b])]
        w, v = np.linalg.eigh(sub)
        vec = v[:, 0]
        ka, ja = np.unravel_index(flat[a], mask.shape)
        kb, jb = np.unravel_index(flat[b], mask.shape)
        coef = vec / np.array([sig[ka, ja], sig[kb, jb]])
        se = float(np.sqrt(w[0] + (vec @ shift[[a, b]]) ** 2))
        out.append({"parameters": ((int(ka), int(ja)), (int(kb), int(jb))),
                    "correlation": float(corr[a, b]), "coefficients": coef.tolist(),
                    "value": float(coef @ [theta[ka, ja], theta[kb, jb]]),
                    "std_error": se,
                    "identifiable": bool(se < IDENTIFIABLE_RATIO * np.hypot(*vec))})
    return out


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
           "CORRELATION_LIMIT",
           "fit", "fitted_mask", "posterior_std"]
