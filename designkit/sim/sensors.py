"""The runner's sensor source on the simulated sensor bus, with the sensor thread's timing.

Models :class:`firmware_io.run.ThreadedSensorSource`: read a pass of every sensor (its wire time
on the simulated 400 kHz bus), fit it (a modelled compute time, so that a run does not depend on
the host's speed or load; or, asked for, its measured CPU time), publish the
:class:`firmware_io.runner.Fix`, read the next pass. Each frame carries the field (T) of the
previous pass's start, as a master-controlled TLV493D returns the conversion the previous read
triggered.
"""

from __future__ import annotations

import time

import numpy as np

from firmware_io.runner import SensorFrame

MODELLED_FIT_S = 1e-3
"""Compute time of one fit on the sensor side in the simulated timeline, s: a fixed value, so
that when a fix is published does not depend on the host (a warm fit takes a few hundred us on
a desktop CPU, a cold one and a slower controller more; studies/bench_runner.py measures it)."""


class SimSensorSource:
    """The sensor side of :class:`firmware_io.runner.Runner` on the simulated sensor bus, with
    the timing of the sensor thread (:class:`firmware_io.run.ThreadedSensorSource`).

    :meth:`tick` does the simulation work (fields into the TLV493D models, one pass of
    :meth:`firmware_io.hw.sensors.SensorArrays.read` on the sensor bus, the runner's
    :class:`firmware_io.runner.SensorPipeline` on the frame); the plant calls it before each
    runner step, outside the runner's timed section, as the sensor thread runs beside the
    control loop on hardware. The thread's cycle is: read a pass (its wire time on the bus
    model), then fit (``fit_time_s``, or its measured compute time on this thread's CPU clock
    when that is None), publish the
    :class:`firmware_io.runner.Fix`, read the next pass. The runner takes a result at the first
    control step at or after the time it is published. In master-controlled mode a TLV493D
    returns the conversion triggered by the previous read, so each frame carries the field of
    the previous pass's start time. Without an attached pipeline raw frames are handed over.

    Parameters
    ----------
    device : designkit.sim.device.SimulatedDevice
    position_at : callable, ``position_at(t_s) -> (3,)`` m, the true position
    period_s : float, s -- the control period
    fit_time_s : float or None, s -- the modelled compute time of a fit (default
        :data:`MODELLED_FIT_S`); None: the fit's measured CPU time (the timeline then depends
        on the host)

    Attributes
    ----------
    fit_s : list of float
        Measured CPU time of each fit on the sensor side, s (diagnostics; the timeline uses
        ``fit_time_s`` unless it is None).
    frame_truth_m : ndarray (3,) or None
        The true position at the field time of the last frame read (diagnostics).
    fixes : list of (field time s, trusted, distance m)
        Each published fix: whether the sensor side trusted it and how far its position was
        from the true one at its frame's field time (diagnostics).
    """

    def __init__(self, device, position_at, period_s: float,
                 fit_time_s: float | None = MODELLED_FIT_S):
        self.device, self.position_at, self.period_s = device, position_at, period_s
        self.fit_time_s = fit_time_s
        self.in_flight = None      # (ready time s, field time s, reading)
        self.fitted = None         # (publish time s, result, field time s)
        self.ready = None          # a result the runner has not taken yet
        self.last_set_s = 0.0
        self.frame_truth_m = None
        self.pipeline = None
        self.fit_s: list = []
        self.fixes: list = []

    def attach(self, pipeline) -> None:
        self.pipeline = pipeline

    def tick(self, t_s: float) -> None:
        dev = self.device
        if self.in_flight is not None:
            ready_s, field_s, reading = self.in_flight
            if t_s + 1e-12 < ready_s:
                return
            self.in_flight = None
            frame = SensorFrame(reading.field_t, reading.status, field_s)
            self.frame_truth_m = self.position_at(field_s)   # diagnostics: where it really was
            fit_s = 0.0
            if self.pipeline is not None:
                c0 = time.thread_time()
                frame = self.pipeline.process(frame)
                measured = time.thread_time() - c0
                self.fixes.append((field_s,) + self.diagnose(frame, self.frame_truth_m))
                self.fit_s.append(measured)
                fit_s = measured if self.fit_time_s is None else self.fit_time_s
            self.fitted = (ready_s + fit_s, frame, field_s)
        if self.fitted is not None:
            publish_s, result, field_s = self.fitted
            if t_s + 1e-12 < publish_s:
                return
            self.fitted = None
            self.ready = result
        step = int(round(t_s / self.period_s))
        b = dev.sensor_readings_t(min(step, len(dev.path_m) - 1), self.position_at(t_s),
                                  dev.current_a)
        for sensor, bi in zip(dev.tlv, b):
            sensor.field_t = tuple(bi)
        dev.sensor_clock.t = t_s
        reading = dev.sensors.read()
        dev.sensor_bus.clear_log()
        self.in_flight = (dev.sensor_clock.t, self.last_set_s, reading)
        self.last_set_s = t_s

    @staticmethod
    def diagnose(fix, truth_m) -> tuple:
        """(trusted, distance m from ``truth_m``) of a published fix (diagnostics)."""
        return bool(fix.ok), float(np.linalg.norm(np.asarray(fix.position_m, float) - truth_m))

    def __call__(self, t_s: float):
        frame, self.ready = self.ready, None
        return frame


