"""The tracker's innovation gate and the multi-frame protection level of the rendered position.

A trusted fix is taken into the tracker only when it agrees with the tracker's prediction at
its frame time: squared Mahalanobis distance with both covariances (the fix's and the
prediction's plus the tracker's measurement noise) <= the chi-square(3) quantile at the gate
risk. A fix that fails asks the sensor side to re-acquire (the next fit starts from the global
search); a following fix solved cold (re-acquired, or its frame rejected the track's prior)
consistent with it confirms that the finger really moved (a warm fit could repeat a wrong
basin; a cold one would not). The protection level of the
position the runner renders is that of the tracker's filtered position once the fix is in
(:func:`firmware_io.localization.integrity.fused_protection_level`). docs/runner.md,
"Integrity".
"""

from __future__ import annotations

import math

import numpy as np

from ..localization.integrity import chi2_quantile, fused_protection_level, ratio_quantiles
from .frames import Fix

_ZERO3 = np.zeros((3, 3))


class InnovationGate:
    """The gate of one tracker (module docstring).

    Parameters
    ----------
    gate_risk : float -- probability that a correct fix fails the gate
    """

    def __init__(self, gate_risk: float):
        self.d2_max = chi2_quantile(gate_risk, 3)
        self.candidate: Fix | None = None     # a gated-out fix awaiting confirmation

    def check(self, fix: Fix, tracker) -> tuple[str, bool]:
        """('' or why the fix fails, whether the tracker must restart at this fix: a fix
        solved cold agrees with the gated fix before it, so the tracker was wrong, not the
        fix)."""
        if tracker.x is None:
            return "", False
        cov = fix.covariance_m2 if fix.covariance_m2 is not None else _ZERO3
        innov, var = tracker.innovation(fix.position_m, fix.frame_t_s)
        d2 = float(innov @ np.linalg.solve(cov + var * np.eye(3), innov))
        if d2 <= self.d2_max:
            self.candidate = None
            return "", False
        c = self.candidate
        if c is not None and (fix.reacquired or not fix.prior_used):
            cc = c.covariance_m2 if c.covariance_m2 is not None else _ZERO3
            dv = fix.position_m - c.position_m
            s = cov + cc + 2 * tracker.r * np.eye(3)
            if float(dv @ np.linalg.solve(s, dv)) <= self.d2_max:
                self.candidate = None
                return "", True
        self.candidate = fix
        return (f"fix {np.round(fix.position_m * 1e3, 1).tolist()} mm fails the tracker's gate "
                f"(Mahalanobis^2 {d2:.3g} > {self.d2_max:.3g}); re-acquiring"), False


def rendered_protection_level(fix: Fix, tracker, estimator) -> float:
    """The protection level (m) of the position the runner renders once ``fix`` (past the gate)
    is in the tracker: its filtered position, from the fix's covariance and the tracker's
    prediction, the estimator's ``model_bias_m`` kept whole, its quantile table from the
    estimator's ``integrity_risk``. Without a tracked state: the fix's own."""
    if tracker.x is None:
        return fix.protection_level_m
    _, var = tracker.innovation(fix.position_m, fix.frame_t_s)
    p = var - tracker.r
    if not math.isfinite(fix.protection_level_m):
        return math.inf
    return fused_protection_level(fix.protection_level_m, fix.covariance_m2, p,
                                  float(estimator.model_bias_m), p / var,
                                  ratio_quantiles(estimator.integrity_risk))
