"""One frame's fix from a :class:`PoseFit`: :func:`locate` (warm or cold start, the integrity
verdict with fault exclusion, the :class:`Estimate`).

The warm start is the caller's prior pose, else the last trusted fix; a warm fit that fails
its verdict or moved farther than ``reacquire_m`` is solved again from the global search's
best starts and the better verdict wins (trusted first, then the lower chi2 per degree of
freedom); the first consistent start ends the search. A prior with a covariance is also an
observation: a block it cannot explain is excluded before the solve (innovation screening),
and when the frame agrees with the prior (the fit passes every test but the alert limits) its
fix is returned, trusted or not, without the search. The verdict (:func:`assess`): converged, inside the plausible box, chi2 within the
test's threshold, the normalized residual within its cap, the protection levels within the
alert limits. The protection levels (position, orientation): the model-bias bound plus the
larger of the fault-free bound of the covariance (inflated by chi2 / dof above 1) and the
undetected single-sensor fault's (:mod:`.fde`): max over sensors of slope x sqrt(lam_md) for
a fault of any shape, or of the worst undetected offset or gain error within their bounds
(``settings.fault_model``).
Fault exclusion (RAIM FDE): when chi2 fails its test, the sensor whose removal lowers chi2 the
most is excluded if the rest then passes and no other single sensor's removal would
(separation); the fit is solved again without it and judged anew, up to ``max_exclusions``.
When no single sensor explains it, the ambient field's gradient is tried (``gradient``
'auto'): kept when it lowers chi2 by more than the chi-square(5) quantile at the false-alarm
probability and the fit then passes; a field the gradient cannot describe either (a steel
object near the sensors) stays refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .estimate import Estimate, Pose
from .fde import bounded_fault_bias, exclusion_drops, fault_slopes, projections
from .integrity import orientation_protection_level, position_protection_level
from .levenberg import beyond
from .pose import tangent_axes
from .pose_fit import PRIOR_ITERATIONS, PoseFit, Solution, State


@dataclass(frozen=True)
class Verdict:
    """The integrity of one solution: ok, reason, covariance (P, P) (inflated), the position
    and orientation protection levels (m, rad), dof, the blocks it excluded; ``consistent``:
    it passed every test but the alert limits; ``free``: the fault-free protection levels (the
    model bias and the covariance's bound, without the undetected fault) (m, rad)."""

    solution: Solution
    ok: bool
    reason: str
    covariance: np.ndarray | None
    pl_m: float
    pl_rad: float
    dof: int
    excluded: tuple = ()
    consistent: bool = False
    free: tuple = (math.inf, math.inf)

    def rank(self) -> tuple:
        """Sort key: trusted first, then consistent, then converged, then the lower chi2 per
        degree of freedom."""
        return (not self.ok, not self.consistent, not self.solution.converged,
                self.solution.chi2 / max(self.dof, 1))


@dataclass(frozen=True)
class Blocks:
    """One frame's observation blocks: data d (b, 3) T (0 where unusable), weights w (b,)
    1 / sigma (0 where unusable), the readings whose gain a fault would change (b, 3) T."""

    d: np.ndarray
    w: np.ndarray
    reading: np.ndarray


def assess(fit: PoseFit, sol: Solution, frame: Blocks, excluded: tuple = (),
           gradient: bool = True) -> Verdict:
    """The verdict of a solution (module docstring), with fault exclusion when chi2 fails and,
    unless ``gradient`` is False, the ambient field's gradient when no sensor explains it."""
    s = fit.settings
    rows, unknowns = sol.jac.shape
    dof = rows - unknowns
    cov, pl_m, pl_rad, kt = None, math.inf, math.inf, None
    free_m, free_rad = math.inf, math.inf
    k = 3 * len(sol.blocks)                     # the sensors' rows (a prior's follow)
    try:
        cov0 = np.linalg.inv(sol.jac.T @ sol.jac)
    except np.linalg.LinAlgError:
        cov0 = None
    if cov0 is not None and dof >= 1 and np.all(np.isfinite(cov0)):
        inflate = max(1.0, sol.chi2 / dof)
        cov = cov0 * inflate
        kt = projections(sol.jac[:k], cov0)
        fault_m, fault_rad = _fault_bias(fit, sol, frame, kt, fit.lam_md[dof])
        scale = math.sqrt(inflate)
        noise_m = position_protection_level(cov[:3, :3], fit.k2)
        pl_m = fit.bias_m + max(noise_m, fault_m * scale)
        free_m = fit.bias_m + noise_m
        if fit.n_rot:
            noise_rad = orientation_protection_level(cov[3:5, 3:5], s.integrity_risk)
            pl_rad = fit.bias_rad + max(noise_rad, fault_rad * scale)
            free_rad = fit.bias_rad + noise_rad
    inconsistent = _inconsistent(fit, sol, dof, pl_m, pl_rad)
    reason = inconsistent or _beyond_limits(fit, pl_m, pl_rad)
    verdict = Verdict(sol, not reason, reason, cov, pl_m, pl_rad, dof, excluded,
                      not inconsistent, (free_m, free_rad))
    if kt is None or (sol.chi2 <= fit.chi2_max[dof] and sol.converged):
        return verdict
    if len(excluded) < s.max_exclusions and dof > 3:
        drops = exclusion_drops(sol.jac[:k], sol.res[:k], kt)
        better = _exclude(fit, sol, frame, drops, dof, excluded)
        if better is not None:
            return better
    if gradient and s.gradient == "auto" and sol.state.g is None and dof > 5 and not excluded:
        return _with_gradient(fit, sol, frame) or verdict
    return verdict


def _fault_bias(fit: PoseFit, sol: Solution, frame: Blocks, kt: np.ndarray, lam_md: float):
    """The worst undetected single-sensor fault's bias (m, rad) per the fault model; ``kt``
    the blocks' gains (:func:`.fde.projections`)."""
    jac = sol.jac[:3 * len(sol.blocks)]
    if fit.settings.fault_model == "any":
        root = math.sqrt(lam_md)
        slope_p, slope_u = fault_slopes(jac, kt, fit.n_rot)
        return float(slope_p.max()) * root, float(slope_u.max()) * root
    s = fit.settings
    if not (s.fault_offset_t or s.fault_gain):
        return 0.0, 0.0
    w = frame.w[sol.blocks]
    reading = frame.reading[sol.blocks]
    # an offset or a gain error on one axis (the larger of the two), a gain error on all three
    axis_amp = w[:, None] * np.maximum(s.fault_offset_t, s.fault_gain * np.abs(reading))
    dp, du = bounded_fault_bias(jac, kt, axis_amp, (s.fault_gain * w)[:, None] * reading,
                                lam_md, fit.n_rot)
    return float(dp.max()), float(du.max())


HOPELESS = 4.0
"""A hypothesis tested on a fit that failed its residual test (one sensor excluded, or the
ambient field's gradient added) is kept only when its fit passes the test; one whose
linearized best chi2 (where one Gauss-Newton step says its minimum is) exceeds this many times
the test's threshold is not solved, or its solve is abandoned (not converged: never trusted).
The margin covers the model's curvature over the step."""


def _with_gradient(fit: PoseFit, sol: Solution, frame: Blocks) -> Verdict | None:
    """The verdict with the ambient field's gradient fitted too, when it is significant and
    passes the test (module docstring); else None. Not solved, or abandoned, while even its
    linearized best (:func:`_linearized_chi2`) stays beyond :data:`HOPELESS` times the
    threshold."""
    st = sol.state
    start = State(st.p, st.u, st.log_scale, st.b, np.zeros(5))
    blocks = sol.blocks
    w, d = frame.w[blocks], frame.d[blocks]
    first = fit.rows(start, blocks, w, d)
    dof = first[0].shape[0] - first[0].shape[1]
    bound = HOPELESS * fit.chi2_max[dof] if dof >= 1 else -math.inf
    if _linearized_chi2(*first) > bound:
        return None
    again = fit.solve_corrected(start, blocks, w, d, first, give_up=beyond(bound))
    dof = again.jac.shape[0] - again.jac.shape[1]
    if not (again.converged and sol.chi2 - again.chi2 > fit.gradient_drop
            and again.chi2 <= fit.chi2_max[dof]):
        return None
    return assess(fit, again, frame)


def _exclude(fit: PoseFit, sol: Solution, frame: Blocks, drops: np.ndarray, dof: int,
             excluded: tuple) -> Verdict | None:
    """The verdict without the one sensor that explains the failed residual test (``drops``:
    the chi-square drop of removing each block), or None when none does or two would (not
    identifiable); its solve is abandoned beyond :data:`HOPELESS` times the threshold."""
    limit = fit.chi2_max[dof - 3]
    order = np.argsort(-drops)
    rest = sol.chi2 - drops[order]
    if not rest[0] <= limit or (len(rest) > 1 and rest[1] <= limit):
        return None
    drop = int(sol.blocks[order[0]])
    blocks = sol.blocks[sol.blocks != drop]
    again = fit.solve_corrected(sol.state, blocks, frame.w[blocks], frame.d[blocks],
                                give_up=beyond(HOPELESS * limit))
    return assess(fit, again, frame, excluded + (drop,))


def _linearized_chi2(jac: np.ndarray, res: np.ndarray) -> float:
    """min |res - jac x|^2: the chi2 one undamped Gauss-Newton step would reach (inf when the
    normal matrix is singular)."""
    g = jac.T @ res
    try:
        x = np.linalg.solve(jac.T @ jac, g)
    except np.linalg.LinAlgError:
        return math.inf
    return float(res @ res - x @ g)


def _inconsistent(fit: PoseFit, sol: Solution, dof: int, pl_m: float, pl_rad: float) -> str:
    """Why the solution fails a test other than the alert limits ('' when it passes them)."""
    s = fit.settings
    p = sol.state.p
    rms = math.sqrt(sol.chi2 / max(dof, 1))
    if dof < 1:
        return f"{len(sol.blocks)} usable sensors leave no redundancy"
    if not sol.converged:
        return "fit did not converge" + ("" if sol.chi2 <= fit.chi2_max[dof] else
                                         f" (residual chi2 {sol.chi2:.3g} > "
                                         f"{fit.chi2_max[dof]:.3g}, {dof} dof)")
    if not _inside(p, fit.lo, fit.hi):
        return "position at or outside the plausible box's edge"
    if not sol.chi2 <= fit.chi2_max[dof]:
        return (f"residual chi2 {sol.chi2:.3g} > {fit.chi2_max[dof]:.3g} ({dof} dof, "
                f"false-alarm {s.false_alarm:g}): lost or model error")
    if rms > s.residual_limit:
        return f"residual {rms:.3g} > {s.residual_limit:g} (lost or implausible)"
    if not (math.isfinite(pl_m) and (math.isfinite(pl_rad) or not fit.n_rot)):
        return "singular Fisher information: the pose is not determined"
    return ""


def _inside(p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Is p strictly inside the box [lo, hi], 1 um from its faces (Python floats: every fix)?"""
    return all(a + 1e-6 < x < b - 1e-6 for x, a, b in zip(p.tolist(), lo.tolist(), hi.tolist()))


def _beyond_limits(fit: PoseFit, pl_m: float, pl_rad: float) -> str:
    """Why the protection levels are not within the alert limits ('' when they are)."""
    s = fit.settings
    if not pl_m <= s.alert_limit_m:
        return (f"protection level {pl_m * 1e3:.3g} mm > alert limit "
                f"{s.alert_limit_m * 1e3:.3g} mm")
    if fit.n_rot and not pl_rad <= s.orientation_alert_limit_rad:
        return (f"orientation protection level {math.degrees(pl_rad):.3g} deg > alert limit "
                f"{math.degrees(s.orientation_alert_limit_rad):.3g} deg")
    return ""


def locate(fit: PoseFit, d: np.ndarray, use: np.ndarray, sigma: np.ndarray, reading: np.ndarray,
           seed: Pose | None, method: str) -> Estimate:
    """The estimate of one frame's blocks: data d (b, 3) T (0 where unusable), ``use`` (b,),
    sigma (b,) T, the readings (b, 3) T (the fault model's gain errors scale them); ``seed``
    a prior pose (None: the last trusted fix, else cold)."""
    blocks = np.flatnonzero(use)
    need = max(3, -(-(fit.n_unknowns(False) + 1) // 3))    # >= 1 degree of freedom
    if len(blocks) < need:
        return Estimate.refused(_fallback(fit), _moment(fit, fit.last), f"only {len(blocks)} "
                                f"usable sensors (need {need})", method)
    w_all = np.where(use, 1.0 / sigma, 0.0)
    frame = Blocks(d, w_all, np.where(use[:, None], reading, 0.0))   # finite where used
    best = None
    if seed is not None and seed.covariance is not None:
        best = _with_prior(fit, frame, blocks, seed)
        if best.consistent:      # a frame that agrees with its prior keeps it
            return _estimate(fit, best, method, True)
    elif seed is not None or fit.last is not None:
        start = (fit.initial_state(seed.position_m, seed.moment_a_m2) if seed is not None
                 else fit.last)
        best = assess(fit, fit.solve_corrected(start, blocks, w_all[blocks], d[blocks]), frame)
        moved = float(np.linalg.norm(best.solution.state.p - start.p))
        if best.ok and (moved <= fit.settings.reacquire_m or seed is not None):
            return _estimate(fit, best, method, False)
    return _estimate(fit, _cold(fit, frame, blocks, need, best), method, False)


GROSS = 100.0
"""A block whose whitened innovation at the prior exceeds this many times the residual test's
chi-square(3) threshold is screened before the first solve (it would drag it)."""


def _with_prior(fit: PoseFit, frame: Blocks, blocks: np.ndarray, seed: Pose) -> Verdict:
    """The verdict of the fit aided by the seed's prior, from the seed. A block the prior
    cannot explain at the seed (:func:`_screen`) is excluded: before the solve when its
    innovation is gross, else when the solve fails the residual test and the linearized
    exclusion cannot name a liar (then the fit is solved again from the seed); then the
    ambient field's gradient."""
    start = fit.initial_state(seed.position_m, seed.moment_a_m2)
    if fit.last is not None:
        # the room changes slowly: the last trusted fix's background
        start = State(start.p, start.u, start.log_scale, fit.last.b.copy(), start.g)
    w, db = frame.w[blocks], frame.d[blocks]
    fit.set_prior(seed)
    try:
        fit.corr.update(start.p, start.u)
        first = fit.rows(start, blocks, w, db)
        drop = _screen(fit, first, blocks, w, seed.covariance, GROSS)
        if drop is not None:
            return _prior_without(fit, frame, blocks, start, drop)
        sol = fit.solve_corrected(start, blocks, w, db, first, PRIOR_ITERATIONS)
        best = assess(fit, sol, frame, gradient=False)
        if best.consistent or not sol.chi2 > fit.chi2_max[best.dof]:
            return best
        drop = _screen(fit, first, blocks, w, seed.covariance)
        if drop is not None:
            again = _prior_without(fit, frame, blocks, start, drop)
            if again.rank() < best.rank():
                best = again
            if best.consistent:
                return best
        if fit.settings.gradient == "auto" and sol.state.g is None and best.dof > 5:
            again = _with_gradient(fit, sol, frame)
            if again is not None and again.rank() < best.rank():
                best = again
        return best
    finally:
        fit.set_prior(None)


def _prior_without(fit: PoseFit, frame: Blocks, blocks: np.ndarray, start: State,
                   drop: int) -> Verdict:
    """The prior-aided verdict without block ``drop``, solved from ``start``."""
    rest = blocks[blocks != drop]
    sol = fit.solve_corrected(start, rest, frame.w[rest], frame.d[rest])
    return assess(fit, sol, frame, (drop,))


def _screen(fit: PoseFit, first: tuple, blocks: np.ndarray, w: np.ndarray,
            prior_cov: np.ndarray, gross: float = 1.0) -> int | None:
    """The one block whose reading the prior cannot explain, or None: at the prior pose each
    block's whitened innovation r_i (its data minus the model, minus the robust (median)
    uniform background of all blocks) has the covariance I + J_i C J_i^T with C the prior's
    (J_i the block's pose columns); a block beyond the residual test's chi-square(3) threshold
    at the false-alarm probability is a fault the prior names before any solve can be dragged
    by it. More than one such block: the frame disagrees with the prior, not one sensor
    (None). With ``gross`` > 1 only when some |r_i|^2 exceeds ``gross`` times the threshold.
    Only for one block a sensor (the 'model' observation)."""
    if fit.op is not None or len(blocks) <= 3 or fit.settings.max_exclusions < 1:
        return None
    jac, res = first
    nb = len(blocks)
    rb = res[:3 * nb].reshape(nb, 3)
    if fit.background:
        # the robust uniform background: each axis' middle value over the blocks
        rb = rb - w[:, None] * np.sort(rb / w[:, None], axis=0)[nb // 2]
    limit = fit.chi2_max[3]
    # q_i <= |r_i|^2 (the innovation's covariance is at least I): most frames stop here
    r2 = np.einsum("bi,bi->b", rb, rb)
    if not r2.max() > gross * limit:
        return None
    k = 3 + fit.n_rot
    cov = np.asarray(prior_cov, float)[:k, :k]
    g = jac[:3 * nb, :k].reshape(nb, 3, k) @ np.linalg.cholesky(cov)
    s = np.einsum("bip,bjp->bij", g, g)
    s[:, [0, 1, 2], [0, 1, 2]] += 1.0
    q = np.einsum("bi,bi->b", rb, np.linalg.solve(s, rb[..., None])[..., 0])
    out = np.flatnonzero(q > limit)
    return int(blocks[out[0]]) if len(out) == 1 else None


def _cold(fit: PoseFit, frame: Blocks, blocks: np.ndarray, need: int,
          best: Verdict | None) -> Verdict:
    """The verdict from the global search's starts, the best first; the first consistent one
    ends the search (another basin cannot be more trusted). A gross fault can pull every start
    into a wrong basin, where the linearized exclusion test cannot name the liar: when the best
    start fails the residual test, the search is run once per block left out
    (:meth:`.search.GridSearch.leave_one_out`) and all blocks are judged at the pose the
    others give (the exclusion test then runs where the others agree; a fit of all blocks
    would slide back); only then the ambient field's gradient, then the other starts."""
    d, w_all = frame.d, frame.w
    w, db = w_all[blocks], d[blocks]
    starts = fit.cold_starts(d, w_all ** 2)
    hopeless = _hopeless_start(fit, blocks, w)
    for k, st in enumerate(starts):
        sol = fit.solve_cold(st, blocks, w, db, hopeless)
        v = assess(fit, sol, frame, gradient=k > 0)
        if best is None or v.rank() < best.rank():
            best = v
        if best.consistent or k > 0:
            if best.consistent:
                return best
            continue
        if not v.solution.chi2 <= fit.chi2_max[v.dof] and len(blocks) > need:
            loo = _leave_one_out(fit, frame, blocks)
            if loo is not None and loo.rank() < best.rank():
                best = loo
            if best.consistent:
                return best
            if fit.settings.gradient == "auto" and sol.state.g is None and v.dof > 5:
                again = _with_gradient(fit, sol, frame)
                if again is not None and again.rank() < best.rank():
                    best = again
                if best.consistent:
                    return best
    return best


def _hopeless_start(fit: PoseFit, blocks: np.ndarray, w: np.ndarray):
    """The ``give_up`` test of a cold start's fit of ``blocks`` (weights w): abandoned (after
    :data:`.levenberg.GIVE_UP_AFTER` iterations) while, linearized, neither the fit nor the fit
    without its best single block to exclude (the exclusion drops at the linearized minimum)
    nor, with ``gradient='auto'``, the fit with the ambient gradient comes within
    :data:`HOPELESS` times its threshold: no verdict of this start could then pass."""
    nb, s = len(blocks), fit.settings
    dof = 3 * nb - fit.n_unknowns(False)
    if dof <= 3 or s.max_exclusions < 1:
        return beyond(HOPELESS * fit.chi2_max[max(dof, 1)])
    one_out = HOPELESS * fit.chi2_max[dof - 3]
    graded = HOPELESS * fit.chi2_max[dof - 5] if s.gradient == "auto" and dof > 5 else -1.0
    gcols = None
    if graded > 0:
        gcols = fit.gcols if fit.op is None else np.einsum("kisj,sjq->kiq", fit.op, fit.gcols)
        gcols = (gcols[blocks] * w[:, None, None]).reshape(3 * nb, 5)

    def test(jac, res, linearized):
        if linearized <= one_out:
            return False
        try:
            cov0 = np.linalg.inv(jac.T @ jac)
        except np.linalg.LinAlgError:
            return False
        r = res - jac @ (cov0 @ (jac.T @ res))          # the residual at the linearized minimum
        drops = exclusion_drops(jac, r, projections(jac, cov0))
        if float(r @ r) - float(drops.max()) <= one_out:
            return False
        return gcols is None or _linearized_chi2(np.hstack((jac, gcols)), res) > graded
    return test


def _leave_one_out(fit: PoseFit, frame: Blocks, blocks: np.ndarray) -> Verdict | None:
    """The block whose removal fits best (:meth:`.search.GridSearch.leave_one_out`), the
    search and the fit without it (abandoned while its linearized chi2 stays beyond
    :data:`HOPELESS` times the rest's threshold), judged with every block at that pose
    (:func:`_cold`). None when the search cannot tell."""
    d, w_all = frame.d, frame.w
    suspect = fit.search.leave_one_out(d, w_all ** 2, fit.background)
    if suspect is None:
        return None
    w_rest = w_all.copy()
    w_rest[suspect] = 0.0
    rest = blocks[blocks != suspect]
    st = fit.cold_starts(d, w_rest ** 2)[0]
    # the rest must pass the test on its own: abandoned beyond HOPELESS times its threshold
    limit = fit.chi2_max[max(3 * len(rest) - fit.n_unknowns(False), 1)]
    sub = fit.solve_cold(st, rest, w_all[rest], d[rest], beyond(HOPELESS * limit))
    jac, res = fit.rows(sub.state, blocks, w_all[blocks], d[blocks])
    return assess(fit, Solution(sub.state, jac, res, blocks, float(res @ res), sub.converged,
                                sub.iterations), frame, gradient=False)


def _estimate(fit: PoseFit, v: Verdict, method: str, prior_used: bool) -> Estimate:
    st = v.solution.state
    fit.last = st if v.ok else None
    k = 3 + fit.n_rot + fit.fit_scale
    cov = None if v.covariance is None else v.covariance[:k, :k].copy()
    excluded = tuple(sorted(s for b in v.excluded for s in fit.block_sensors[b]))
    return Estimate(st.p.copy(), _moment(fit, st), v.ok, v.reason, cov, v.pl_m, v.pl_rad,
                    excluded, st.b.copy(), float(v.solution.chi2), v.dof,
                    len(v.solution.blocks), v.solution.iterations, method,
                    tangent_axes(st.u) if fit.n_rot else None, None, v.consistent,
                    v.free[0], v.free[1], prior_used)


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
