"""The fail-safe control loop: newest fix -> predicted pose -> object force -> currents ->
voltages -> PWM, one step per control period.

Each :meth:`Runner.step` takes the sensor side's newest :class:`~firmware_io.runner.frames.Fix`
(or None), updates the tracker at the frame's time and predicts to now, evaluates the scene's
force f (N) there, allocates currents (A) with min ||F(p, m) I - (f - F0(p))|| within the bounds
for the moment m the estimator found (column k of F scaled by the map's saturation factor at
|I_k| when the cores saturate), turns them into the voltages of the R-L feed-forward
(:mod:`firmware_io.runner.drive`) and writes the coil drivers' duties, one block write per PCA9685. The
torque m x B the currents cause is reported with each step. Every fault switches every coil off
in the same step; no force is rendered with a position older than one sensor pass. For the
fault table, the resume policy and the timing rationale see docs/runner.md.

The garbage collector is the runner's while it runs (:mod:`firmware_io.runner.collector`):
:meth:`Runner.start` collects once, freezes what start-up made and switches automatic
collection off; each step ends, after the coils were written, with a young pass when one is due
(its time counts in the step's ``loop_s``); middle and full passes -- which walk every
survivor and would land in whichever step crosses a threshold -- never run in the loop;
:meth:`Runner.stop` gives the collector back as it found it. Callers stop the runner in a
``finally``, so that an exception or Ctrl-C gives it back too.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..allocation import Allocator
from ..errors import BadInputError, CoilWriteError
from .collector import LoopCollector
from .config import RunnerConfig
from .drive import CurrentPath
from .forcelaw import force_law_matrix, torque_matrix
from .frames import Fix, SensorFrame
from .gate import InnovationGate, rendered_protection_level
from .headroom import SensorHeadroom, SensorLayout
from .history import CurrentHistory
from .pipeline import SensorPipeline
from .skip import CoilSkipBound
from .thermal import ThermalGuard
from .tracker import PoseTracker

FAULTS = ("pwm_nack", "sensor_stuck", "sensor_dead", "sensor_saturated", "sensor_value",
          "lost", "gated", "out_of_box", "overrun", "thermal", "over_limit")
"""The runner's fault states (docs/runner.md: cause and resume policy of each)."""

LOCALIZATION_FAULTS = ("sensor_stuck", "sensor_dead", "sensor_saturated", "sensor_value",
                       "lost", "gated", "out_of_box")
"""Faults cleared by ``RunnerConfig.resume_fixes`` accepted fixes in a row (the frames that
show the position is supported again), not by ``resume_after_s``."""

HISTORY_S = 0.2
"""How far back the modelled currents are kept for the sensor side, s (frames arrive late)."""

STALE_PASSES = 1.5
"""The rendered position is stale once the newest trusted fix was handed over more than this
many sensor passes ago (the pass interval measured from the frames; plus two control periods
of hand-over jitter): a newer frame is missing, so the position is older than one pass."""

PASSES_KEPT = 8
"""Frame intervals the pass interval is the median of."""

SATURATION_SOLVES = 2
"""Allocations per step with saturating cores: about the previous command, then (when that
linearization is off at the result) once about the result (docs/runner.md, "Saturation")."""

SATURATION_RTOL = 1e-3
"""The linearization of g(I) = s(|I|) I is accepted at the allocation's result when it is off
by at most SATURATION_RTOL |I_k| + :data:`SATURATION_ATOL_A` in every coil (0.1 % of that
coil's force, plus 1 mA)."""

SATURATION_ATOL_A = 1e-3
"""See :data:`SATURATION_RTOL`, A."""

_ALL_ROWS = np.arange(8)


@dataclass
class StepRecord:
    """What one control step did (SI). ``state`` is 'running', 'safe' or a fault name;
    ``moment_a_m2`` the moment rendered on (the tracker's), ``torque_n_m`` the torque m x B
    the commanded currents exert on it."""

    t_s: float
    position_m: np.ndarray
    force_ref_n: np.ndarray
    command_a: np.ndarray
    voltage_v: np.ndarray
    predicted_current_a: np.ndarray
    loop_s: float
    state: str
    new_frame: bool
    torque_n_m: np.ndarray
    moment_a_m2: np.ndarray


