"""The joint pose fit of several finger magnets: :class:`MagnetsFit`.

Unknowns: each present magnet's position (3, m) and moment direction (2 rotations about its
tangent axes, rad; |m| from its spec), then the uniform background (3, T): 5 k + 3 for k
magnets. The sensors read the sum of the magnets' fields (superposed: each magnet's multipole,
its exact-cylinder correction and the cores it magnetizes, the cores linear) plus the
background; each magnet's field and pose columns are those of the single-magnet fit
(:meth:`.pose_fit.PoseFit.rows` of one :class:`PoseFit` a magnet, its spec's moment and size,
no background), so the joint model is the single-magnet model summed. Levenberg-Marquardt on
the whitened residual, the corrections re-linearized near each pose (:mod:`.corrections`).

Integrity per magnet (:func:`judge`): the joint covariance C0 = (J^T J)^-1 (inflated by chi2 /
dof above 1) gives each magnet's fault-free protection levels from its own 5 x 5 block
(:mod:`.integrity`); the undetected single-sensor fault's bias is the single-magnet code's
bounded-fault bound (:func:`.fde.bounded_fault_bias`) over the joint fit's blocks, read on that
magnet's columns. Fault exclusion (RAIM FDE) as in :mod:`.fix`: when chi2 fails, the one
sensor whose removal passes the test, and no other's would, is excluded and the fit solved
again. Derivations: docs/localization.md ("Several magnets").
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..errors import BadInputError
from .fde import bounded_fault_bias, exclusion_drops, projections
from .integrity import orientation_protection_level, position_protection_level
from .levenberg import levenberg_marquardt
from .pose_fit import COLD_ITERATIONS, PoseFit, Solution, State
from .sensor_model import SensorModel
from .settings import EstimatorSettings

MAGNET_UNKNOWNS = 5
"""Unknowns of one magnet: its position (3) and its moment's direction (2)."""


@dataclass(frozen=True)
class MagnetSpec:
    """What the fit knows of one magnet: ``moment_a_m2`` |m| (A m^2), ``radius_m``,
    ``length_m`` (m) of its cylinder, ``name``."""

    moment_a_m2: float
    radius_m: float
    length_m: float
    name: str

    def same_field(self, other: "MagnetSpec") -> bool:
        """Do the two magnets make the same field in the same pose (identical for the fit)?"""
        return (math.isclose(self.moment_a_m2, other.moment_a_m2, rel_tol=1e-9)
                and math.isclose(self.radius_m, other.radius_m, rel_tol=1e-9)
                and math.isclose(self.length_m, other.length_m, rel_tol=1e-9))


@dataclass(frozen=True)
class JointState:
    """The present magnets' identities ``ids`` (indices into the specs), their poses
    (:class:`.pose_fit.State`, background 0) and the background b (3,) T."""

    ids: tuple
    poses: tuple
    b: np.ndarray

    def positions(self) -> np.ndarray:
        return np.array([s.p for s in self.poses]).reshape(-1, 3)


@dataclass(frozen=True)
class MagnetVerdict:
    """One magnet's integrity in a joint solution: ok, reason, its covariance (5, 5), the
    position and orientation protection levels (m, rad) with and without the undetected fault
    (``free``), and the position level it would have if the other magnets' poses were known
    (``alone_m``: tells magnets too close to separate from a weak signal); ``frame``: its
    position (3,) m and covariance (3, 3) m^2 from the sensors alone (:func:`frame_only`), or
    None."""

    ok: bool
    reason: str
    covariance: np.ndarray | None
    pl_m: float
    pl_rad: float
    free: tuple
    alone_m: float
    frame: tuple | None = None


@dataclass(frozen=True)
class JointVerdict:
    """The verdict of a joint solution: ``consistent`` (converged, inside the box, the residual
    test after any exclusion, finite levels), ``reason`` ('' when consistent), the magnets'
    verdicts (in ``solution.state.ids`` order), dof and the excluded sensors."""

    solution: Solution
    consistent: bool
    reason: str
    magnets: tuple
    dof: int
    excluded: tuple = ()

    @property
    def ok(self) -> bool:
        """Every present magnet trusted."""
        return self.consistent and all(m.ok for m in self.magnets)

    def rank(self) -> tuple:
        """Sort key: all trusted, consistent, converged, then the lower chi2 per dof."""
        return (not self.ok, not self.consistent, not self.solution.converged,
                self.solution.chi2 / max(self.dof, 1))


