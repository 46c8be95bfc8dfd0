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
