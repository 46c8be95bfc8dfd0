"""A measurement plan from the Fisher information of the calibration fit.

The fit's whitened Jacobian J (readings / sigma by parameters / tolerance) at the nominal device
gives the information ``I + J^T J`` (the identity: the priors). The onboard sensors' readings
(each coil alone at +-2 A) come first; probe points are then added greedily from a grid over
the workspace region, each read with every coil alone at ``current_a``, choosing the point that
raises log det of the information most (D-optimal; the matrix determinant lemma keeps each
choice a small determinant). Outputs: the probe rows (m, A, T) and each parameter's posterior
standard deviation with the onboard arrays alone and with the plan.
"""

from __future__ import annotations

import numpy as np

from ..design.asbuilt import BuildTolerances
from .fit import WhitenedProblem, fitted_mask
from .measurements import Measurements, onboard_plan, probe_plan
from .model import coupled_forward_model


def candidate_points(design, per_axis: int = 7, heights: int = 3) -> np.ndarray:
    """A grid over the workspace region (:meth:`Design.workspace_region`): per_axis x per_axis
    over its bounding box, the points inside its outline, at ``heights`` levels from z_min to
    z_max, m."""
    region = design.workspace_region()
    lo, hi = region.bounds_m()
    xs = np.linspace(lo[0], hi[0], per_axis)
    ys = np.linspace(lo[1], hi[1], per_axis)
    zs = np.linspace(lo[2], hi[2], heights)
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    pts = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    return pts[region.contains(pts)]


def _jacobian(array, meas: Measurements, tol: BuildTolerances, mask) -> np.ndarray:
    coils = array.coils
    uniq, inv = meas.unique_points()
    model = coupled_forward_model(coils, array, np.zeros(mask.shape), uniq)
    sig = np.broadcast_to(tol.sigmas(), mask.shape)
    _, j = WhitenedProblem(model, meas, inv, sig, mask).residual(np.zeros(int(mask.sum())), True)
    return j[:-int(mask.sum())]


def _posterior(info) -> np.ndarray:
    """Posterior / prior standard deviation per parameter from the whitened information."""
    return np.sqrt(np.diag(np.linalg.inv(info)))


def make_plan(design, array, n_points: int, tol: BuildTolerances, *, current_a: float = 1.0,
              sigma_t: float = 2e-5, onboard_current_a: float = 2.0,
              onboard_sigma_t: float = 5e-5) -> dict:
    """Greedy D-optimal probe points after the onboard arrays.

    Returns dict: ``plan`` (Measurements of the probe, readings zero), ``points_m`` (n, 3),
    ``onboard_ratio`` / ``plan_ratio`` (n_coils, 8) posterior / prior standard deviation
    (NaN for parameters not fitted), ``mask`` (n_coils, 8) fitted.
    """
    mask = fitted_mask(array.coils, tol)
    n_coils = array.n_coils
    onboard = onboard_plan(array.sensor_poses()[0], n_coils, onboard_current_a,
                           onboard_sigma_t)
    j_on = _jacobian(array, onboard, tol, mask)
    info = np.eye(int(mask.sum())) + j_on.T @ j_on
    onboard_ratio = _posterior(info)
    cand = candidate_points(design)
    j_c = _jacobian(array, probe_plan(cand, n_coils, current_a, sigma_t), tol, mask)
    # rows of one candidate: each coil alone (coil-major), 3 axes each
    j_c = j_c.reshape(n_coils, len(cand), 3, -1).transpose(1, 0, 2, 3).reshape(
        len(cand), 3 * n_coils, -1)
    chosen = []
    for _ in range(min(n_points, len(cand))):
        m_inv = np.linalg.inv(info)
        gain = np.full(len(cand), -np.inf)
        for c in range(len(cand)):
            if c in chosen:
                continue
            s = np.eye(j_c.shape[1]) + j_c[c] @ m_inv @ j_c[c].T
            gain[c] = np.linalg.slogdet(s)[1]
        best = int(np.argmax(gain))
        chosen.append(best)
        info = info + j_c[best].T @ j_c[best]
    pts = cand[chosen]

    def full(ratio):
        out = np.full(mask.shape, np.nan)
        out[mask] = ratio
        return out

    return {"plan": probe_plan(pts, n_coils, current_a, sigma_t), "points_m": pts,
            "onboard_ratio": full(onboard_ratio), "plan_ratio": full(_posterior(info)),
            "mask": mask}