def spec_model(model: SensorModel, spec: MagnetSpec) -> SensorModel:
    """``model`` with the magnet of ``spec`` (its |m| along the model's direction, its size,
    its l = 3 ratio (L / 2)^2 - 3 a^2 / 4); the cores' field per unit moment is shared."""
    u0 = model.moment_a_m2 / float(np.linalg.norm(model.moment_a_m2))
    a, length = spec.radius_m, spec.length_m
    return dataclasses.replace(model, moment_a_m2=spec.moment_a_m2 * u0,
                               magnet_size_m=(a, length),
                               octupole_m2=(0.5 * length) ** 2 - 0.75 * a * a)


class MagnetsFit:
    """The joint fit of the magnets ``specs`` (module docstring) over ``model``'s sensors;
    ``settings`` as the single-magnet estimator's (the background uniform or off; the
    gradient is not fitted), ``calibration`` likewise."""

    def __init__(self, model: SensorModel, specs, settings: EstimatorSettings,
                 calibration=None):
        self.specs = tuple(specs)
        self.settings = settings
        if settings.orientation != "fit" or settings.fit_moment_magnitude:
            raise BadInputError("settings", "orientation 'fit' and fit_moment_magnitude False "
                                "(several magnets: each pose's 5 unknowns, |m| from its spec)",
                                (settings.orientation, settings.fit_moment_magnitude))
        single = dataclasses.replace(settings, background="off", gradient="off")
        self.engines = [PoseFit(spec_model(model, s), single, calibration) for s in self.specs]
        first = self.engines[0]
        self.calibration = first.calibration
        self.background = settings.background == "uniform"
        self.n_bg = 3 if self.background else 0
        self.lo, self.hi = first.lo, first.hi
        self.chi2_max, self.lam_md, self.k2 = first.chi2_max, first.lam_md, first.k2
        self.bias_m, self.bias_rad = first.bias_m, first.bias_rad
        self.search = first.search

    # -- data ------------------------------------------------------------------------------
    def frame(self, readings: np.ndarray, currents: np.ndarray):
        """(d (n, 3) T, usable (n,), sigma (n,) T, field (n, 3) T) of a checked frame: the
        field in the array frame minus the coils' at ``currents`` (:meth:`PoseFit.data`)."""
        first = self.engines[0]
        return first.data(first.corrected(readings), currents)

    def n_unknowns(self, k: int) -> int:
        return MAGNET_UNKNOWNS * k + self.n_bg

    def start(self, ids, positions, moments, b=None) -> JointState:
        """The joint state of magnets ``ids`` at ``positions`` with ``moments`` (directions)."""
        poses = tuple(self.engines[i].initial_state(p, m) for i, p, m in
                      zip(ids, positions, moments))
        return JointState(tuple(ids), poses, np.zeros(3) if b is None else np.array(b, float))

    # -- the model and its Jacobian --------------------------------------------------------
    def rows(self, st: JointState, blocks, w, d, corrected: bool = True):
        """Whitened Jacobian and residual of the used ``blocks`` (weights w, data d of those
        blocks) at ``st``; each engine's prior rows (when set) follow the sensors' rows."""
        nb, k = len(blocks), len(st.ids)
        n_par = self.n_unknowns(k)
        priors = [i for i in st.ids if self.engines[i].prior is not None]
        jac = np.zeros((3 * nb + MAGNET_UNKNOWNS * len(priors), n_par))
        res = np.zeros(len(jac))
        zero = np.zeros((nb, 3))
        res[:3 * nb] = ((d - (st.b if self.background else 0.0)) * w[:, None]).reshape(-1)
        row = 3 * nb
        for j, (i, pose) in enumerate(zip(st.ids, st.poses)):
            eng = self.engines[i]
            ji, ri = eng.rows(pose, blocks, w, zero, corrected)
            cols = slice(MAGNET_UNKNOWNS * j, MAGNET_UNKNOWNS * (j + 1))
            jac[:3 * nb, cols] = ji[:3 * nb]
            res[:3 * nb] += ri[:3 * nb]
            if eng.prior is not None:
                jac[row:row + MAGNET_UNKNOWNS, cols] = ji[3 * nb:]
                res[row:row + MAGNET_UNKNOWNS] = ri[3 * nb:]
                row += MAGNET_UNKNOWNS
        if self.background:
            jac[:3 * nb, n_par - 3:] = (w[:, None, None] * np.eye(3)).reshape(3 * nb, 3)
        return jac, res

    def fields(self, st: JointState) -> np.ndarray:
        """(k, n, 3) T: each present magnet's modelled field at every sensor (array frame)."""
        n = len(self.engines[0].pts)
        allb, ones, zero = np.arange(n), np.ones(n), np.zeros((n, 3))
        return np.stack([-self.engines[i].rows(pose, allb, ones, zero)[1][:3 * n].reshape(n, 3)
                         for i, pose in zip(st.ids, st.poses)])

    def step(self, st: JointState, delta: np.ndarray) -> JointState:
        poses = tuple(self.engines[i].step(pose, delta[MAGNET_UNKNOWNS * j:
                                                       MAGNET_UNKNOWNS * (j + 1)])
                      for j, (i, pose) in enumerate(zip(st.ids, st.poses)))
        b = st.b + delta[len(delta) - 3:] if self.background else st.b
        return JointState(st.ids, poses, b)

    def set_priors(self, priors) -> None:
        """Each engine's prior (a :class:`Pose` with a covariance, or None: see
        :meth:`PoseFit.set_prior`)."""
        for eng, seed in zip(self.engines, priors):
            eng.set_prior(seed)

    def relinearize(self, st: JointState) -> None:
        for i, pose in zip(st.ids, st.poses):
            self.engines[i].corr.update(pose.p, pose.u)

    def within(self, st: JointState, slack: float = 1.0) -> bool:
        return all(not self.engines[i].corr.active or self.engines[i].corr.within(
            pose.p, pose.u, slack) for i, pose in zip(st.ids, st.poses))

    # -- solving ---------------------------------------------------------------------------
    def solve_once(self, st: JointState, blocks, w, d, corrected: bool,
                   max_iterations: int) -> Solution:
        """Levenberg-Marquardt from ``st`` (:func:`.levenberg.levenberg_marquardt`): converged
        when the Gauss-Newton step would lower chi2 by less than
        :data:`.levenberg.CONVERGED_GAIN`."""
        def rows(state):
            return self.rows(state, blocks, w, d, corrected)

        out = levenberg_marquardt(st, rows, self.step, rows(st), max_iterations)
        return Solution(out.state, out.jac, out.res, np.asarray(blocks), out.chi2,
                             out.converged, out.iterations)

    def solve(self, st: JointState, blocks, w, d, max_iterations: int | None = None,
              cold: bool = False) -> Solution:
        """The solve with the corrections linearized near every pose, re-linearized (at most 4
        times) until the solution stays within twice their reuse radius; ``cold``: the
        multipoles alone first (at most :data:`.pose_fit.COLD_ITERATIONS` iterations)."""
        iters = max_iterations or self.settings.max_iterations
        total = 0
        if cold:
            sol = self.solve_once(st, blocks, w, d, False, min(COLD_ITERATIONS, iters))
            if not sol.converged:
                return sol
            st, total = sol.state, sol.iterations
        for _ in range(5):
            self.relinearize(st)
            sol = self.solve_once(st, blocks, w, d, True, iters)
            total += sol.iterations
            st = sol.state
            if not sol.converged or self.within(st, slack=2.0):
                break
        # the rows reported at the final state with the corrections linearized there
        self.relinearize(st)
        jac, res = self.rows(st, blocks, w, d, True)
        return Solution(st, jac, res, sol.blocks, float(res @ res), sol.converged, total)


