"""firmware_io.runner.collector: the runner takes the garbage collector while it runs and gives
it back as it found it (at stop, after an exception, after Ctrl-C); the step itself makes no
reference cycles (the collector would have to find them), on the simulated PWM boards."""

from __future__ import annotations

import gc

import numpy as np
import pytest

from designkit.design import default_design
from designkit.sim import SimulatedDevice, simulate, slide_trajectory
from firmware_io.runner import Fix, PoseTracker, Runner, RunnerConfig, RunnerIO
from firmware_io.runner.collector import LoopCollector

from _runner_fakes import PlaneScene, TruthEstimator, clipped_lstsq, device_map, md10c_drive

BOX = (np.array([-0.075, -0.075, 0.010]), np.array([0.075, 0.075, 0.080]))


@pytest.fixture(scope="module")
def device_and_a(thesis_array):
    design = default_design()
    return design, thesis_array, thesis_array.actuation_matrix(np.array([0.0, 0.0, 0.04]))


@pytest.fixture
def collector_state():
    """The collector's state before the test, restored after it whatever the test did."""
    enabled, frozen = gc.isenabled(), gc.get_freeze_count()
    gc.enable()
    yield
    gc.unfreeze()
    if frozen:
        gc.freeze()
    (gc.enable if enabled else gc.disable)()


def _runner(device_and_a, source=None):
    design, _, a = device_and_a
    drive = md10c_drive(design)
    dev = SimulatedDevice(design, device_and_a[1], drive=drive)
    p = np.array([0.0, 0.0, 0.04])

    def fixed(t):
        return Fix(p.copy(), dev.moment.copy(), True, t, (), np.zeros(18, bool), 0.0,
                   (0.3e-3) ** 2 * np.eye(3), 1e-3)

    r = Runner(device_map(a, BOX, dev), PlaneScene(0.05, 6.0), TruthEstimator(lambda: p),
               RunnerIO(dev.coils, source or fixed, lambda line: None, lambda: 0.0),
               RunnerConfig(drive), tracker=PoseTracker(), allocate=clipped_lstsq)
    return r, dev


def test_collector_is_off_in_the_loop_and_given_back_at_stop(device_and_a, collector_state):
    r, _ = _runner(device_and_a)
    r.start()
    assert not gc.isenabled() and gc.get_freeze_count() > 0
    for k in range(50):
        assert r.step(k * 1e-3).state == "running"
    r.stop()
    assert gc.isenabled() and gc.get_freeze_count() == 0
    r.stop()                          # a second stop changes nothing
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_a_collector_that_was_off_stays_off(device_and_a, collector_state):
    gc.disable()
    r, _ = _runner(device_and_a)
    r.start()
    r.step(0.0)
    r.stop()
    assert not gc.isenabled() and gc.get_freeze_count() == 0


def test_young_passes_run_in_the_loop_and_free_cycles(collector_state):
    """A cycle made while the collector is held is freed by the next due young pass (not only
    at stop); nothing runs while it is not held."""
    c = LoopCollector()
    assert not c.young()
    c.take()
    try:
        class Node:
            pass

        a, b = Node(), Node()
        a.other, b.other = b, a
        del a, b
        gc.set_debug(gc.DEBUG_SAVEALL)
        keep = [[] for _ in range(c.young_objects)]     # generation 0 past its threshold
        assert c.young()
        del keep
        assert sum(type(o).__name__ == "Node" for o in gc.garbage) == 2
    finally:
        gc.set_debug(0)
        gc.garbage.clear()
        c.release()
    assert gc.isenabled()


@pytest.mark.parametrize("exc", [KeyboardInterrupt, RuntimeError])
def test_the_collector_is_given_back_when_the_simulated_loop_is_interrupted(
        device_and_a, collector_state, exc):
    design, _, a = device_and_a
    drive = md10c_drive(design)
    dev = SimulatedDevice(design, device_and_a[1], seed=1, drive=drive)
    traj = slide_trajectory(lambda x, y: np.full_like(x, 0.05), duration_s=0.05, samples=51)
    calls = {"n": 0}

    def factory(source, clock, hook):
        def interrupting(t):
            calls["n"] += 1
            if calls["n"] == 20:
                raise exc("interrupted")
            return source(t)
        r = Runner(device_map(a, BOX, dev), PlaneScene(0.05, 6.0),
                   TruthEstimator(lambda: source.frame_truth_m, dev.moment),
                   RunnerIO(dev.coils, interrupting, lambda line: None, clock),
                   RunnerConfig(drive), allocate=hook(clipped_lstsq))
        r.start()
        assert not gc.isenabled()
        return r

    with pytest.raises(exc):
        simulate(dev, factory, traj, duration_s=0.05, progress=False)
    assert calls["n"] == 20
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_the_step_makes_no_reference_cycles(device_and_a, collector_state):
    """Every step's objects are freed by reference counting: a young pass after 200 steps
    (frames, allocation, the PWM boards' block writes through i2c messages) finds no garbage."""
    r, _ = _runner(device_and_a)
    r.start()
    try:
        r.step(0.0)
        gc.collect(0)
        gc.set_debug(gc.DEBUG_SAVEALL)
        for k in range(1, 200):
            assert r.step(k * 1e-3).state == "running"
        gc.collect(0)
        kinds = sorted({type(o).__name__ for o in gc.garbage})
        assert kinds == []
    finally:
        gc.set_debug(0)
        gc.garbage.clear()
        r.stop()
