"""The fail-safe control loop: newest fix -> predicted position -> object force -> currents ->
voltages -> PWM, one step per control period.

Each :meth:`Runner.step` takes the sensor side's newest :class:`~firmware_io.runner.pipeline.Fix`
(or None), updates the tracker at the frame's time and predicts to now, evaluates the scene's
force f (N) there, allocates currents (A) with min ||F(p) I - (f - F0(p))|| within the bounds,
turns them into the voltages of the R-L feed-forward (:mod:`firmware_io.runner.drive`) and
writes the MD10C duties, one block write per PCA9685. Every fault switches every coil off in
the same step. For the fault table, the resume policy and the timing rationale see
docs/runner.md.
"""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import BadInputError, CoilWriteError
from ..localization.integrity import chi2_quantile, fused_protection_level, ratio_quantiles
from .config import RunnerConfig
from .drive import CurrentPath
from .forcelaw import force_law_rows
from .pipeline import CurrentHistory, Fix, SensorFrame, SensorPipeline
from .skip import CoilSkipBound
from .thermal import ThermalGuard

FAULTS = ("pwm_nack", "sensor_stuck", "sensor_dead", "sensor_saturated", "lost", "gated",
          "out_of_box", "overrun", "thermal", "over_limit")
"""The runner's fault states (docs/runner.md: cause and resume policy of each)."""

LOCALIZATION_FAULTS = ("sensor_stuck", "sensor_dead", "sensor_saturated", "lost", "gated",
                       "out_of_box")
"""Faults cleared by ``RunnerConfig.resume_fixes`` accepted fixes in a row (the frames that
show the position is supported again), not by ``resume_after_s``."""

HISTORY_S = 0.2
"""How far back the modelled currents are kept for the sensor side, s (frames arrive late)."""


@dataclass
class StepRecord:
    """What one control step did (SI). ``state`` is 'running', 'safe' or a fault name."""

    t_s: float
    position_m: np.ndarray
    force_ref_n: np.ndarray
    command_a: np.ndarray
    voltage_v: np.ndarray
    predicted_current_a: np.ndarray
    loop_s: float
    state: str
    new_frame: bool


class SceneForce:
    """A compiled scene (:class:`firmware_io.scene.Scene`) as the runner's one-point interface:
    ``force(position_m (3,), velocity_m_s (3,)) -> (3,)`` N."""

    def __init__(self, scene):
        self.scene = scene

    def force(self, p, v):
        return self.scene.force(np.asarray(p, float)[None], np.asarray(v, float)[None])[0]