def judge(fit: MagnetsFit, sol: Solution, frame: tuple, excluded: tuple = ()) -> JointVerdict:
    """The verdict of a joint solution (module docstring); ``frame`` = (d, w_all, reading)
    of every sensor (w 0 where unusable). Fault exclusion when chi2 fails."""
    verdict = _verdict(fit, sol, frame, excluded)
    dof = verdict.dof
    if (dof < 1 or (sol.chi2 <= fit.chi2_max[dof] and sol.converged)
            or len(excluded) >= fit.settings.max_exclusions or dof <= 3):
        return verdict
    better = _exclude(fit, sol, frame, excluded)
    return better if better is not None and better.rank() < verdict.rank() else verdict


def _verdict(fit: MagnetsFit, sol: Solution, frame: tuple, excluded: tuple) -> JointVerdict:
    rows, n_par = sol.jac.shape
    dof = rows - n_par
    nb = len(sol.blocks)
    k = len(sol.state.ids)
    try:
        cov0 = np.linalg.inv(sol.jac.T @ sol.jac) if dof >= 1 else None
    except np.linalg.LinAlgError:
        cov0 = None
    if cov0 is not None and not np.all(np.isfinite(cov0)):
        cov0 = None
    reason = _inconsistent(fit, sol, dof)
    mags = []
    alone = frame_only(sol, fit.n_unknowns(k))
    for j in range(k):
        v = _magnet_verdict(fit, sol, frame, cov0, j, dof)
        if alone is not None:
            cols = slice(MAGNET_UNKNOWNS * j, MAGNET_UNKNOWNS * j + 3)
            v = dataclasses.replace(v, frame=(sol.state.poses[j].p + alone[0][cols],
                                              alone[1][cols, cols]))
        mags.append(v)
    if not reason and any(not math.isfinite(m.pl_m) for m in mags):
        reason = "singular Fisher information: the poses are not determined"
    if reason:
        mags = [dataclasses.replace(m, ok=False, reason=reason) for m in mags]
    return JointVerdict(sol, not reason, reason, tuple(mags), dof, excluded)


