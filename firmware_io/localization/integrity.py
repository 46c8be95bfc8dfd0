"""Integrity of a position fix, as satellite navigation defines it (RAIM): a covariance, a
residual test and a protection level.

The fit minimizes chi2 = sum r_i^2 / sigma_i^2 over the usable sensor axes (sigma: noise plus
the model-error terms, :class:`firmware_io.localization.EstimatorSettings`). Under that noise
model chi2 at the solution follows a chi-square law with dof = 3 m - 3 (m sensors, 3 unknowns); the
fix passes the residual test when chi2 <= the (1 - p_fa) quantile. Its covariance is the
inverse Fisher information (J^T W J)^-1, m^2, inflated by chi2 / dof when the residual says the
noise is larger than modelled. The protection level bounds the position error |e| with
probability 1 - risk: for a Gaussian e ~ N(0, C) with eigenvalues l1 >= l2 >= l3,
|e|^2 = l1 z1^2 + l2 z2^2 + l3 z3^2 <= l1 (z1^2 + r (z2^2 + z3^2)), r = l2 / l1, so PL =
sqrt(l1 k(r)) with k(r) that quantile (chi-square(1) at r = 0, chi-square(3) at r = 1; r rounded
up on a table), plus the localizer's bound on the bias the noise model leaves out. A fix is
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


RATIO_STEPS = 20
"""Steps of the table of k(r) over r = l2 / l1 in [0, 1] (r rounded up to a step)."""


def _ratio_step(r: float) -> int:
    """Table index of r = l2 / l1 rounded up (at least 1: the bound of
    :func:`fused_protection_level` divides by the tabulated ratio)."""
    return min(max(math.ceil(r * RATIO_STEPS - 1e-12), 1), RATIO_STEPS)


def _tail(k: np.ndarray, r: np.ndarray, nodes: int = 4001) -> np.ndarray:
    """P(z1^2 + r X > k), z1 ~ N(0, 1), X ~ chi-square(2) (exponential, mean 2), for arrays k
    and r in (0, 1]: P(z1^2 > k) + int_0^sqrt(k) 2 phi(u) exp(-(k - u^2) / (2 r)) du
    (conditioning on z1 = u; trapezoid rule)."""
    t = np.linspace(0.0, 1.0, nodes)
    u = np.sqrt(k)[:, None] * t
    f = 2.0 * np.exp(-0.5 * u * u - (k[:, None] - u * u) / (2.0 * r[:, None])) / math.sqrt(
        2.0 * math.pi)
    integral = (f.sum(1) - 0.5 * (f[:, 0] + f[:, -1])) * np.sqrt(k) / (nodes - 1)
    return np.array([math.erfc(math.sqrt(0.5 * x)) for x in k]) + integral


@functools.lru_cache(maxsize=None)
def ratio_quantiles(risk: float) -> tuple:
    """k_j, j = 0 .. RATIO_STEPS: P(z1^2 + r_j (z2^2 + z3^2) > k_j) = risk at r_j = j /
    RATIO_STEPS (k_0: chi-square(1), k_RATIO_STEPS: chi-square(3) quantile). Bisection on
    :func:`_tail`, all ratios at once."""
    r = np.arange(1, RATIO_STEPS + 1) / RATIO_STEPS
    lo = np.full(RATIO_STEPS, chi2_quantile(risk, 1))
    hi = np.full(RATIO_STEPS, chi2_quantile(risk, 3) * 1.01)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        above = _tail(mid, r) > risk
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    return (chi2_quantile(risk, 1),) + tuple(float(x) for x in hi)


def covariance_and_pl(fisher, chi2: float, dof: int, k2):
    """(covariance (3, 3) m^2, protection level m) from the Fisher information (the upper-left
    3 x 3 block of ``fisher``, nested lists, 1/m^2: the fit's Gram matrix), the residual's chi2
    and dof and k2: the table :func:`ratio_quantiles` at the integrity risk (or one number, the
    chi-square(3) quantile: the isotropic bound). Singular or non-finite information -> (None,
    inf). Closed forms on Python floats (the inverse by the adjugate, the eigenvalues by the
    trigonometric formula for a symmetric 3 x 3 matrix): this runs on every fix."""
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
    lam, lam2 = _eigenvalues(m)[:2]
    if not (math.isfinite(lam) and lam > 0):
        return None, math.inf
    k = k2 if isinstance(k2, float) else k2[_ratio_step(max(lam2, 0.0) / lam)]
    return np.array(m), math.sqrt(lam * k)


def fused_protection_level(pl: float, cov, var_pred: float, bias: float, gain: float,
                           table=None) -> float:
    """Protection level (m) of a tracker's filtered position (1 - K) x_pred + K x_fix, K =
    ``gain``, from the fix's covariance ``cov`` (3, 3) m^2 and the prediction's variance
    ``var_pred`` m^2 per axis (from the earlier fixes, independent noise): the filtered error's
    covariance is (1 - K)^2 var_pred I + K^2 C, so the fix's own noise part ``pl - bias`` scales
    by sqrt(((1 - K)^2 var_pred + K^2 l1) / l1) (l1 >= l2: C's largest eigenvalues); the
    model-bias part ``bias`` (m, common to every frame: filtering does not shrink it) stays.
    The filtered covariance is rounder (ratio r' = l2' / l1' >= the fix's r), so its quantile
    grows too: by k(r'_j) / k(r_j) from ``table``, the :func:`ratio_quantiles` table the fix's
    PL came from (:func:`covariance_and_pl`: r rounded up to r_j); without one (an isotropic or
    unknown quantile) by the bound r' / r_j (z1^2 + r' X <= (r' / r_j)(z1^2 + r_j X)).
    Degenerate inputs: ``pl`` unchanged."""
    if cov is None or not (math.isfinite(pl) and var_pred > 0 and 0 <= gain <= 1):
        return pl
    lam, lam2 = _eigenvalues(np.asarray(cov, float).tolist())[:2]
    if not (math.isfinite(lam) and lam > 0):
        return pl
    a = (1 - gain) ** 2 * var_pred
    filtered = a + gain ** 2 * lam
    ratio = (a + gain ** 2 * max(lam2, 0.0)) / filtered
    j = _ratio_step(max(lam2, 0.0) / lam)
    if table is None:
        growth = max(ratio / (j / RATIO_STEPS), 1.0)
    else:
        growth = table[max(_ratio_step(ratio), j)] / table[j]
    return bias + max(pl - bias, 0.0) * math.sqrt(filtered / lam * growth)


def _eigenvalues(m) -> tuple:
    """Eigenvalues, largest first, of a symmetric 3 x 3 matrix (nested lists): Smith, Comm. ACM
    4, 168 (1961)."""
    p1 = m[0][1] ** 2 + m[0][2] ** 2 + m[1][2] ** 2
    q = (m[0][0] + m[1][1] + m[2][2]) / 3.0
    p2 = (m[0][0] - q) ** 2 + (m[1][1] - q) ** 2 + (m[2][2] - q) ** 2 + 2.0 * p1
    if p2 <= 1e-30 * q * q:
        return tuple(sorted((m[0][0], m[1][1], m[2][2]), reverse=True))
    p = math.sqrt(p2 / 6.0)
    b00, b11, b22 = (m[0][0] - q) / p, (m[1][1] - q) / p, (m[2][2] - q) / p
    b01, b02, b12 = m[0][1] / p, m[0][2] / p, m[1][2] / p
    r = 0.5 * (b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02)
               + b02 * (b01 * b12 - b11 * b02))
    phi = math.acos(min(max(r, -1.0), 1.0)) / 3.0
    big = q + 2.0 * p * math.cos(phi)
    small = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
    return big, 3.0 * q - big - small, small


def noncentral_chi2_cdf(x: float, dof: int, lam: float) -> float:
    """P(X <= x) for X ~ noncentral chi-square(dof, lam): the Poisson(lam / 2) mixture of
    chi-square(dof + 2 j) (:func:`_central_cdfs`)."""
    return float(_mixture_cdf(_central_cdfs(x, dof, _poisson_terms(lam)), lam))


def _poisson_terms(lam: float) -> int:
    """Poisson(lam / 2) terms that carry all but ~1e-16 of the weight."""
    h = 0.5 * lam
    return int(h + 12.0 * math.sqrt(h + 1.0) + 40.0)


def _central_cdfs(x: float, dof: int, terms: int) -> np.ndarray:
    """P(chi-square(dof + 2 j) <= x), j = 0 .. terms - 1, from the recurrence
    sf(x, nu + 2) = sf(x, nu) + (x / 2)^(nu / 2) exp(-x / 2) / Gamma(nu / 2 + 1)."""
    nu = dof + 2.0 * np.arange(terms - 1)
    log_step = 0.5 * nu * math.log(0.5 * x) - 0.5 * x - np.array(
        [math.lgamma(v / 2.0 + 1.0) for v in nu]) if x > 0 else np.full(terms - 1, -np.inf)
    sf = chi2_sf(x, dof) + np.r_[0.0, np.cumsum(np.exp(log_step))]
    return np.clip(1.0 - sf, 0.0, 1.0)


def _mixture_cdf(cdfs: np.ndarray, lam: float) -> float:
    j = np.arange(len(cdfs))
    if lam <= 0:
        return float(cdfs[0])
    h = 0.5 * lam
    log_w = -h + j * math.log(h) - np.cumsum(np.log(np.maximum(j, 1)))
    return float(np.exp(log_w) @ cdfs)


@functools.lru_cache(maxsize=None)
def missed_detection_noncentrality(p_fa: float, p_md: float, dof: int) -> float:
    """The noncentrality lam at which the residual test (chi-square(dof) beyond its (1 - p_fa)
    quantile) misses a fault with probability p_md: P(X <= T) = p_md for X ~ noncentral
    chi-square(dof, lam) (RAIM's pbias^2; Brown, Navigation 39 (1992)). Bisection."""
    t = chi2_quantile(p_fa, dof)
    hi = 4.0 * t + 100.0
    cdfs = _central_cdfs(t, dof, _poisson_terms(hi))
    while _mixture_cdf(cdfs[:_poisson_terms(hi)], hi) > p_md or _poisson_terms(hi) > len(cdfs):
        hi *= 2.0
        cdfs = _central_cdfs(t, dof, _poisson_terms(hi))
    lo = 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if _mixture_cdf(cdfs, mid) > p_md:
            lo = mid
        else:
            hi = mid
    return hi


def largest_eigenvalues(m: np.ndarray) -> tuple:
    """(l1, l2) of a symmetric 3 x 3 or 2 x 2 matrix (closed forms)."""
    if m.shape == (2, 2):
        a, b, c = float(m[0, 0]), float(m[0, 1]), float(m[1, 1])
        mid, rad = 0.5 * (a + c), math.hypot(0.5 * (a - c), b)
        return mid + rad, mid - rad
    return _eigenvalues(m.tolist())[:2]


def position_protection_level(cov: np.ndarray, k2) -> float:
    """sqrt(l1 k(r)) for the position covariance ``cov`` (3, 3) m^2 and the ratio table ``k2``
    (:func:`ratio_quantiles`): the fault-free bound of the module docstring (inf when singular)."""
    lam, lam2 = largest_eigenvalues(cov)
    if not (math.isfinite(lam) and lam > 0):
        return math.inf
    return math.sqrt(lam * k2[_ratio_step(max(lam2, 0.0) / lam)])


def orientation_protection_level(cov: np.ndarray, risk: float) -> float:
    """sqrt(l1 q) for the moment direction's 2 x 2 covariance (rad^2), q the chi-square(2)
    quantile at ``risk`` (|e|^2 <= l1 (z1^2 + z2^2)): the fault-free bound, rad."""
    lam = largest_eigenvalues(cov)[0]
    if not (math.isfinite(lam) and lam > 0):
        return math.inf
    return math.sqrt(lam * chi2_quantile(risk, 2))