class Runner:
    """Compose map, scene, localizer, allocator and drivers into the fail-safe control loop.

    Parameters
    ----------
    fieldmap : firmware_io.actuation.ActuationSource
        ``actuation(point, rows=..., coils=...)`` (rows Bx, By, Bz, dBx/dx, dBx/dy, dBx/dz,
        dBy/dy, dBy/dz, per ampere), ``bounds`` (lower (3,), upper (3,)) m, ``moment_a_m2``
        (3,), and optionally ``bias_force(point) -> (3,)`` N.
    scene : object
        ``force(position_m, velocity_m_s) -> (3,)`` N, the object's force on the finger.
    localizer : object
        ``estimate(readings_t, currents_a)`` -> an Estimate (firmware_io.localization.Estimator).
    tracker : object
        A constant-velocity filter over the estimates between frames
        (:class:`firmware_io.localization.ConstantVelocityKalman`): ``update(position_m, time_s,
        ok)``, ``predict(time_s) -> position_m`` and its state ``x`` ((2, 3): position, velocity).
    allocate : callable
        ``allocate(force_matrix, target, current_limit, total_limit, unipolar=...)``
        -> (currents, residual) (firmware_io.allocation).
    coils : firmware_io.hw.coils.CoilDriver
        Takes the voltages of the current path (``command_voltage``); ``all_off`` is the safe
        state.
    sensors : callable
        ``sensors(t_s) -> Fix | SensorFrame | None``: the newest result not yet handed out, or
        None. A source with ``attach(pipeline)`` is given this runner's
        :class:`SensorPipeline` and runs it on its side (the sensor thread); a raw
        :class:`SensorFrame` is processed inside the step.
    config : RunnerConfig
    log : callable
        ``log(line)`` for one line per fault/resume.
    clock : callable
        ``clock() -> s`` for the compute time of a step (default ``time.perf_counter``).
    """

    def __init__(self, fieldmap, scene, localizer, tracker, allocate: Callable, coils,
                 sensors: Callable, config: RunnerConfig, *, log: Callable[[str], None] = print,
                 clock: Callable[[], float] = time.perf_counter):
        if coils.n_coils != config.n_coils:
            raise BadInputError("config.resistance_ohm", f"{coils.n_coils} coils (the driver's)",
                                config.n_coils)
        self.map, self.scene, self.localizer, self.tracker = fieldmap, scene, localizer, tracker
        self.allocate, self.coils, self.sensors, self.cfg = allocate, coils, sensors, config
        self.log, self.clock = log, clock
        n = config.n_coils
        self.path = CurrentPath(config.drives, config.control_period_s, config.feedforward)
        self.limit = np.full(n, config.current_limit_a)
        self.thermal = ThermalGuard(n, config.thermal_continuous_current_a,
                                    config.thermal_time_constant_s)
        m = np.asarray(fieldmap.moment_a_m2, float)
        self.moment = m
        mx, my, mz = m
        self.z_only = config.force_axes == "z" and abs(mx) + abs(my) <= 1e-12 * abs(mz)
        self.law_rows, self.law_matrix = force_law_rows(m, "z" if self.z_only else "xyz")
        self.lo, self.hi = (np.asarray(b, float) for b in fieldmap.bounds)
        self.skip = (CoilSkipBound(fieldmap, self.law_rows, self.law_matrix)
                     if config.skip_force_n > 0 else None)
        self.command_a = np.zeros(n)
        self.state = "safe"
        self.fault: str | None = None
        self.fault_since_s = -math.inf
        self.clear_since_s: float | None = None
        self.latched = False
        self.pwm_failures = 0
        self.pwm_reinit_needed = False
        self.last_estimate_ok = False
        self.accepted_in_row = 0      # fixes taken into the tracker since the last fault
        self.have_fix = False
        self.position_m = np.full(3, np.nan)
        self.fault_log: list[tuple[float, str, str]] = []
        # modelled currents at the start of each step of the last HISTORY_S (frames arrive late)
        self.history = CurrentHistory(n, max(16, int(HISTORY_S / config.control_period_s)))
        self.pipeline = SensorPipeline(localizer, fieldmap, n, self.history.at, m)
        self.last_fix: Fix | None = None
        self.gate_d2 = chi2_quantile(config.gate_risk, 3)
        self._candidate: Fix | None = None     # a gated-out fix awaiting confirmation
        # per-stage compute times of the last step (s), when ``profile`` is set
        self.profile = False
        self.stages: dict[str, float] = {}
        attach = getattr(sensors, "attach", None)
        if attach is not None:
            attach(self.pipeline)       # the source runs the fit on its side

    @property
    def current_a(self) -> np.ndarray:
        """The model of the coil currents, (n,) A (the feed-forward's state)."""
        return self.path.current_a

    # -- life cycle ----------------------------------------------------------------------------
    def start(self, pwm_frequency_hz: float = 1526.0) -> None:
        """Initialise every PWM board into the safe state (all coils off), then run the step's
        computations once at the box centre so that the first real step is not slowed by
        first-call costs (an overrun)."""
        self.coils.initialize(pwm_frequency_hz)
        self.coils.all_off()
        self.path.current_a[:] = 0.0
        self.state = "safe"
        centre = 0.5 * (self.lo + self.hi)
        self._allocate(centre, np.asarray(self.scene.force(centre, np.zeros(3)), float))
        self.coils.plan_voltage(self.path.voltage(self.path.current_a))
        # a full collection walks every object the map, scene and localizer made at start-up
        # (long enough to be an overrun, docs/runner.md): collect once now and move the
        # survivors out of the collector's reach; later collections see only the loop's objects
        gc.collect()
        gc.freeze()

    def stop(self) -> None:
        self.coils.all_off()
        self.state = "safe"
        gc.unfreeze()  # what start() froze is collectable again once the loop is over

    # -- faults --------------------------------------------------------------------------------
    def _enter_fault(self, t_s: float, name: str, detail: str) -> None:
        if self.fault != name:
            self.log(f"[{t_s:9.4f} s] FAULT {name}: {detail}; all coils off")
            self.fault_log.append((t_s, name, detail))
        self.fault = name
        self.fault_since_s = t_s
        self.clear_since_s = None
        self.accepted_in_row = 0
        unconfirmed = self.coils.all_off()
        if unconfirmed:
            self.latched = True
            self.log(f"[{t_s:9.4f} s] all-off NOT confirmed on {unconfirmed}: latched")
        self.command_a[:] = 0.0
        self.state = name

    def _may_resume(self, t_s: float, clear: bool) -> bool:
        """True once the fault is over: a localization fault after ``resume_fixes`` fixes in a
        row accepted with no problem in between, any other once its condition has been clear
        for ``resume_after_s`` (either count restarts at any problem)."""
        if self.latched:
            return False
        if not clear:
            self.clear_since_s = None
            self.accepted_in_row = 0
            return False
        if self.clear_since_s is None:
            self.clear_since_s = t_s
        by_fixes = self.fault in LOCALIZATION_FAULTS
        if by_fixes:
            done = self.accepted_in_row >= self.cfg.resume_fixes
        else:
            done = t_s - self.clear_since_s + 1e-12 >= self.cfg.resume_after_s
        if not done:
            return False
        if self.pwm_reinit_needed and not self._reinit_pwm(t_s):
            return False      # a NACK this fault superseded: the boards first
        self.log(f"[{t_s:9.4f} s] resume after {self.fault}"
                 + (f" ({self.accepted_in_row} fixes)" if by_fixes else ""))
        self.fault = None
        self.clear_since_s = None
        return True

    def _reinit_pwm(self, t_s: float) -> bool:
        """Re-initialise the PWM boards after a NACK; latch after ``max_pwm_retries`` failures."""
        try:
            self.coils.initialize()
        except CoilWriteError:
            self.pwm_failures += 1
            self.clear_since_s = None
            if self.pwm_failures >= self.cfg.max_pwm_retries:
                self.latched = True
                self.log(f"[{t_s:9.4f} s] PWM boards failed {self.pwm_failures} "
                         "re-initialisations: latched off")
            return False
        self.pwm_failures = 0
        self.pwm_reinit_needed = False
        return True

    def _still_off(self, t_s: float, problems: list) -> bool:
        """Enter the first problem's fault, or stay in the current one until it may resume;
        True while the coils must stay off."""
        if problems and (self.fault is None or problems[0][0] != self.fault):
            name, detail = problems[0]
            self._enter_fault(t_s, name, detail)
        elif self.fault is not None:
            ok_now = self.thermal.cooled() if self.fault == "thermal" else not problems
            if not self._may_resume(t_s, ok_now):
                return True
        return self.fault is not None

    # -- the step ------------------------------------------------------------------------------
    def _mark(self, name: str, t_prev: float) -> float:
        t = self.clock()
        self.stages[name] = t - t_prev
        return t

    def _take_fix(self, t_s: float) -> tuple[bool, list]:
        """Hand-over from the sensor side: (a new frame arrived, its problems)."""
        item = self.sensors(t_s)
        if isinstance(item, SensorFrame):
            item = self.pipeline.process(item)
        fix: Fix | None = item
        problems: list[tuple[str, str]] = []
        if fix is not None:
            self.last_fix = fix
            problems.extend(fix.problems)
            accepted = False
            gated = self._gate(fix) if fix.ok else ""
            pl = self._protection_level(fix) if fix.ok and not gated else math.inf
            if gated:
                problems.append(("gated", gated))
            elif fix.ok and pl > self.cfg.alert_limit_m:
                problems.append(("lost", f"protection level {pl * 1e3:.3g} mm > alert limit "
                                 f"{self.cfg.alert_limit_m * 1e3:.3g} mm"))
                if not self.have_fix:
                    # acquisition: the tracker takes the fix (it passed the localizer's tests
                    # and the gate), nothing renders until a filtered PL is within the limit
                    self.tracker.update(fix.position_m, fix.frame_t_s, True)
            elif fix.ok:
                self.tracker.update(fix.position_m, fix.frame_t_s, True)
                self.have_fix = accepted = True
            self.last_estimate_ok = accepted      # taken into the tracker
            self.accepted_in_row = self.accepted_in_row + 1 if accepted else 0
        return fix is not None, problems

    def _protection_level(self, fix: Fix) -> float:
        """The protection level (m) of the position the runner renders at once this fix (past
        the gate) is in the tracker: its filtered position, from the fix's covariance and the
        tracker's prediction (:func:`firmware_io.localization.integrity.
        fused_protection_level`, the localizer's ``model_bias_m`` kept whole, its quantile
        table from the localizer's ``integrity_risk``). Without a tracked state (the tracker
        also holds the fixes of an acquisition): the fix's own."""
        if getattr(self.tracker, "x", None) is None or not hasattr(self.tracker, "innovation"):
            return fix.protection_level_m
        _, var = self.tracker.innovation(fix.position_m, fix.frame_t_s)
        p = var - self.tracker.r
        risk = getattr(self.localizer, "integrity_risk", None)
        return fused_protection_level(fix.protection_level_m, fix.covariance_m2, p,
                                      float(getattr(self.localizer, "model_bias_m", 0.0)),
                                      p / var, None if risk is None else ratio_quantiles(risk))

    def _gate(self, fix: Fix) -> str:
        """The innovation gate: '' when the fix agrees with the tracker's prediction at its
        frame time (Mahalanobis distance^2 with both covariances <= the chi-square(3) quantile
        at ``gate_risk``), else why not. A gated-out fix asks the sensor side to re-acquire
        (the next fit starts from the global search); a following fix consistent with it (both
        fixes' covariances and the tracker's measurement noise), itself from the global search,
        re-starts the tracker there (a warm fit could repeat a wrong basin; a cold one would
        not)."""
        if getattr(self.tracker, "x", None) is None or not hasattr(self.tracker, "innovation"):
            return ""
        cov = fix.covariance_m2 if fix.covariance_m2 is not None else np.zeros((3, 3))
        innov, var = self.tracker.innovation(fix.position_m, fix.frame_t_s)
        d2 = float(innov @ np.linalg.solve(cov + var * np.eye(3), innov))
        if d2 <= self.gate_d2:
            self._candidate = None
            return ""
        c = self._candidate
        if c is not None and fix.reacquired:
            cc = c.covariance_m2 if c.covariance_m2 is not None else np.zeros((3, 3))
            dv = fix.position_m - c.position_m
            s = cov + cc + 2 * self.tracker.r * np.eye(3)
            if float(dv @ np.linalg.solve(s, dv)) <= self.gate_d2:
                # two consecutive re-acquired fixes agree: the tracker was wrong, not the fix
                self.tracker.reset()
                self.have_fix = False     # renders again from the next accepted fix
                self._candidate = None
                return ""
        self._candidate = fix
        self.pipeline.reacquire = True
        return (f"fix {np.round(fix.position_m * 1e3, 1).tolist()} mm fails the tracker's gate "
                f"(Mahalanobis^2 {d2:.3g} > {self.gate_d2:.3g}); re-acquiring")

    def step(self, t_s: float) -> StepRecord:
        """One control step at time ``t_s`` (s). Never raises for a device fault.

        ``self.sensors(t_s)`` hands over the newest :class:`Fix` of the sensor side, or None;
        a source that hands over raw :class:`SensorFrame` s instead has them processed here
        (the single-threaded fallback: the fit then counts in this step).
        """
        t0 = self.clock()
        cfg = self.cfg
        prof = self.profile
        self.history.push(t_s, self.path.current_a)
        new_frame, problems = self._take_fix(t_s)
        tm = self._mark("fix", t0) if prof else t0
        if not self.have_fix:
            return self._record(t_s, t0, np.full(3, np.nan), np.zeros(3), new_frame,
                                off=True)
        p = np.asarray(self.tracker.predict(t_s), float)
        vel = np.asarray(self.tracker.x[1], float)
        self.position_m = p
        t_fix = getattr(self.tracker, "t", None)    # frame time of the newest accepted fix
        age = t_s - t_fix if t_fix is not None else 0.0
        if age > cfg.max_fix_age_s:
            problems.append(("lost", f"newest accepted fix {age * 1e3:.0f} ms old > "
                             f"{cfg.max_fix_age_s * 1e3:.0f} ms"))
        inside = bool(np.all(p >= self.lo) and np.all(p <= self.hi))
        if not inside:
            problems.append(("out_of_box", f"estimate {np.round(p * 1e3, 1).tolist()} mm outside "
                             f"the map box"))
        if self.thermal.exceeded():
            problems.append(("thermal", f"I^2 t {self.thermal.energy_a2s.max():.0f} A^2 s above "
                             f"the budget {self.thermal.budget_a2s:.0f} A^2 s"))
        if self._still_off(t_s, problems):
            return self._record(t_s, t0, p, np.zeros(3), new_frame, off=True)
        if prof:
            tm = self._mark("predict", tm)

        f_ref = np.asarray(self.scene.force(p, vel), float)
        if prof:
            tm = self._mark("object_force", tm)
        command = self._allocate(p, f_ref)
        total = float(np.sum(np.abs(command)))
        if np.any(np.abs(command) > self.limit + 1e-9) or total > cfg.total_current_a + 1e-9 \
                or (cfg.unipolar and np.any(command < -1e-9)):
            self._enter_fault(t_s, "over_limit",
                              f"command max |I| {np.abs(command).max():.3f} A, sum {total:.3f} A "
                              f"(limits {cfg.current_limit_a:.3f} A, {cfg.total_current_a:.3f} A)")
            return self._record(t_s, t0, p, f_ref, new_frame, off=True)
        return self._drive(t_s, t0, p, f_ref, command, new_frame)

    def force_matrix(self, p: np.ndarray, coils=None) -> np.ndarray:
        """Force per ampere at p: (1, n) N/A (Fz of a z-dipole) or (3, n); with ``coils`` (index
        array) only those columns."""
        return self.law_matrix @ self.map.actuation(p, rows=self.law_rows, coils=coils)

    def _allocate(self, p: np.ndarray, f_ref: np.ndarray) -> np.ndarray:
        cfg = self.cfg
        prof = self.profile
        tm = self.clock() if prof else 0.0
        keep = None
        if self.skip is not None:
            k = self.skip.keep(p, self.limit, cfg.skip_force_n)
            if len(k) < cfg.n_coils:
                keep = k
        fm = self.force_matrix(p, keep)
        target = f_ref[2:3] if self.z_only else f_ref
        bias = getattr(self.map, "bias_force", None)
        if bias is not None:
            b = np.asarray(bias(p), float)
            target = target - (b[2:3] if self.z_only else b)
        if prof:
            tm = self._mark("force_matrix", tm)
        if keep is None:
            command, _ = self.allocate(fm, target, self.limit, cfg.total_current_a,
                                       unipolar=cfg.unipolar)
            command = np.asarray(command, float)
        else:
            command = np.zeros(cfg.n_coils)
            if len(keep):
                i, _ = self.allocate(fm, target, self.limit[keep], cfg.total_current_a,
                                     unipolar=cfg.unipolar)
                command[keep] = i
        if prof:
            self._mark("allocation", tm)
        return command

    def _drive(self, t_s, t0, p, f_ref, command, new_frame) -> StepRecord:
        cfg = self.cfg
        tm = self.clock() if self.profile else 0.0
        try:
            result = self.coils.command_voltage(self.path.voltage(command))
        except CoilWriteError as exc:
            self.pwm_reinit_needed = True
            self._enter_fault(t_s, "pwm_nack", str(exc))
            return self._record(t_s, t0, p, f_ref, new_frame, off=True)
        elapsed = self.clock() - t0
        if elapsed > cfg.overrun_factor * cfg.control_period_s:
            # too late to trust this command: switch off within this step, nothing stays on
            self._enter_fault(t_s, "overrun", f"step took {elapsed * 1e3:.2f} ms > "
                              f"{cfg.overrun_factor * cfg.control_period_s * 1e3:.2f} ms")
            return self._record(t_s, t0, p, f_ref, new_frame, off=True)
        v_out = np.asarray(result.voltage_v, float)     # what the duty really applies
        self.command_a = command
        current = self.path.advance(v_out)
        self.thermal.update(current, cfg.control_period_s)
        self.state = "running"
        if self.profile:
            self._mark("drive", tm)
        return StepRecord(t_s, p, f_ref, command.copy(), v_out, current.copy(),
                          self.clock() - t0, self.state, new_frame)

    def _record(self, t_s, t0, p, f_ref, new_frame, *, off: bool) -> StepRecord:
        cfg = self.cfg
        if off:
            if self.fault is None:
                self.state = "safe"
                if np.any(self.command_a != 0) or np.any(np.abs(self.path.current_a) > 0):
                    self.coils.all_off()
            self.command_a = np.zeros(cfg.n_coils)
            current = self.path.advance(np.zeros(cfg.n_coils))
            self.thermal.update(current, cfg.control_period_s)
        return StepRecord(t_s, np.asarray(p, float).copy(), np.asarray(f_ref, float),
                          self.command_a.copy(), np.zeros(cfg.n_coils), self.path.current_a.copy(),
                          self.clock() - t0, self.state, new_frame)