def frame_only(sol: Solution, n_par: int):
    """(step (P,), covariance (P, P)) of the sensors alone at the solution: the Gauss-Newton
    step F^-1 J_s^T r_s from it and F^-1, F = J_s^T J_s over the sensors' rows only (a seed's
    prior rows left out), inflated by chi2 / dof above 1 as the fix's; None when the sensors
    alone do not determine the unknowns. The fix with a prior is the posterior; this is the
    frame's own measurement of it (linearized there), what a tracker's filter may take in
    without counting its own prediction twice."""
    nb = len(sol.blocks)
    js, rs = sol.jac[:3 * nb], sol.res[:3 * nb]
    dof = 3 * nb - n_par
    if dof < 1:
        return None
    try:
        cov = np.linalg.inv(js.T @ js)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(cov)):
        return None
    chi2 = float(rs @ rs)
    return cov @ (js.T @ rs), cov * max(1.0, chi2 / dof)


def _magnet_verdict(fit: MagnetsFit, sol: Solution, frame: tuple, cov0, j: int,
                    dof: int) -> MagnetVerdict:
    """Magnet j's levels and verdict from the joint covariance ``cov0`` (None: singular)."""
    if cov0 is None:
        return MagnetVerdict(False, "singular Fisher information", None, math.inf, math.inf,
                             (math.inf, math.inf), math.inf)
    s = fit.settings
    nb = len(sol.blocks)
    cols = np.arange(MAGNET_UNKNOWNS * j, MAGNET_UNKNOWNS * (j + 1))
    order = np.r_[cols, np.setdiff1d(np.arange(cov0.shape[0]), cols)]
    inflate = max(1.0, sol.chi2 / dof)
    cov = cov0[np.ix_(cols, cols)] * inflate
    jac = sol.jac[:3 * nb][:, order]
    kt = projections(jac, cov0[np.ix_(order, order)])
    d, w_all, reading = frame
    w = w_all[sol.blocks]
    rd = reading[sol.blocks]
    axis_amp = w[:, None] * np.maximum(s.fault_offset_t, s.fault_gain * np.abs(rd))
    if s.fault_offset_t or s.fault_gain:
        dp, du = bounded_fault_bias(jac, kt, axis_amp, (s.fault_gain * w)[:, None] * rd,
                                    fit.lam_md[dof], 2)
        fault_m, fault_rad = float(dp.max()), float(du.max())
    else:
        fault_m = fault_rad = 0.0
    scale = math.sqrt(inflate)
    noise_m = position_protection_level(cov[:3, :3], fit.k2)
    noise_rad = orientation_protection_level(cov[3:5, 3:5], s.integrity_risk)
    pl_m = fit.bias_m + max(noise_m, fault_m * scale)
    pl_rad = fit.bias_rad + max(noise_rad, fault_rad * scale)
    info = sol.jac[:, cols]
    try:
        alone = np.linalg.inv(info.T @ info)[:3, :3] * inflate
        alone_m = fit.bias_m + position_protection_level(alone, fit.k2)
    except np.linalg.LinAlgError:
        alone_m = math.inf
    reason = _beyond_limits(s, pl_m, pl_rad)
    return MagnetVerdict(not reason, reason, cov, pl_m, pl_rad,
                         (fit.bias_m + noise_m, fit.bias_rad + noise_rad), alone_m)


