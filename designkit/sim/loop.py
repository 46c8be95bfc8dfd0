"""The closed loop: firmware_io's runner driven step by step against the simulated device.

Per control period T (s): scheduled faults are injected, the sensor source ticks (outside the
runner's timed section, as the sensor thread runs beside the loop on hardware), the runner
steps, the true force on the magnet (N) is taken at the true position with the true coil
currents (A), and the coils advance one R-L step under the voltages the PWM registers hold.
Compute time (:class:`LoopTiming`): modelled by default -- the runner's step takes no simulated
time and a fit on the sensor side a fixed one, so a run is the same on any host under any load
-- or measured (this thread's CPU time less the CPU time spent inside the simulated PWM boards).
The measured step time is recorded either way (``loop_s``). Output: :class:`SimulationResult`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..errors import BadInputError
from ..support.progress import tqdm
from .device import SimulatedDevice
from .faults import FAULT_CLEARS_S, FaultSchedule, inject
from .sensors import MODELLED_FIT_S
from .trajectory import Trajectory

OUT_OF_BOX_LIFT_M = 0.06
"""An injected ``out_of_box`` lifts the finger this far (above the map box), m."""

OUT_OF_BOX_S = FAULT_CLEARS_S["out_of_box"]
"""How long an injected ``out_of_box`` keeps the finger lifted, s."""

RUNNING_FAULTS = ("pwm_nack", "overrun", "over_limit")
"""Faults injected at the next running step, not at their scheduled time: a NACK answers the
next PWM write, a slow step or an over-limit command is a defect of a running loop; while
another fault holds the coils off none of them can act (their time to safe would count the
other fault's hold time)."""

COLUMNS = ("t_s", "x_m", "y_m", "z_m", "xe_m", "ye_m", "ze_m", "mx_a_m2", "my_a_m2",
           "mz_a_m2", "mxe_a_m2", "mye_a_m2", "mze_a_m2", "fx_ref_n", "fy_ref_n", "fz_ref_n",
           "fx_n", "fy_n", "fz_n", "fx_obj_n", "fy_obj_n", "fz_obj_n", "tx_n_m", "ty_n_m",
           "tz_n_m", "txe_n_m", "tye_n_m", "tze_n_m", "n_saturating", "fix_t_s", "loop_s")
"""The per-step float columns (SI): true (x_m, mx_a_m2, ...) and estimated (xe_m, mxe_a_m2,
...) pose, the rendered force (f*_ref_n: the runner's target), the force on the true magnet
(f*_n) and the object's at the true position (f*_obj_n), the torque of the coils' field on the
true magnet (t*_n_m) and as the runner reports it on its estimate (t*e_n_m), the sensors left
out for predicted saturation in the newest frame, the frame time of the newest fix in the
tracker (fix_t_s, NaN: none); coil currents and commands are added per coil, and
``fault_excluded`` (the sensors the estimator's fault detection excludes)."""


@dataclass(frozen=True)
class LoopTiming:
    """How time passes in a simulated run.

    Attributes
    ----------
    period_s : float, s -- the control period T
    compute : {'modelled', 'measured'}
        'modelled' (default): the runner's compute clock stands still (a step overruns only when
        an overrun is injected) and a fit on the sensor side takes ``fit_time_s``, so the run
        does not depend on the host's speed or load. 'measured': the runner's clock is this
        thread's CPU time less the simulated PWM boards' (its stage profile), and a fit takes its
        measured CPU time (benchmarks).
    fit_time_s : float, s -- the modelled fit time
    """

    period_s: float = 1e-3
    compute: Literal["modelled", "measured"] = "modelled"
    fit_time_s: float = MODELLED_FIT_S

    def __post_init__(self):
        if not (0 < self.period_s <= 0.1):
            raise BadInputError("period_s", "in (0, 0.1] s", self.period_s)
        if self.compute not in ("modelled", "measured"):
            raise BadInputError("compute", "'modelled' or 'measured'", self.compute)
        if not (0 <= self.fit_time_s < math.inf):
            raise BadInputError("fit_time_s", "a finite time >= 0 s", self.fit_time_s)


def _still() -> float:
    """The modelled compute clock: a step takes no simulated time."""
    return 0.0


@dataclass
class SimulationResult:
    """Per-step columns (SI; the run.csv columns, plus ``new_frame`` (bool: the step took in a
    new sensor result) and, when the runner profiles, ``stage_<name>_s``), the faults as
    injected (time s, type; those in :data:`RUNNING_FAULTS` wait for a running step), the
    runner's fault log, the sensor side's fit times (s, one per frame) and its fixes (field
    time s, trusted, distance from the truth m)."""

    columns: dict
    faults: list
    fault_log: list
    period_s: float
    fit_s: list = field(default_factory=list)
    fixes: list = field(default_factory=list)


class _Injector:
    """The fault schedule during a run: what to inject before each step, and the hooks that
    let a defect reach the runner (the allocation wrapper, the out-of-box lift)."""

    def __init__(self, device: SimulatedDevice, faults: FaultSchedule):
        self.device = device
        self.events = list(faults.events)
        self.pending: list = []
        self.injected: list = []
        self.state: dict = {}
        self.out_windows = [(te, te + OUT_OF_BOX_S) for te, f in self.events
                            if f == "out_of_box"]

    def position(self, trajectory: Trajectory, ts: float) -> np.ndarray:
        """The true position at ``ts`` (s), lifted out of the box in an out-of-box window."""
        p = trajectory.at(ts)
        if any(a <= ts < b for a, b in self.out_windows):
            p = p + np.array([0.0, 0.0, OUT_OF_BOX_LIFT_M])   # above the map box
        return p

    def allocate_hook(self, allocate):
        """Wrap the allocator so that an injected over-limit defect asks for 1.5x the limit."""
        def wrapped(*args, **kw):
            i, r = allocate(*args, **kw)
            if self.state.pop("over_limit_step", False):     # a defect upstream
                i = 1.5 * np.asarray(args[2], float) * np.where(i < 0, -1.0, 1.0)
            return i, r
        return wrapped

    def before_step(self, runner, ts: float) -> bool:
        """Inject what is due at ``ts`` and end expired ones; True when this step overruns."""
        device, state = self.device, self.state
        n = device.array.n_coils
        while self.events and self.events[0][0] <= ts + 1e-12:
            _, name = self.events.pop(0)
            if name in RUNNING_FAULTS:
                self.pending.append(name)     # shows only in a running loop: wait for one
            else:
                self._inject(runner, name, ts)
        if self.pending and runner.state == "running":
            self._inject(runner, self.pending.pop(0), ts)
        if ts >= state.get("saturated_until", np.inf):
            device.field_offset_t[0] = 0.0
            state.pop("saturated_until")
        if ts >= state.get("dead_until", np.inf):
            device.tlv[n + 1].nack_always = False
            state.pop("dead_until")
        return state.pop("overrun_step", False)

    def _inject(self, runner, name: str, ts: float) -> None:
        inject(self.device, runner, name, ts, self.state)
        self.injected.append((float(ts), name))


class _Recorder:
    """The per-step columns of a run (see :class:`SimulationResult`)."""

    def __init__(self, n_steps: int, n_coils: int):
        self.cols = {k: np.zeros(n_steps) for k in COLUMNS}
        self.cur = np.zeros((n_steps, n_coils))
        self.cmd = np.zeros((n_steps, n_coils))
        self.new_frame = np.zeros(n_steps, dtype=bool)
        self.stages: dict = {}
        self.states: list = []
        self.excluded: list = []

    def _put(self, names: str, s: int, values) -> None:
        for name, v in zip(names.split(), values):
            self.cols[name][s] = v

    def add(self, s: int, rec, truth: dict, i_true, runner) -> None:
        """Step ``s``: the runner's record, the truth (position, moment, force, torque, object
        force: (3,) each, the object's None without a scene) and the true currents."""
        cols = self.cols
        cols["t_s"][s] = rec.t_s
        self._put("x_m y_m z_m", s, truth["position"])
        self._put("xe_m ye_m ze_m", s, rec.position_m)
        self._put("mx_a_m2 my_a_m2 mz_a_m2", s, truth["moment"])
        self._put("mxe_a_m2 mye_a_m2 mze_a_m2", s, rec.moment_a_m2)
        self._put("fx_ref_n fy_ref_n fz_ref_n", s, rec.force_ref_n)
        self._put("fx_n fy_n fz_n", s, truth["force"])
        if truth["object"] is not None:
            self._put("fx_obj_n fy_obj_n fz_obj_n", s, truth["object"])
        self._put("tx_n_m ty_n_m tz_n_m", s, truth["torque"])
        self._put("txe_n_m tye_n_m tze_n_m", s, rec.torque_n_m)
        fix = runner.last_fix
        cols["n_saturating"][s] = 0 if fix is None else len(fix.saturating)
        t_fix = runner.tracker.t
        cols["fix_t_s"][s] = np.nan if t_fix is None else t_fix
        self.excluded.append(" ".join(map(str, runner.fault_excluded)))
        cols["loop_s"][s] = rec.loop_s
        self.new_frame[s] = rec.new_frame
        if runner.profile and rec.state == "running":
            for name, v in runner.stages.items():
                self.stages.setdefault(name, np.full(len(self.new_frame), np.nan))[s] = v
        self.cur[s] = i_true
        self.cmd[s] = rec.command_a
        self.states.append(rec.state)

    def columns(self) -> dict:
        cols = self.cols
        n = self.cur.shape[1]
        for k in range(n):
            cols[f"i{k + 1}_a"] = self.cur[:, k]
        for k in range(n):
            cols[f"cmd{k + 1}_a"] = self.cmd[:, k]
        cols["state"] = np.array(self.states)
        cols["fault_excluded"] = np.array(self.excluded)
        cols["new_frame"] = self.new_frame
        for name, v in self.stages.items():
            cols[f"stage_{name}_s"] = v
        return cols


def simulate(device: SimulatedDevice, runner_factory, trajectory: Trajectory, *,
             duration_s: float, timing: LoopTiming = LoopTiming(),
             faults: FaultSchedule = FaultSchedule(), scene_force=None,
             progress: bool = True) -> SimulationResult:
    """Close the loop: ``runner_factory(sensor_source, clock, allocate_hook)`` -> a started Runner.

    Parameters
    ----------
    device : SimulatedDevice
    runner_factory : callable
        Builds the :class:`firmware_io.runner.Runner` around the given sensor source, compute
        clock and allocation wrapper (the plant wraps both to inject overrun and over-limit
        faults), on ``device.coils``.
    trajectory : Trajectory
    duration_s : float, s
    timing : LoopTiming -- the control period and how compute time passes
    faults : FaultSchedule
    scene_force : callable, optional
        ``scene_force(p, v) -> (3,)``: the object's force at the TRUE position (the reference the
        rendered force is judged against).
    """
    period_s = timing.period_s
    n_steps = int(round(duration_s / period_s))
    t = np.arange(n_steps) * period_s
    injector = _Injector(device, faults)

    def position_at(ts: float) -> np.ndarray:
        return injector.position(trajectory, ts)

    true_p = np.array([position_at(ts) for ts in t])
    vel = np.gradient(true_p, period_s, axis=0)
    device.prepare(true_p, trajectory.moment_direction(t, device.moment)
                   if trajectory.tilted else None)
    measured = timing.compute == "measured"
    source = device.sensor_source(position_at, period_s,
                                  None if measured else timing.fit_time_s)
    # measured compute time = this thread's CPU time (the plant shares the host with the
    # runner; other processes would otherwise show up as overruns) less the CPU time spent
    # inside the simulated PWM boards (the plant's, not the runner's)
    cpu = device.coil_bus.cpu_outside_s
    runner = runner_factory(source, cpu if measured else _still, injector.allocate_hook)
    rec_all = _Recorder(n_steps, device.array.n_coils)
    bar = tqdm(total=n_steps, desc="simulate", unit="step", disable=not progress,
               mininterval=0.5)
    try:     # the runner gives the garbage collector back on any exit
        for s in range(n_steps):
            ts = t[s]
            overrun = injector.before_step(runner, ts)
            source.tick(ts)
            c0 = cpu()
            rec = _step(runner, ts, overrun)
            if not measured:      # the step's measured CPU time, for the record only
                rec.loop_s = cpu() - c0
            i_true = device.current_a.copy()
            truth = {"position": true_p[s], "moment": device.moment_steps[s],
                     "force": device.true_force_n(s, i_true),
                     "torque": device.true_torque_n_m(s, i_true),
                     "object": (scene_force(true_p[s], vel[s]) if scene_force is not None
                                else None)}
            rec_all.add(s, rec, truth, i_true, runner)
            device.advance_currents(period_s)
            device.coil_bus.clear_log()
            bar.update()
        bar.close()
    finally:
        runner.stop()
    return SimulationResult(rec_all.columns(), injector.injected, list(runner.fault_log),
                            period_s, list(source.fit_s), list(source.fixes))


def _step(runner, ts: float, overrun: bool):
    """One runner step; an injected overrun makes the compute clock jump inside the step."""
    if overrun:
        original = runner.clock
        calls = {"n": 0}

        def slow_clock() -> float:
            calls["n"] += 1
            return original() + (0.0 if calls["n"] == 1 else 5 * runner.cfg.control_period_s
                                  * runner.cfg.overrun_factor)

        runner.clock = slow_clock
        try:
            return runner.step(ts)
        finally:
            runner.clock = original
    return runner.step(ts)
