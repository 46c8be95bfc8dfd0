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
    """(covariance (3, 3) m^2, protection level m) from the Fisher information (the upper-left
    3 x 3 block of ``fisher``, nested lists, 1/m^2: the fit's Gram matrix), the residual's chi2 and dof and k2 = the chi-square(3) quantile at the
    integrity risk. Singular or non-finite information -> (None, inf). Closed forms on Python
    floats (the inverse by the adjugate, the largest eigenvalue by the trigonometric formula
    for a symmetric 3 x 3 matrix): this runs on every fix."""
    (a, b, c), (d, e), f = fisher[0][:3], fisher[1][1:3], fisher[2][2]
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    det = a * c00 + b * c01 + c * c02
    if not (math.isfinite(det) and det > 0.0):
        return None, math.inf
    scale = (chi2 / dof if dof > 0 and chi2 > dof else 1.0) / det
    m = [[c00 * scale, c01 * scale, c02 * scale], [0.0, (a * f - c * c) * scale,
                                                   (b * c - a * e) * scale],
         [0.0, 0.0, (a * d - b * b) * scale]]
    m[1][0], m[2][0], m[2][1] = m[0][1], m[0][2], m[1][2]
    lam = _largest_eigenvalue(m)
    if not (math.isfinite(lam) and lam > 0):
        return None, math.inf
    return np.array(m), math.sqrt(lam * k2)


def fused_protection_level(pl: float, cov, var_pred: float, bias: float,
                           gain: float) -> float:
    """Protection level (m) of a tracker's filtered position (1 - K) x_pred + K x_fix, K =
    ``gain``, from the fix's covariance ``cov`` (3, 3) m^2 and the prediction's variance
    ``var_pred`` m^2 per axis (from the earlier fixes, independent noise): the filtered error's
    covariance is (1 - K)^2 var_pred I + K^2 C, so the fix's own noise part ``pl - bias`` scales
    by sqrt(((1 - K)^2 var_pred + K^2 lambda_max(C)) / lambda_max(C)); the model-bias part
    ``bias`` (m, common to every frame: filtering does not shrink it) stays. Degenerate inputs:
    ``pl`` unchanged."""
    if cov is None or not (math.isfinite(pl) and var_pred > 0 and 0 <= gain <= 1):
        return pl
    lam = float(np.linalg.eigvalsh(cov)[-1])
    if not (math.isfinite(lam) and lam > 0):
        return pl
    filtered = (1 - gain) ** 2 * var_pred + gain ** 2 * lam
    return bias + max(pl - bias, 0.0) * math.sqrt(filtered / lam)


def _largest_eigenvalue(m) -> float:
    """Largest eigenvalue of a symmetric 3 x 3 matrix (nested lists): Smith, Comm. ACM 4, 168
    (1961)."""
    p1 = m[0][1] ** 2 + m[0][2] ** 2 + m[1][2] ** 2
    q = (m[0][0] + m[1][1] + m[2][2]) / 3.0
    p2 = (m[0][0] - q) ** 2 + (m[1][1] - q) ** 2 + (m[2][2] - q) ** 2 + 2.0 * p1
    if p2 <= 1e-30 * q * q:
        return max(m[0][0], m[1][1], m[2][2])
    p = math.sqrt(p2 / 6.0)
    b00, b11, b22 = (m[0][0] - q) / p, (m[1][1] - q) / p, (m[2][2] - q) / p
    b01, b02, b12 = m[0][1] / p, m[0][2] / p, m[1][2] / p
    r = 0.5 * (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
               + b02 * (b01 * b12 - b11 * b02))
    phi = math.acos(min(max(r, -1.0), 1.0)) / 3.0
    return q + 2.0 * p * math.cos(phi)
