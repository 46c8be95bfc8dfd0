"""A measurement plan from the Fisher information of the calibration fit.

The fit's whitened Jacobian J (readings / sigma by parameters / tolerance) at the nominal device
gives the information ``I + J^T J`` (the identity: the priors). The onboard arrays' readings
(each coil alone at +-2 A) come first; probe points are then added greedily from a grid over
the workspace box, each read with every coil alone at ``current_a``, choosing the point that
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
    """A grid over the workspace box (per_axis^2 x heights points), m."""
    ws = design.workspace
    xs = np.linspace(-ws.half_width_m, ws.half_width_m, per_axis)
    zs = np.linspace(ws.z_min_m, ws.z_max_m, heights)
    X, Y, Z = np.meshgrid(xs, xs, zs, indexing="ij")
    return np.c_[X.ravel(), Y.ravel(), Z.ravel()]


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
    onboard = onboard_plan(array.sensor_positions_m(), n_coils, onboard_current_a,
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