def _beyond_limits(s: EstimatorSettings, pl_m: float, pl_rad: float) -> str:
    if not pl_m <= s.alert_limit_m:
        return (f"protection level {pl_m * 1e3:.3g} mm > alert limit "
                f"{s.alert_limit_m * 1e3:.3g} mm")
    if not pl_rad <= s.orientation_alert_limit_rad:
        return (f"orientation protection level {math.degrees(pl_rad):.3g} deg > alert limit "
                f"{math.degrees(s.orientation_alert_limit_rad):.3g} deg")
    return ""


def _inconsistent(fit: MagnetsFit, sol: Solution, dof: int) -> str:
    """Why the joint solution fails a test other than the alert limits ('' when it passes)."""
    s = fit.settings
    if dof < 1:
        return f"{len(sol.blocks)} usable sensors leave no redundancy"
    if not sol.converged:
        return "fit did not converge"
    for p in sol.state.poses:
        if not (np.all(p.p > fit.lo + 1e-6) and np.all(p.p < fit.hi - 1e-6)):
            return "a position at or outside the plausible box's edge"
    if not sol.chi2 <= fit.chi2_max[dof]:
        return (f"residual chi2 {sol.chi2:.3g} > {fit.chi2_max[dof]:.3g} ({dof} dof, "
                f"false-alarm {s.false_alarm:g}): lost or model error")
    rms = math.sqrt(sol.chi2 / dof)
    if rms > s.residual_limit:
        return f"residual {rms:.3g} > {s.residual_limit:g} (lost or implausible)"
    return ""


def _exclude(fit: MagnetsFit, sol: Solution, frame: tuple,
             excluded: tuple) -> JointVerdict | None:
    """The verdict without the one sensor that explains the failed residual test (RAIM FDE,
    :func:`.fde.exclusion_drops`), or None when none does or two would."""
    nb = len(sol.blocks)
    rows, n_par = sol.jac.shape
    dof = rows - n_par
    try:
        cov0 = np.linalg.inv(sol.jac.T @ sol.jac)
    except np.linalg.LinAlgError:
        return None
    kt = projections(sol.jac[:3 * nb], cov0)
    drops = exclusion_drops(sol.jac[:3 * nb], sol.res[:3 * nb], kt)
    order = np.argsort(-drops)
    rest = sol.chi2 - drops[order]
    limit = fit.chi2_max[dof - 3]
    if not rest[0] <= limit or (len(rest) > 1 and rest[1] <= limit):
        return None
    drop = int(sol.blocks[order[0]])
    blocks = sol.blocks[sol.blocks != drop]
    d, w_all, _ = frame
    again = fit.solve(sol.state, blocks, w_all[blocks], d[blocks])
    return judge(fit, again, frame, excluded + (drop,))