@dataclass
class RunnerIO:
    """What the runner talks to.

    Attributes
    ----------
    coils : firmware_io.hw.coils.CoilDriver
        Takes the voltages of the current path (``command_voltage``); ``all_off`` is the safe
        state.
    sensors : callable
        ``sensors(t_s) -> Fix | SensorFrame | None``: the newest result not yet handed out. A
        source with ``attach(pipeline)`` is given the runner's :class:`SensorPipeline` and runs
        it on its side (the sensor thread); a raw :class:`SensorFrame` is processed inside the
        step.
    log : callable -- ``log(line)`` for one line per fault, resume or exclusion
    clock : callable -- ``clock() -> s`` for the compute time of a step
    """

    coils: object
    sensors: Callable
    log: Callable[[str], None] = print
    clock: Callable[[], float] = time.perf_counter


class SceneForce:
    """A compiled scene (:class:`firmware_io.scene.Scene`) as the runner's interface:
    ``force(position_m (3,), velocity_m_s (3,)) -> (3,)`` N at one point, ``forces(positions_m
    (N, 3), velocities_m_s (N, 3)) -> (N, 3)`` N at each magnet's (one evaluation)."""

    def __init__(self, scene):
        self.scene = scene

    def force(self, p, v):
        return self.scene.force(np.asarray(p, float)[None], np.asarray(v, float)[None])[0]

    def forces(self, p, v):
        return self.scene.force(np.asarray(p, float), np.asarray(v, float))


