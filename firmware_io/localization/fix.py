"""One frame's fix from a :class:`PoseFit`: :func:`locate` (warm or cold start, the integrity
verdict, the :class:`Estimate`).

The warm start is the caller's prior pose, else the last trusted fix; a warm fit that fails
its verdict or moved farther than ``reacquire_m`` is solved again from the global search's
best starts and the better verdict wins (trusted first, then the lower chi2 per degree of
freedom). The verdict (:func:`assess`): converged, inside the plausible box, chi2 within the
test's threshold, the normalized residual within its cap, the protection levels within the
alert limits. The protection levels: the fault-free bound of the covariance (inflated by
chi2 / dof above 1) plus the model-bias bounds (:mod:`.integrity`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .estimate import Estimate, Pose
from .integrity import orientation_protection_level, position_protection_level
from .pose import tangent_axes
from .pose_fit import PoseFit, Solution, State


@dataclass(frozen=True)
class Verdict:
    """The integrity of one solution: ok, reason, covariance (P, P) (inflated), the position
    and orientation protection levels (m, rad), dof, the blocks it excluded."""

    solution: Solution
    ok: bool
    reason: str
    covariance: np.ndarray | None
    pl_m: float
    pl_rad: float
    dof: int
    excluded: tuple = ()

    def rank(self) -> tuple:
        """Sort key: trusted first, then the lower chi2 per degree of freedom."""
        return (not self.ok, self.solution.chi2 / max(self.dof, 1))


def assess(fit: PoseFit, sol: Solution) -> Verdict:
    """The verdict of a solution (module docstring)."""
    s = fit.settings
    rows, unknowns = sol.jac.shape
    dof = rows - unknowns
    cov, pl_m, pl_rad = None, math.inf, math.inf
    try:
        cov0 = np.linalg.inv(sol.jac.T @ sol.jac)
    except np.linalg.LinAlgError:
        cov0 = None
    if cov0 is not None and np.all(np.isfinite(cov0)):
        cov = cov0 * max(1.0, sol.chi2 / max(dof, 1))
        pl_m = fit.bias_m + position_protection_level(cov[:3, :3], fit.k2)
        pl_rad = fit.bias_rad + orientation_protection_level(cov[3:5, 3:5], s.integrity_risk)
    reason = _failed(fit, sol, dof, pl_m, pl_rad)
    return Verdict(sol, not reason, reason, cov, pl_m, pl_rad, dof)


def _failed(fit: PoseFit, sol: Solution, dof: int, pl_m: float, pl_rad: float) -> str:
    """Why the solution is not trusted ('' when it is)."""
    s = fit.settings
    p = sol.state.p
    rms = math.sqrt(sol.chi2 / max(dof, 1))
    if dof < 1:
        return f"{len(sol.blocks)} usable sensors leave no redundancy"
    if not sol.converged:
        return "fit did not converge"
    if not (np.all(p > fit.lo + 1e-6) and np.all(p < fit.hi - 1e-6)):
        return "position at or outside the plausible box's edge"
    if not sol.chi2 <= fit.chi2_max[dof]:
        return (f"residual chi2 {sol.chi2:.3g} > {fit.chi2_max[dof]:.3g} ({dof} dof, "
                f"false-alarm {s.false_alarm:g}): lost or model error")
    if rms > s.residual_limit:
        return f"residual {rms:.3g} > {s.residual_limit:g} (lost or implausible)"
    if not (math.isfinite(pl_m) and math.isfinite(pl_rad)):
        return "singular Fisher information: the pose is not determined"
    if not pl_m <= s.alert_limit_m:
        return (f"protection level {pl_m * 1e3:.3g} mm > alert limit "
                f"{s.alert_limit_m * 1e3:.3g} mm")
    if not pl_rad <= s.orientation_alert_limit_rad:
        return (f"orientation protection level {math.degrees(pl_rad):.3g} deg > alert limit "
                f"{math.degrees(s.orientation_alert_limit_rad):.3g} deg")
    return ""


def locate(fit: PoseFit, d: np.ndarray, use: np.ndarray, sigma: np.ndarray,
           seed: Pose | None, method: str) -> Estimate:
    """The estimate of one frame's blocks: data d (b, 3) T (0 where unusable), ``use`` (b,),
    sigma (b,) T; ``seed`` a prior pose (None: the last trusted fix, else cold)."""
    blocks = np.flatnonzero(use)
    need = max(3, -(-(fit.n_unknowns(False) + 1) // 3))    # >= 1 degree of freedom
    if len(blocks) < need:
        return Estimate.refused(_fallback(fit), _moment(fit, fit.last), f"only {len(blocks)} "
                                f"usable sensors (need {need})", method)
    w_all = np.where(use, 1.0 / sigma, 0.0)
    w, db = w_all[blocks], d[blocks]
    start = (fit.initial_state(seed.position_m, seed.moment_a_m2) if seed is not None
             else fit.last)
    best = None
    if start is not None:
        best = assess(fit, fit.solve_corrected(start, blocks, w, db))
        moved = float(np.linalg.norm(best.solution.state.p - start.p))
        if best.ok and moved <= fit.settings.reacquire_m:
            return _estimate(fit, best, method)
    for st in fit.cold_starts(d, w_all ** 2):
        v = assess(fit, fit.solve_cold(st, blocks, w, db))
        if best is None or v.rank() < best.rank():
            best = v
        if best.ok:
            break
    return _estimate(fit, best, method)


def _estimate(fit: PoseFit, v: Verdict, method: str) -> Estimate:
    st = v.solution.state
    fit.last = st if v.ok else None
    k = 6 if fit.fit_scale else 5
    cov = None if v.covariance is None else v.covariance[:k, :k].copy()
    excluded = tuple(sorted(s for b in v.excluded for s in fit.block_sensors[b]))
    return Estimate(st.p.copy(), _moment(fit, st), v.ok, v.reason, cov, v.pl_m, v.pl_rad,
                    excluded, st.b.copy(), float(v.solution.chi2), v.dof,
                    len(v.solution.blocks), v.solution.iterations, method, tangent_axes(st.u))


def _moment(fit: PoseFit, st: State | None) -> np.ndarray:
    if st is None:
        return fit.model.moment_a_m2.copy()
    return fit.moment * math.exp(st.log_scale) * st.u


def _fallback(fit: PoseFit) -> np.ndarray:
    return (fit.last.p if fit.last is not None else 0.5 * (fit.lo + fit.hi)).copy()


def fallback_position(fit: PoseFit) -> np.ndarray:
    """(3,) m for a not-ok estimate without a fit: the last trusted position or the box's
    centre."""
    return _fallback(fit)
