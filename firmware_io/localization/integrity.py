"""Integrity of a position fix, as satellite navigation defines it (RAIM): a covariance, a
residual test and a protection level.

The fit minimizes chi2 = sum r_i^2 / sigma_i^2 over the usable sensor axes (sigma: noise plus
the model-error terms, :class:`firmware_io.localization.Localizer`). Under that noise model
chi2 at the solution follows a chi-square law with dof = 3 m - 3 (m sensors, 3 unknowns); the
fix passes the residual test when chi2 <= the (1 - p_fa) quantile. Its covariance is the
inverse Fisher information (J^T W J)^-1, m^2, inflated by chi2 / dof when the residual says the
noise is larger than modelled. The protection level bounds the position error |e| with
probability 1 - risk: for a Gaussian e ~ N(0, C), e^T C^-1 e follows chi-square(3) and
|e|^2 <= lambda_max(C) e^T C^-1 e, so PL = sqrt(lambda_max(C) q3(1 - risk)) (m), plus the
localizer's bound on the bias the noise model leaves out (sensor poses, core model). A fix is
usable when it passes the test and PL <= the alert limit. Reference: Brown, "A baseline GPS
RAIM scheme", Navigation 39 (1992); Walter & Enge, ION GPS 1995 (weighted RAIM).
numpy only (runs on the controller).
"""

from __future__ import annotations

import functools
import math

import numpy as np


def chi2_sf(x: float, dof: int) -> float:
    """P(X > x) for X ~ chi-square(dof), integer dof >= 1 (closed forms: the even case is a
    Poisson sum, the odd case erfc plus a half-integer sum)."""
    if x <= 0:
        return 1.0
    h = 0.5 * x
    if dof % 2 == 0:
        term, total = 1.0, 1.0
        for j in range(1, dof // 2):
            term *= h / j
            total += term
        return min(math.exp(-h) * total, 1.0)
    total = math.erfc(math.sqrt(h))
    term = math.sqrt(h) / math.gamma(1.5)
    for j in range(1, (dof + 1) // 2):
        total += math.exp(-h) * term
        term *= h / (j + 0.5)
    return min(total, 1.0)


@functools.lru_cache(maxsize=None)
def chi2_quantile(p_exceed: float, dof: int) -> float:
    """x with P(X > x) = p_exceed for X ~ chi-square(dof) (bisection on :func:`chi2_sf`)."""
    lo, hi = 0.0, float(dof) + 10.0 * math.sqrt(2.0 * dof) + 60.0
    while chi2_sf(hi, dof) > p_exceed:
        hi *= 2.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if chi2_sf(mid, dof) > p_exceed:
            lo = mid
        else:
            hi = mid
    return hi


def thresholds(p_fa: float, max_dof: int) -> list:
    """The residual test's thresholds for dof = 0 .. max_dof (index = dof; dof 0: +inf)."""
    return [math.inf] + [chi2_quantile(p_fa, k) for k in range(1, max_dof + 1)]


def covariance_and_pl(fisher, chi2: float, dof: int, k2: float):
    """(covariance (3, 3) m^2, protection level m) from the Fisher information (3 x 3, 1/m^2,
    nested lists or array), the residual's chi2 and dof and k2 = the chi-square(3) quantile at
    the integrity risk. Singular or non-finite information -> (None, inf)."""
    f = np.array(fisher, dtype=float)
    if not np.all(np.isfinite(f)):
        return None, math.inf
    try:
        cov = np.linalg.inv(f)
    except np.linalg.LinAlgError:
        return None, math.inf
    if dof > 0 and chi2 > dof:
        cov = cov * (chi2 / dof)
    lam = float(np.linalg.eigvalsh(cov)[-1])
    if not (math.isfinite(lam) and lam > 0):
        return None, math.inf
    return cov, math.sqrt(lam * k2)