class Runner:
    """Compose map, scene, estimator, allocator and drivers into the fail-safe control loop.

    Parameters
    ----------
    fieldmap : firmware_io.mapfile.MapFile (an ActuationSource with a sensor section)
        ``actuation(point, coils=...)`` (rows Bx, By, Bz, dBx/dx, dBx/dy, dBx/dz, dBy/dy,
        dBy/dz, per ampere), ``bias_force(point)`` N, ``bounds`` m, ``moment_a_m2`` A m^2,
        ``sensor_positions_m`` and ``sensor_coil_field()`` (:class:`SensorLayout`).
    scene : object -- ``force(position_m, velocity_m_s) -> (3,)`` N
    estimator : firmware_io.localization.Estimator
        ``estimate(readings_t, currents_a, ...)``, ``reset()``, ``integrity_risk``,
        ``model_bias_m`` (:class:`firmware_io.localization.Estimate` lists the estimate's
        fields).
    io : RunnerIO -- coils, sensor source, log, clock
    config : RunnerConfig
    tracker : PoseTracker, optional (default: a new one)
    allocate : callable, optional
        ``allocate(force_matrix, target, current_limit, total_limit, unipolar=...,
        inequalities=...)`` -> (currents, residual) (default
        :class:`firmware_io.allocation.Allocator`).
    headroom : SensorHeadroom, optional -- sensors the allocation keeps in their linear range
        (the scene's choice; default none)
    """

    def __init__(self, fieldmap, scene, estimator, io: RunnerIO, config: RunnerConfig, *,
                 tracker: PoseTracker | None = None, allocate: Callable | None = None,
                 headroom: SensorHeadroom | None = None):
        if io.coils.n_coils != config.n_coils:
            raise BadInputError("config.drive.resistance_ref_ohm",
                                f"{io.coils.n_coils} values (one per coil of the driver)",
                                config.n_coils)
        if allocate is None:
            allocate = Allocator()
        self.map, self.scene, self.estimator, self.cfg = fieldmap, scene, estimator, config
        # ``integrity_risk`` and ``model_bias_m`` of the multi-frame protection level
        self.integrity = estimator
        self.tracker = tracker if tracker is not None else PoseTracker()
        self.allocate, self.headroom = allocate, headroom
        self.coils, self.sensors, self.log, self.clock = io.coils, io.sensors, io.log, io.clock
        n = config.n_coils
        drive = config.drive
        self.path = CurrentPath(drive.drives, config.control_period_s, config.feedforward)
        self.limit = np.full(n, drive.current_limit_a)
        self.thermal = ThermalGuard(n, drive.thermal_continuous_current_a,
                                    drive.thermal_time_constant_s)
        self.moment = np.asarray(fieldmap.moment_a_m2, float)
        self.z_only = config.force_axes == "z"
        self.lo, self.hi = (np.asarray(b, float) for b in fieldmap.bounds)
        self.skip = CoilSkipBound(fieldmap) if config.skip_force_n > 0 else None
        self.layout = SensorLayout.of_map(fieldmap)
        self.command_a = np.zeros(n)
        self.torque_n_m = np.zeros(3)
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
        self.accepted_at_s = -math.inf     # step time the newest accepted fix was taken
        self.frame_times = deque(maxlen=PASSES_KEPT + 1)
        self.pass_interval_s: float | None = None   # median spacing of frame_times, s
        self.position_m = np.full(3, np.nan)
        self.fault_log: list[tuple[float, str, str]] = []
        self.exclusion_log: list[tuple[float, tuple]] = []
        self.fault_excluded: tuple = ()
        self.background_t = np.zeros(3)
        # modelled currents at the start of each step of the last HISTORY_S (frames arrive late)
        self.history = CurrentHistory(n, max(16, int(HISTORY_S / config.control_period_s)))
        self.pipeline = SensorPipeline(estimator, self.layout, self.history.at, self.moment)
        self.last_fix: Fix | None = None
        self.gate = InnovationGate(config.gate_risk)
        # per-stage compute times of the last step (s), when ``profile`` is set
        self.profile = False
        self.stages: dict[str, float] = {}
        self.collector = LoopCollector()
        attach = getattr(io.sensors, "attach", None)
        if attach is not None:
            attach(self.pipeline)       # the source runs the fit on its side

    @property
    def current_a(self) -> np.ndarray:
        """The model of the coil currents, (n,) A (the feed-forward's state)."""
        return self.path.current_a

    # -- life cycle ----------------------------------------------------------------------------
    def start(self) -> None:
        """Initialise every PWM board at the drive record's PWM frequency into the safe state
        (all coils off), then run the step's computations once at the box centre so that the
        first real step is not slowed by first-call costs (an overrun)."""
        self.coils.initialize(self.cfg.drive.pwm_frequency_hz)
        self.coils.all_off()
        self.path.current_a[:] = 0.0
        self.state = "safe"
        centre = 0.5 * (self.lo + self.hi)
        self._allocate(centre, np.asarray(self.scene.force(centre, np.zeros(3)), float),
                       self.moment)
        self.coils.plan_voltage(self.path.voltage(self.path.current_a))
        # a full collection walks every object the map, scene and estimator made at start-up
        # (long enough to be an overrun, docs/runner.md): collect once now, move the survivors
        # out of the collector's reach and take the collector for the loop (module docstring)
        self.collector.take()

    def stop(self) -> None:
        """All coils off, the safe state, and the garbage collector given back as
        :meth:`start` found it (also when the coils fail to answer)."""
        try:
            self.coils.all_off()
            self.state = "safe"
        finally:
            self.collector.release()

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
            self.coils.initialize(self.cfg.drive.pwm_frequency_hz)
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

    # -- the sensor side's results ------------------------------------------------------------
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
        if fix is None:
            return False, problems
        self._note_frame(fix, t_s)
        problems.extend(fix.problems)
        accepted = self._accept(fix, t_s, problems, self)
        self.last_estimate_ok = accepted      # taken into the tracker
        self.accepted_in_row = self.accepted_in_row + 1 if accepted else 0
        self.pipeline.track = self.tracker.snapshot()   # the next frame's prior
        return True, problems

    def _note_frame(self, fix, t_s: float) -> None:
        """A new result from the sensor side (a :class:`Fix`, or anything with its
        ``frame_t_s`` and ``fault_excluded``): the pass interval and the exclusion log."""
        self.last_fix = fix
        if math.isfinite(fix.frame_t_s):
            self.frame_times.append(fix.frame_t_s)
            if len(self.frame_times) > 1:   # the pass interval: the (lower) median spacing
                t = list(self.frame_times)
                d = sorted(b - a for a, b in zip(t, t[1:]))
                self.pass_interval_s = d[(len(d) - 1) // 2]
        if fix.fault_excluded != self.fault_excluded:
            self.fault_excluded = fix.fault_excluded
            self.exclusion_log.append((t_s, fix.fault_excluded))
            self.log(f"[{t_s:9.4f} s] fault detection excludes sensors "
                     f"{list(fix.fault_excluded) or 'none'}")

    def _accept(self, fix: Fix, t_s: float, problems: list, lane) -> bool:
        """Take one magnet's fix into its track (``lane``: ``tracker``, ``gate``, ``have_fix``,
        ``accepted_at_s``; the runner itself for one magnet): the gate, the acquisition's
        prior, the multi-frame protection level against the alert limit; appends the
        problems it finds and returns whether the fix was accepted."""
        ok = fix.ok and math.isfinite(float(np.sum(fix.position_m) + np.sum(fix.moment_a_m2)))
        accepted = False
        gated = ""
        if ok:
            gated, restart = lane.gate.check(fix, lane.tracker)
            if restart:       # the tracker was wrong, not the fix: restart there
                lane.tracker.reset()
                lane.have_fix = False     # renders again from the next accepted fix
            if gated:
                self.pipeline.reacquire = True
        if not ok and fix.candidate and not lane.have_fix and math.isfinite(
                float(np.sum(fix.position_m) + np.sum(fix.moment_a_m2))):
            # acquiring: a consistent fix beyond the limits is the next frame's prior (frames'
            # noise averages out in the chain), nothing renders on it
            lane.tracker.update(fix.position_m, fix.frame_t_s, True, fix.moment_a_m2,
                                fix.pose_covariance)
        pl = (rendered_protection_level(fix, lane.tracker, self.integrity)
              if ok and not gated else math.inf)
        if gated:
            problems.append(("gated", gated))
        elif ok and pl > self.cfg.alert_limit_m:
            problems.append(("lost", f"protection level {pl * 1e3:.3g} mm > alert limit "
                             f"{self.cfg.alert_limit_m * 1e3:.3g} mm"))
            if not lane.have_fix:
                # acquisition: the tracker takes the fix (it passed the estimator's tests and
                # the gate), nothing renders until a filtered PL is within the limit
                lane.tracker.update(fix.position_m, fix.frame_t_s, True, fix.moment_a_m2,
                                    fix.pose_covariance)
        elif ok:
            lane.tracker.update(fix.position_m, fix.frame_t_s, True, fix.moment_a_m2,
                                fix.pose_covariance)
            lane.have_fix = accepted = True
            lane.accepted_at_s = t_s
            self.background_t = fix.background_t
        return accepted

    def _freshness(self, t_s: float, problems: list, lane=None) -> None:
        """No force with a position older than one sensor pass: 'lost' once the newest accepted
        fix was handed over more than :data:`STALE_PASSES` pass intervals ago (a newer frame
        is missing); beyond ``max_fix_age_s`` the track is dropped (the next fix starts from
        the global search and restarts the tracker: a returning finger is not gated against
        where it left). ``lane``: one magnet's track (:meth:`_accept`; default the runner's
        own)."""
        lane = self if lane is None else lane
        cfg = self.cfg
        age = t_s - lane.tracker.t
        if age > cfg.max_fix_age_s:
            # also an acquisition's track (fixes beyond the alert limit): a state that old
            # would bend the next fixes with its velocity
            lane.tracker.reset()
            self._forget_track(lane)
            self.pipeline.reacquire = True
            if lane.have_fix:
                lane.have_fix = False
                problems.append(("lost", f"newest accepted fix {age * 1e3:.0f} ms old > "
                                 f"{cfg.max_fix_age_s * 1e3:.0f} ms: track dropped"))
            return
        if not lane.have_fix:
            return
        dt = self.pass_interval_s
        if dt is None:
            return
        since = t_s - lane.accepted_at_s
        limit = STALE_PASSES * dt + 2 * cfg.control_period_s
        if since > limit:
            problems.append(("lost", f"no trusted fix for {since * 1e3:.1f} ms > "
                             f"{limit * 1e3:.1f} ms ({STALE_PASSES:g} sensor passes)"))

    def _forget_track(self, lane) -> None:
        """The sensor side fits the next frame without ``lane``'s prior."""
        self.pipeline.track = None

    # -- the step ------------------------------------------------------------------------------
    def step(self, t_s: float) -> StepRecord:
        """One control step at time ``t_s`` (s). Never raises for a device fault or a bad
        frame.

        ``self.sensors(t_s)`` hands over the newest :class:`Fix` of the sensor side, or None;
        a source that hands over raw :class:`SensorFrame` s instead has them processed here
        (the single-threaded fallback: the fit then counts in this step). After the coils
        were written, the young garbage collection when one is due (module docstring); the
        record's ``loop_s`` includes it.
        """
        t0 = self.clock()
        rec = self._step(t_s, t0)
        tc = self.clock() if self.profile else 0.0
        if self.collector.young():
            rec.loop_s = self.clock() - t0
        if self.profile:
            self.stages["collect"] = self.clock() - tc
        return rec

    def _step(self, t_s: float, t0: float) -> StepRecord:
        """The step up to the coils' write (:meth:`step`)."""
        cfg = self.cfg
        prof = self.profile
        self.history.push(t_s, self.path.current_a)
        new_frame, problems = self._take_fix(t_s)
        tm = self._mark("fix", t0) if prof else t0
        if self.tracker.x is not None:
            self._freshness(t_s, problems)
        if not self.have_fix:
            # a coil over its budget is a fault whether or not the finger is located; it
            # outlasts any localization problem (it waits for the coil to cool), so it is shown
            problems[:0] = self._thermal_problem([])
            if problems and (self.fault is None or problems[0][0] != self.fault):
                self._enter_fault(t_s, *problems[0])
            return self._record(t_s, t0, np.full(3, np.nan), np.zeros(3), new_frame,
                                off=True)
        p = np.asarray(self.tracker.predict(t_s), float)
        vel = np.asarray(self.tracker.x[1], float)
        m = self._moment()
        self.position_m = p
        inside = bool(np.all(p >= self.lo) and np.all(p <= self.hi))
        if not inside:
            problems.append(("out_of_box", f"estimate {np.round(p * 1e3, 1).tolist()} mm outside "
                             f"the map box"))
        self._thermal_problem(problems)
        if self._still_off(t_s, problems):
            return self._record(t_s, t0, p, np.zeros(3), new_frame, off=True)
        if prof:
            tm = self._mark("predict", tm)

        f_ref = np.asarray(self.scene.force(p, vel), float)
        if prof:
            tm = self._mark("object_force", tm)
        command = self._allocate(p, f_ref, m)
        if self._over_limit(t_s, command):
            return self._record(t_s, t0, p, f_ref, new_frame, off=True)
        return self._drive(t_s, t0, p, f_ref, command, new_frame)

    def _over_limit(self, t_s: float, command: np.ndarray) -> bool:
        """Enter 'over_limit' (True) when ``command`` (A) breaks a per-coil limit, the total
        budget or the drive mode, or is not finite: a defect upstream never reaches a coil."""
        cfg = self.cfg
        total = float(np.sum(np.abs(command)))
        budget = cfg.drive.total_current_a
        if np.any(np.abs(command) > self.limit + 1e-9) or total > budget + 1e-9 \
                or (cfg.unipolar and np.any(command < -1e-9)) \
                or not math.isfinite(total):
            self._enter_fault(t_s, "over_limit",
                              f"command max |I| {np.abs(command).max():.3f} A, sum {total:.3f} A "
                              f"(limits {cfg.drive.current_limit_a:.3f} A, {budget:.3f} A)")
            return True
        return False

    def _thermal_problem(self, problems: list) -> list:
        """``problems`` with the 'thermal' problem appended when a coil's I^2 t is over its
        budget."""
        if self.thermal.exceeded():
            problems.append(("thermal", f"I^2 t {self.thermal.energy_a2s.max():.0f} A^2 s above "
                             f"the budget {self.thermal.budget_a2s:.0f} A^2 s"))
        return problems

    def force_matrix(self, p: np.ndarray, moment_a_m2, coils=None) -> np.ndarray:
        """Force per ampere at p on the moment ``moment_a_m2`` (A m^2): (3, c) N/A, or (1, c)
        (Fz) when rendering Fz alone; with ``coils`` (index array) only those columns."""
        a = self.map.actuation(p, coils=coils)
        f = force_law_matrix(moment_a_m2) @ a[3:]
        return f[2:3] if self.z_only else f

    def _allocate(self, p: np.ndarray, f_ref: np.ndarray, m: np.ndarray) -> np.ndarray:
        """Currents (n,) A for the object force ``f_ref`` N at p on the moment m; sets
        ``torque_n_m``, the torque m x B of those currents (N m)."""
        cfg = self.cfg
        prof = self.profile
        tm = self.clock() if prof else 0.0
        keep = None
        if self.skip is not None:
            k = self.skip.keep(p, self.limit, cfg.skip_force_n, math.sqrt(float(m @ m)))
            if len(k) < cfg.n_coils:
                keep = k
        a = self.map.actuation(p, coils=keep)
        fm = force_law_matrix(m) @ a[3:]
        target = f_ref - np.asarray(self.map.bias_force(p), float)
        if self.z_only:
            fm, target = fm[2:3], target[2:3]
        if prof:
            tm = self._mark("force_matrix", tm)
        limit = self.limit if keep is None else self.limit[keep]
        kw = {"unipolar": cfg.unipolar}
        if self.headroom is not None:
            rest = self.layout.predicted_t(np.zeros(cfg.n_coils), p, m, self.background_t)
            g, h, _ = self.headroom.constraints(self.layout, rest, keep)
            if len(h):
                kw["inequalities"] = (g, h)
        command = np.zeros(cfg.n_coils)
        equivalent = np.zeros(0 if keep is None else len(keep))
        if keep is None or len(keep):
            i, equivalent = self._currents_for(fm, target, limit, kw, keep)
            if keep is None:
                command = i
            else:
                command[keep] = i
        b = a[:3] @ equivalent       # the saturating cores' field of those currents
        self.torque_n_m = torque_matrix(m) @ b
        if prof:
            self._mark("allocation", tm)
        return command

    def _currents_for(self, fm, target, limit, kw, keep) -> tuple[np.ndarray, np.ndarray]:
        """The allocation's currents I (A) for the force per ampere ``fm`` (linear cores) and
        ``target`` (N), and their linear-equivalent currents g(I) (A: what the linear columns
        of A multiply). Saturating cores (``cfg.saturation``): column k scaled by s_k(|I_k|) at
        the currents solved for, g(I) = s(|I|) I -- the allocation runs on g linearized about
        the previous command and, when the result lies where that is off by more than
        :data:`SATURATION_RTOL`, once more about the result (docs/runner.md, "Saturation")."""
        total = self.cfg.drive.total_current_a
        sat = self.cfg.saturation
        if sat is None:
            i = np.asarray(self.allocate(fm, target, limit, total, **kw)[0], float)
            return i, i
        about = self.command_a if keep is None else self.command_a[keep]
        for _ in range(SATURATION_SOLVES):
            gain, offset = sat.linearize(about, keep)
            i = np.asarray(self.allocate(fm * gain, target - fm @ offset, limit, total,
                                         **kw)[0], float)
            g = sat.equivalent(i, keep)
            if np.all(np.abs(g - gain * i - offset) <= SATURATION_RTOL * np.abs(i)
                      + SATURATION_ATOL_A):
                break
            about = i
        return i, g

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
                          self.clock() - t0, self.state, new_frame, self.torque_n_m.copy(),
                          self._moment())

    def _record(self, t_s, t0, p, f_ref, new_frame, *, off: bool) -> StepRecord:
        cfg = self.cfg
        if off:
            if self.fault is None:
                self.state = "safe"
                if np.any(self.command_a != 0) or np.any(np.abs(self.path.current_a) > 0):
                    self.coils.all_off()
            self.command_a = np.zeros(cfg.n_coils)
            self.torque_n_m = np.zeros(3)
            current = self.path.advance(np.zeros(cfg.n_coils))
            self.thermal.update(current, cfg.control_period_s)
        return StepRecord(t_s, np.asarray(p, float).copy(), np.asarray(f_ref, float),
                          self.command_a.copy(), np.zeros(cfg.n_coils), self.path.current_a.copy(),
                          self.clock() - t0, self.state, new_frame, self.torque_n_m.copy(),
                          self._moment())

    def _moment(self) -> np.ndarray:
        """The moment rendered on, A m^2: the tracker's, else the map's."""
        m = self.tracker.moment_a_m2
        return (self.moment if m is None else m).copy()
