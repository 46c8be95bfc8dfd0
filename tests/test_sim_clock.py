"""The simulated device's compute clock for the runner: this thread's CPU time less the CPU
time spent inside the simulated devices, so a plant slowed by the host's load (wall time inside
the models, not CPU time) neither shortens nor lengthens the runner's measured step."""

from __future__ import annotations

import time

from firmware_io.hw.sim import SimBus
from firmware_io.hw.sim.device import SimDevice

WAIT_S = 0.02


class WaitingDevice(SimDevice):
    """A device at 0x30 whose model waits ``WAIT_S`` (wall time, no CPU) on each write, as a
    model preempted by other processes does."""

    def responds_to(self, addr: int) -> bool:
        return addr == 0x30

    def on_write(self, addr: int, data: bytes) -> None:
        time.sleep(WAIT_S)


def _busy(seconds: float) -> None:
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


def test_the_clock_takes_off_the_models_cpu_time_not_their_wall_time():
    """A step that burns 5 ms of CPU and writes once to a model that waits 20 ms: the clock
    moves by ~5 ms (the step's own CPU), where taking off the models' wall time would move
    it by ~5 - 20 ms (backwards)."""
    bus = SimBus()
    bus.attach(WaitingDevice())
    before, wall_before = bus.cpu_outside_s(), time.thread_time() - bus.model_time_s
    _busy(0.005)
    bus.write_byte(0x30, 0x01)
    step, wall_step = bus.cpu_outside_s() - before, time.thread_time() - bus.model_time_s - \
        wall_before
    assert 0.005 <= step < 0.005 + 0.5 * WAIT_S
    assert wall_step < 0.005 - 0.5 * WAIT_S      # what the wall-time subtraction gave
    assert bus.model_time_s >= WAIT_S > 10 * bus.model_cpu_s


# ---------------------------------------------------------------------------------------------
# the simulated timeline does not depend on the host


def _fake_loop(thesis_array, timing, faults="sensor_dead@0.1"):
    """A 0.25 s closed loop (fake localizer and tracker, constant map) on the simulated device:
    its per-step columns."""
    import numpy as np

    from designkit.design import default_design
    from designkit.sim import FaultSchedule, SimulatedDevice, simulate, slide_trajectory
    from firmware_io.runner import Runner, RunnerConfig, RunnerIO

    from _runner_fakes import (HoldTracker, PlaneScene, TruthEstimator, clipped_lstsq,
                               device_map, md10c_drive)

    box = (np.array([-0.075, -0.075, 0.010]), np.array([0.075, 0.075, 0.080]))
    dev = SimulatedDevice(default_design(), thesis_array, seed=3,
                          drive=md10c_drive(default_design()))
    a = thesis_array.actuation_matrix(np.array([0.0, 0.0, 0.04]))

    def factory(source, clock, hook):
        cfg = RunnerConfig(dev.drive, resume_after_s=0.02)
        r = Runner(device_map(a, box, dev), PlaneScene(0.05, 6.0),
                   TruthEstimator(lambda: source.frame_truth_m, dev.moment),
                   RunnerIO(dev.coils, source, lambda line: None, clock), cfg,
                   tracker=HoldTracker(), allocate=hook(clipped_lstsq))
        r.start()
        return r

    traj = slide_trajectory(lambda x, y: np.full_like(x, 0.05), duration_s=0.25, samples=101)
    res = simulate(dev, factory, traj, duration_s=0.25, timing=timing,
                   faults=FaultSchedule.parse(faults, 0.25), progress=False)
    return res.columns


def _slow_host(monkeypatch, step_s=4e-3):
    """Every read of the CPU and wall clocks advances them by ``step_s`` more: a host many
    times slower (or loaded) than this one."""
    extra = {"t": 0.0}
    for name in ("thread_time", "perf_counter"):
        real = getattr(time, name)

        def slowed(real=real):
            extra["t"] += step_s
            return real() + extra["t"]

        monkeypatch.setattr(time, name, slowed)


def test_a_modelled_run_is_the_same_on_a_slow_host(thesis_array, monkeypatch):
    """Modelled compute time (the default): every column but the measured ``loop_s`` is
    bit-identical when the host's clocks run 4 ms per read faster (a slow or loaded host);
    with measured compute time the same host turns steps into overruns and moves the frames
    -- what a run depending on the machine looks like."""
    import numpy as np

    from designkit.sim import LoopTiming

    fast = _fake_loop(thesis_array, LoopTiming())
    with monkeypatch.context() as m:
        _slow_host(m)
        slow = _fake_loop(thesis_array, LoopTiming())
    for key, col in fast.items():
        a, b = np.asarray(col), np.asarray(slow[key])
        if key != "loop_s":
            assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), key
    assert (np.asarray(fast["state"]) == "running").sum() > 100
    assert np.median(fast["loop_s"]) > 0          # the step's CPU time is still recorded
    with monkeypatch.context() as m:
        _slow_host(m)
        measured = _fake_loop(thesis_array, LoopTiming(compute="measured"))
    assert not np.array_equal(np.asarray(measured["state"]), np.asarray(fast["state"]))
