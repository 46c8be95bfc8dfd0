"""The simulated device: a finger trajectory, exact array physics, R-L coil currents, register-level
sensors and PWM boards, so that firmware_io's runner can be closed around it end to end.

What is simulated, and from what:

* the finger: a scripted trajectory (``slide`` over the object as in thesis Fig. 4.5, ``poke``
  down into it, or a CSV file with columns ``t_s, x_m, y_m, z_m``);
* the true force on the magnet: designkit's array model evaluated directly at the true position
  (``CoilArray.force`` + the magnet's pull on the cores when the model has it), never the map, so
  that the map's and the allocator's errors show up in the result;
* the coil currents: each coil an R-L circuit driven by the voltage its MD10C applies, read back
  from the simulated PCA9685 registers (duty of the PWM channel, level of the DIR channel), so the
  bytes the runner wrote are what moves the current;
* the sensors: field values from :func:`sensor_field` written into register-level TLV493D
  models behind TCA9548A muxes on their own simulated bus; the bus's wire-time model sets when a
  frame is complete, so the runner sees the real sensor latency;
* faults on a schedule (:class:`FaultSchedule`), injected on the simulated devices.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import electrical
from .errors import BadInputError
from .localize import analog_reading

FAULT_TYPES = ("pwm_nack", "sensor_stuck", "sensor_dead", "sensor_saturated", "out_of_box",
               "overrun", "over_limit", "thermal")
"""Fault types the plant can inject (``--faults default`` injects each once, in this order;
thermal last because a coil over its I^2 t budget stays off until it has cooled, minutes)."""

TRAJECTORY_COLUMNS = ("t_s", "x_m", "y_m", "z_m")


# ---------------------------------------------------------------------------------------------
# trajectories


@dataclass(frozen=True)
class Trajectory:
    """Finger (magnet centre) positions over time.

    Attributes
    ----------
    t_s : ndarray, shape (k,), s, strictly increasing
    position_m : ndarray, shape (k, 3), m
    """

    t_s: np.ndarray
    position_m: np.ndarray

    def __post_init__(self):
        t = np.asarray(self.t_s, float)
        p = np.asarray(self.position_m, float)
        if t.ndim != 1 or len(t) < 2 or p.shape != (len(t), 3):
            raise BadInputError("trajectory", "k >= 2 times and a (k, 3) array of positions",
                                f"{t.shape} and {p.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
            raise BadInputError("trajectory", "finite times and positions", "NaN or Inf")
        if np.any(np.diff(t) <= 0):
            raise BadInputError("trajectory t_s", "strictly increasing", t[:5].tolist())
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "position_m", p)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])

    def at(self, t_s: float) -> np.ndarray:
        """Position at time t (linear interpolation, held constant outside), m, shape (3,)."""
        return np.array([np.interp(t_s, self.t_s, self.position_m[:, k]) for k in range(3)])

    @classmethod
    def from_csv(cls, path) -> "Trajectory":
        """Read ``t_s, x_m, y_m, z_m`` columns (SI, a header line naming them)."""
        p = Path(path)
        if not p.is_file():
            raise BadInputError("trajectory", "a CSV file with columns t_s,x_m,y_m,z_m", str(p))
        with p.open(newline="") as fh:
            reader = csv.reader(fh)
            try:
                header = [h.strip() for h in next(reader)]
            except StopIteration:
                raise BadInputError("trajectory", "a header line t_s,x_m,y_m,z_m", "an empty file") \
                    from None
            missing = [c for c in TRAJECTORY_COLUMNS if c not in header]
            if missing:
                raise BadInputError("trajectory columns", "t_s, x_m, y_m, z_m (SI units)",
                                    header, hint=f"missing {missing} in {p}")
            idx = [header.index(c) for c in TRAJECTORY_COLUMNS]
            rows = []
            for line_no, row in enumerate(reader, start=2):
                if not row:
                    continue
                try:
                    rows.append([float(row[i]) for i in idx])
                except (ValueError, IndexError):
                    raise BadInputError(f"trajectory line {line_no}", "four numbers", row) from None
        a = np.asarray(rows, float).reshape(-1, 4)
        return cls(a[:, 0], a[:, 1:])


def slide_trajectory(surface_height, *, duration_s: float = 4.0, half_span_m: float = 0.04,
                     depth_m: float = 0.004, y_m: float = 0.0, z_limits_m=(0.012, 0.078),
                     samples: int = 2001) -> Trajectory:
    """Slide across an object at ``depth_m`` below its surface, there and back (thesis Fig. 4.5).

    Parameters
    ----------
    surface_height : callable
        ``surface_height(x_m, y_m) -> z_m`` of the object's top (arrays); NaN where there is no
        object (the finger then stays at the lowest allowed height).
    duration_s, half_span_m, depth_m, y_m : float
        One sweep x: -half_span -> +half_span -> -half_span (cosine speed profile).
    z_limits_m : (float, float)
        Heights the trajectory is kept within (inside the map box), m.
    """
    t = np.linspace(0.0, duration_s, samples)
    x = -half_span_m * np.cos(2 * np.pi * t / duration_s)
    y = np.full_like(t, y_m)
    h = np.asarray(surface_height(x, y), float)
    z = np.where(np.isfinite(h), h - depth_m, z_limits_m[0])
    z = np.clip(z, *z_limits_m)
    return Trajectory(t, np.stack([x, y, z], 1))


def poke_trajectory(surface_height, *, duration_s: float = 3.0, x_m: float = 0.0,
                    y_m: float = 0.0, above_m: float = 0.015, depth_m: float = 0.010,
                    z_limits_m=(0.012, 0.078), samples: int = 1501) -> Trajectory:
    """Poke down into the object and back out, twice (raised-cosine depth profile)."""
    t = np.linspace(0.0, duration_s, samples)
    h = float(np.asarray(surface_height(np.array([x_m]), np.array([y_m])), float)[0])
    if not math.isfinite(h):
        h = z_limits_m[0] + above_m
    phase = 0.5 - 0.5 * np.cos(4 * np.pi * t / duration_s)   # 0 -> 1 -> 0, twice
    z = np.clip(h + above_m - phase * (above_m + depth_m), *z_limits_m)
    return Trajectory(t, np.stack([np.full_like(t, x_m), np.full_like(t, y_m), z], 1))


# ---------------------------------------------------------------------------------------------
# fault schedule


@dataclass(frozen=True)
class FaultSchedule:
    """Faults to inject: ``events`` is a tuple of (time s, fault type), sorted by time."""

    events: tuple = ()

    @classmethod
    def parse(cls, text: str | None, duration_s: float) -> "FaultSchedule":
        """``None``/'none' -> no faults; 'default' -> each type once, spread evenly over the run
        (leaving the first and last 10 %); else 'TYPE@SECONDS,TYPE@SECONDS,...'."""
        if text is None or text.strip().lower() in ("", "none"):
            return cls(())
        if text.strip().lower() == "default":
            times = np.linspace(0.1, 0.9, len(FAULT_TYPES) + 2)[1:-1] * duration_s
            return cls(tuple((float(t), f) for t, f in zip(times, FAULT_TYPES)))
        events = []
        for item in text.split(","):
            name, _, when = item.strip().partition("@")
            if name not in FAULT_TYPES:
                raise BadInputError("faults", f"'default', 'none' or TYPE@SECONDS with TYPE in "
                                    f"{', '.join(FAULT_TYPES)}", item)
            try:
                t = float(when)
            except ValueError:
                raise BadInputError("faults", "TYPE@SECONDS (a time in s after @)", item) from None
            if not 0 <= t <= duration_s:
                raise BadInputError("faults", f"times within the run, [0, {duration_s}] s", item)
            events.append((t, name))
        return cls(tuple(sorted(events)))


# ---------------------------------------------------------------------------------------------
# physics at the sensors


def magnet_moment(design) -> np.ndarray:
    """The design's magnet moment vector, A m^2 (the polarity convention lives in the design)."""
    return np.asarray(design.magnet.moment_vector_a_m2, float)


# ---------------------------------------------------------------------------------------------
# the simulated device on its two simulated I2C buses


class SimulatedDevice:
    """Register-level PWM boards and sensors on two simulated buses, driven by exact physics.

    Parameters
    ----------
    design : Design
    array : CoilArray
        The physics (default ``CoilArray.from_design(design)``).
    noise_t : float
        Sensor noise, T rms per axis (TLV493D datasheet: 0.1 mT), added before quantization.
    sensor_errors : {'default', 'ideal'} or designkit.localize.SensorErrors
        Offsets, gains and mounting errors of the sensors (designkit.localize's stated defaults:
        0.5 mm, 1 degree, 1 % gain, 0.01 mT offset after calibration).
    seed : int
    resistance_ohm, inductance_h : float, optional
        The coils' true R and L (default: from the design's coil model).

    The coil bus runs at 1 MHz (the PCA9685s on their own adapter: Fm+, per the PCA9685 datasheet), the
    sensor bus at 400 kHz (the TCA9548A's limit); each has its own simulated clock.
    """

    def __init__(self, design, array=None, *, noise_t: float = 1e-4, seed: int = 0,
                 sensor_errors="default", resistance_ohm: float | None = None,
                 inductance_h: float | None = None):
        from firmware_io.coils import CoilDriver
        from firmware_io.devices import PCA9685
        from firmware_io.md10c import MD10C_CONTINUOUS_A, CoilDrive
        from firmware_io.sensors import SensorArrays
        from firmware_io.sim import SimBus, SimClock, SimPCA9685, SimTCA9548A, SimTLV493D

        from .array import CoilArray
        from .coil import Coil
        from .localize import SensorSimulator

        self.design = design
        self.array = array if array is not None else CoilArray.from_design(design)
        n = self.array.n_coils
        coil = Coil.from_design(design)
        self.resistance_ohm = float(resistance_ohm if resistance_ohm is not None
                                    else coil.resistance(design.wire))
        self.inductance_h = float(inductance_h if inductance_h is not None
                                  else coil.inductance(design.wire))
        self.supply_v = min(design.drive.supply_voltage_v, design.drive.driver_max_voltage_v)
        self.noise_t = float(noise_t)
        self.rng = np.random.default_rng(seed)
        self.moment = magnet_moment(design)
        # the localization issue's sensor physics: exact magnet field, coils + cores, the cores
        # the magnet magnetizes (coupled solve), offsets/gains/mounting errors and noise
        self.sensor_sim = SensorSimulator(design, array=self.array, errors=sensor_errors,
                                          noise_t=noise_t, moment_direction=self.moment,
                                          induced="coupled", seed=seed)
        self.sensor_positions_m = self.sensor_sim.nominal_m

        self.coil_clock = SimClock()
        self.coil_bus = SimBus(scl_hz=1e6, clock=self.coil_clock)
        n_boards = (n + 7) // 8
        self.sim_boards = [self.coil_bus.attach(SimPCA9685(0x40 + b)) for b in range(n_boards)]
        boards = [PCA9685(self.coil_bus, 0x40 + b, sleep=self.coil_clock.sleep)
                  for b in range(n_boards)]
        # the runner commands a voltage as V/R; the drive may pass up to the supply's Vs/R
        drive = CoilDrive(self.supply_v, self.resistance_ohm,
                          min(self.supply_v / self.resistance_ohm, MD10C_CONTINUOUS_A))
        self.coils = CoilDriver(boards, [drive] * n, sleep=self.coil_clock.sleep)

        self.sensor_clock = SimClock()
        self.sensor_bus = SimBus(scl_hz=400e3, clock=self.sensor_clock)
        n_sensors = 2 * n
        muxes = [self.sensor_bus.attach(SimTCA9548A(0x71 + k)) for k in range((n_sensors + 7) // 8)]
        self.tlv = [muxes[i // 8].attach(i % 8, SimTLV493D()) for i in range(n_sensors)]
        self.sensors = SensorArrays(self.sensor_bus, sleep=self.sensor_clock.sleep)
        self.sensors.configure()

        self.current_a = np.zeros(n)
        self.field_offset_t = np.zeros((n_sensors, 3))   # fault injection (saturation)
        self._in_flight: tuple[float, float, object] | None = None
        self._last_set_s = 0.0

    # -- coils ----------------------------------------------------------------------------------
    def applied_voltage_v(self) -> np.ndarray:
        """Voltage each MD10C applies now, from the PCA9685 registers (PWM duty, DIR level)."""
        v = np.zeros(self.array.n_coils)
        for k, w in enumerate(self.coils.wiring):
            board = self.sim_boards[w.board]
            duty = board.duty(w.pwm_channel)
            dir_high = board.level(w.dir_channel) == "high"
            forward = dir_high == (w.forward_dir_level == "high")
            v[k] = (1.0 if forward else -1.0) * duty * self.supply_v
        return v

    def advance_currents(self, period_s: float) -> np.ndarray:
        """Integrate the R-L coils over one period at the applied voltage; return I, A."""
        from firmware_io.runner import rl_step

        v = self.applied_voltage_v()
        self.current_a = rl_step(self.current_a, v, self.resistance_ohm, self.inductance_h,
                                 period_s)
        return self.current_a

    # -- physics ---------------------------------------------------------------------------------
    def prepare(self, positions_m, *, sample_step_m: float = 2.5e-4, max_stride: int = 10,
                induced_step_m: float = 2e-3) -> None:
        """Evaluate the array model once, in one batch, along every step's true position.

        The finger's path is scripted, so the model is never called inside the loop: it is
        evaluated where the path has moved ``sample_step_m`` since the last sample (at least every
        ``max_stride`` steps, and on both sides of a jump) and interpolated linearly in between;
        per step only (3, n) @ (n,) products remain. For a path that moves 0.25 mm between samples
        the interpolation error of A is ~(0.25 mm / 30 mm)^2 ~ 1e-4 relative at the design point
        (the field varies on the coil-size scale). Sets the per-step force matrices (k, 3, n) N/A,
        bias forces (k, 3) N, and the coils' field at the sensors per ampere.
        """
        from .array import force_matrix

        p = np.asarray(positions_m, float).reshape(-1, 3)
        idx = [0]
        for k in range(1, len(p)):
            jump = np.linalg.norm(p[k] - p[k - 1]) > 1e-3
            if jump and idx[-1] != k - 1:
                idx.append(k - 1)
            if (jump or k - idx[-1] >= max_stride
                    or np.linalg.norm(p[k] - p[idx[-1]]) >= sample_step_m):
                idx.append(k)
        if idx[-1] != len(p) - 1:
            idx.append(len(p) - 1)
        idx = np.asarray(idx)
        a = self.array.actuation_matrix(p[idx])
        f_s = np.einsum("ij,kjl->kil", force_matrix(self.moment), a[:, 3:, :])
        bias = getattr(self.array, "bias_force", None)
        b_s = (np.asarray(bias(p[idx], self.moment), float).reshape(-1, 3) if bias is not None
               else np.zeros((len(idx), 3)))
        steps = np.arange(len(p))
        self.force_per_amp = _interp_rows(steps, idx, f_s)
        self.bias_n = _interp_rows(steps, idx, b_s)
        # the magnet-induced core field at the sensors is a small, smooth term (a few mT):
        # sampled every induced_step_m of travel
        coarse = [0]
        for k in idx[1:]:
            if (np.linalg.norm(p[k] - p[coarse[-1]]) >= induced_step_m
                    or np.linalg.norm(p[k] - p[k - 1]) > 1e-3):
                if coarse[-1] != k - 1 and np.linalg.norm(p[k] - p[k - 1]) > 1e-3:
                    coarse.append(k - 1)
                coarse.append(int(k))
        if coarse[-1] != len(p) - 1:
            coarse.append(len(p) - 1)
        coarse = np.asarray(sorted(set(coarse)))
        self.induced_t = _interp_rows(steps, coarse, self.sensor_sim.induced_part(p[coarse]))
        self.path_m = p

    def true_force_n(self, step: int, current_a) -> np.ndarray:
        """Force on the magnet at step ``step``'s true position, N, shape (3,)."""
        return self.force_per_amp[step] @ current_a + self.bias_n[step]

    def sensor_readings_t(self, step: int, position_m, current_a) -> np.ndarray:
        """(2 n_coils, 3) T, what each sensor's ADC converts at step ``step`` (magnet at
        ``position_m``): the field (magnet, coils, induced cores) through the sensor errors,
        plus noise and injected offsets; the TLV493D models quantize and clip it."""
        sim = self.sensor_sim
        b = (sim.magnet_part(np.asarray(position_m, float)[None])[0]
             + sim.coil_part(np.asarray(current_a, float)[None])[0] + self.induced_t[step])
        a = analog_reading(b[None], sim.errors, self.noise_t, self.rng)[0].reshape(-1, 3)
        return a + self.field_offset_t

    def calibrate_sensors(self, model, *, frames: int = 40, current_a: float | None = None):
        """The start-up sensor calibration through the firmware's path
        (:func:`firmware_io.runner.record_calibration`: duties written to the simulated
        PCA9685s, frames read from the register-level TLV493Ds) with the magnet away from the
        board; while the firmware waits, the coils settle (R-L model at the applied voltage)
        and the sensors see the coils' field through their errors, with noise.

        Parameters
        ----------
        model : firmware_io.localization.SensorModel -- what the localizer knows
        frames : int; current_a : float, A (default :data:`firmware_io.runner.
            CALIBRATION_CURRENT_A`, at most the drive's limit)

        Returns the Localizer's ``calibration`` (gain_inverse (2, n, 3, 3), offsets (2, n, 3)).
        """
        from firmware_io.runner import (CALIBRATION_CURRENT_A, calibrate_sensors,
                                        calibration_currents, record_calibration, rl_step)

        sim = self.sensor_sim

        def settle(dt_s: float) -> None:
            self.current_a = rl_step(self.current_a, self.applied_voltage_v(),
                                     self.resistance_ohm, self.inductance_h, dt_s)
            b = sim.coil_part(self.current_a[None])[0]
            a = analog_reading(b[None], sim.errors, self.noise_t, self.rng)[0].reshape(-1, 3)
            for sensor, bi in zip(self.tlv, a + self.field_offset_t):
                sensor.field_t = tuple(bi)

        amp = min(CALIBRATION_CURRENT_A if current_a is None else current_a,
                  self.supply_v / self.resistance_ohm)
        currents = calibration_currents(self.array.n_coils, amp, frames)
        tau = self.inductance_h / self.resistance_ohm
        top, bottom, applied = record_calibration(self.coils, self.sensors, currents,
                                                  settle_s=7 * tau, sleep=settle)
        settle(7 * tau)          # coils off: decayed before the run starts
        self.current_a[:] = 0.0
        return calibrate_sensors(model, top, bottom, applied)

    def sensor_source(self, position_at, period_s: float) -> "SimSensorSource":
        """The runner's sensor source on this device; ``position_at(t_s)`` is the true position
        (the path given to :meth:`prepare`, one sample per control period ``period_s``)."""
        return SimSensorSource(self, position_at, period_s)


def _interp_rows(steps, idx, values):
    """Linear interpolation of ``values`` (len(idx), ...) sampled at ``idx`` onto ``steps``."""
    flat = values.reshape(len(idx), -1)
    out = np.empty((len(steps), flat.shape[1]))
    for j in range(flat.shape[1]):
        out[:, j] = np.interp(steps, idx, flat[:, j])
    return out.reshape((len(steps),) + values.shape[1:])


class SimSensorSource:
    """The sensor side of :class:`firmware_io.runner.Runner` on the simulated sensor bus, with
    the timing of the sensor thread (:class:`firmware_io.run.ThreadedSensorSource`).

    :meth:`tick` does the simulation work (fields into the TLV493D models, one pass of
    :meth:`firmware_io.sensors.SensorArrays.read` on the sensor bus, the runner's
    :class:`firmware_io.runner.SensorPipeline` on the frame); the plant calls it before each
    runner step, outside the runner's timed section, as the sensor thread runs beside the
    control loop on hardware. The thread's cycle is: read a pass (its wire time on the bus
    model), then fit (its measured compute time, this thread's CPU clock), publish the
    :class:`firmware_io.runner.Fix`, read the next pass. The runner takes a result at the first
    control step at or after the time it is published. In master-controlled mode a TLV493D
    returns the conversion triggered by the previous read, so each frame carries the field of
    the previous pass's start time. Without an attached pipeline raw frames are handed over.

    Attributes
    ----------
    fit_s : list of float
        Compute time of each fit on the sensor side, s.
    frame_truth_m : ndarray (3,) or None
        The true position at the field time of the last frame read (diagnostics).
    """

    def __init__(self, device: SimulatedDevice, position_at, period_s: float):
        self.device, self.position_at, self.period_s = device, position_at, period_s
        self.in_flight = None      # (ready time s, field time s, reading)
        self.fitted = None         # (publish time s, result, field time s)
        self.ready = None          # a result the runner has not taken yet
        self.last_set_s = 0.0
        self.frame_truth_m = None
        self.pipeline = None
        self.fit_s: list = []

    def attach(self, pipeline) -> None:
        self.pipeline = pipeline

    def tick(self, t_s: float) -> None:
        import time as _time

        from firmware_io.runner import SensorFrame

        dev = self.device
        if self.in_flight is not None:
            ready_s, field_s, reading = self.in_flight
            if t_s + 1e-12 < ready_s:
                return
            self.in_flight = None
            frame = SensorFrame(reading.top_t, reading.bottom_t, reading.status, field_s)
            self.frame_truth_m = self.position_at(field_s)   # diagnostics: where it really was
            fit_s = 0.0
            if self.pipeline is not None:
                c0 = _time.thread_time()
                frame = self.pipeline.process(frame)
                fit_s = _time.thread_time() - c0
                self.fit_s.append(fit_s)
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

    def __call__(self, t_s: float):
        frame, self.ready = self.ready, None
        return frame


# ---------------------------------------------------------------------------------------------
# the closed loop


@dataclass
class SimulationResult:
    """Per-step columns (SI; the run.csv columns, plus ``new_frame`` (bool: the step took in a
    new sensor result) and, when the runner profiles, ``stage_<name>_s``), the faults as
    injected (time s, type; overrun and over-limit wait for a running step), the runner's fault
    log and the sensor side's fit times (s, one per frame)."""

    columns: dict
    faults: list
    fault_log: list
    period_s: float
    fit_s: list = field(default_factory=list)


def _inject(device, runner, name: str, t_s: float, state: dict) -> None:
    """Put fault ``name`` on the simulated device (or the runner's environment) at ``t_s``."""
    n = device.array.n_coils
    if name == "pwm_nack":
        device.sim_boards[0].inject_nack(count=1)
    elif name == "sensor_stuck":
        device.tlv[n // 2].stuck_frame = True          # the top sensor above the centre coil
    elif name == "sensor_dead":
        device.tlv[n + 1].nack_always = True           # a bottom sensor stops answering
        state["dead_until"] = t_s + 0.3
    elif name == "sensor_saturated":
        device.field_offset_t[0] = (0.0, 0.0, 0.3)     # past the 12-bit code range (+-200 mT)
        state["saturated_until"] = t_s + 0.2
    elif name == "out_of_box":
        pass  # the trajectory itself leaves the box (see simulate)
    elif name == "overrun":
        state["overrun_step"] = True
    elif name == "thermal":
        # what a long overload leaves behind: one coil's I^2 t just over its budget
        runner.thermal.energy_a2s[n // 2] = 1.01 * runner.thermal.budget_a2s
    elif name == "over_limit":
        state["over_limit_step"] = True


def simulate(device: SimulatedDevice, runner_factory, trajectory: Trajectory, *,
             duration_s: float, period_s: float, faults: FaultSchedule = FaultSchedule(),
             scene_force=None, progress: bool = True) -> SimulationResult:
    """Close the loop: ``runner_factory(sensor_source, clock, allocate_hook)`` -> a started Runner.

    Parameters
    ----------
    device : SimulatedDevice
    runner_factory : callable
        Builds the :class:`firmware_io.runner.Runner` around the given sensor source, compute
        clock and allocation wrapper (the plant wraps both to inject overrun and over-limit
        faults), on ``device.coils``.
    trajectory : Trajectory
    duration_s, period_s : float, s
    faults : FaultSchedule
    scene_force : callable, optional
        ``scene_force(p, v) -> (3,)``: the object's force at the TRUE position (the reference the
        rendered force is judged against).
    """
    import time as _time

    from ._progress import tqdm

    n_steps = int(round(duration_s / period_s))
    t = np.arange(n_steps) * period_s
    state: dict = {}
    events = list(faults.events)
    pending: list = []
    injected: list = []

    out_windows = [(te, te + 0.3) for te, f in events if f == "out_of_box"]

    def position_at(ts: float) -> np.ndarray:
        p = trajectory.at(ts)
        if any(a <= ts < b for a, b in out_windows):
            p = p + np.array([0.0, 0.0, 0.06])   # lifted 60 mm: above the map box
        return p

    true_p = np.array([position_at(ts) for ts in t])
    vel = np.gradient(true_p, period_s, axis=0)
    device.prepare(true_p)
    source = device.sensor_source(position_at, period_s)
    extra: dict = {}

    def allocate_hook(allocate):
        def wrapped(*args, **kw):
            i, r = allocate(*args, **kw)
            if state.pop("over_limit_step", False):     # a defect upstream: 1.5x the limit
                i = 1.5 * np.asarray(args[2], float) * np.where(i < 0, -1.0, 1.0)
            return i, r
        return wrapped

    # compute time = this thread's CPU time (the plant shares the host with the runner; other
    # processes would otherwise show up as overruns) less the time spent inside the simulated
    # PWM boards (the plant's, not the runner's)
    def clock() -> float:
        return _time.thread_time() - device.coil_bus.model_time_s

    runner = runner_factory(source, clock, allocate_hook)
    n = device.array.n_coils
    cols = {k: np.zeros(n_steps) for k in (
        "t_s", "x_m", "y_m", "z_m", "xe_m", "ye_m", "ze_m", "fx_ref_n", "fy_ref_n", "fz_ref_n",
        "fx_n", "fy_n", "fz_n", "fx_obj_n", "fy_obj_n", "fz_obj_n", "loop_s")}
    cur = np.zeros((n_steps, n))
    cmd = np.zeros((n_steps, n))
    new_frame = np.zeros(n_steps, dtype=bool)
    stages: dict = {}
    states = []
    bar = tqdm(total=n_steps, desc="simulate", unit="step", disable=not progress,
               mininterval=0.5)
    for s in range(n_steps):
        ts = t[s]
        while events and events[0][0] <= ts + 1e-12:
            _, name = events.pop(0)
            if name in ("overrun", "over_limit"):
                pending.append(name)     # a defect of a running loop: wait for one
            else:
                _inject(device, runner, name, ts, state)
                injected.append((float(ts), name))
        if pending and runner.state == "running":
            name = pending.pop(0)
            _inject(device, runner, name, ts, state)
            injected.append((float(ts), name))
        if ts >= state.get("saturated_until", np.inf):
            device.field_offset_t[0] = 0.0
            state.pop("saturated_until")
        if ts >= state.get("dead_until", np.inf):
            device.tlv[n + 1].nack_always = False
            state.pop("dead_until")
        if state.pop("overrun_step", False):
            extra["delay_pending"] = True
        source.tick(ts)
        rec = _step(runner, ts, extra)
        i_true = device.current_a.copy()
        f_true = device.true_force_n(s, i_true)
        cols["t_s"][s] = ts
        cols["x_m"][s], cols["y_m"][s], cols["z_m"][s] = true_p[s]
        cols["xe_m"][s], cols["ye_m"][s], cols["ze_m"][s] = rec.position_m
        cols["fx_ref_n"][s], cols["fy_ref_n"][s], cols["fz_ref_n"][s] = rec.force_ref_n
        cols["fx_n"][s], cols["fy_n"][s], cols["fz_n"][s] = f_true
        if scene_force is not None:
            cols["fx_obj_n"][s], cols["fy_obj_n"][s], cols["fz_obj_n"][s] = \
                scene_force(true_p[s], vel[s])
        cols["loop_s"][s] = rec.loop_s
        new_frame[s] = rec.new_frame
        if runner.profile and rec.state == "running":
            for name, v in runner.stages.items():
                stages.setdefault(name, np.full(n_steps, np.nan))[s] = v
        cur[s] = i_true
        cmd[s] = rec.command_a
        states.append(rec.state)
        device.advance_currents(period_s)
        device.coil_bus.clear_log()
        bar.update()
    bar.close()
    runner.stop()
    for k in range(n):
        cols[f"i{k + 1}_a"] = cur[:, k]
    for k in range(n):
        cols[f"cmd{k + 1}_a"] = cmd[:, k]
    cols["state"] = np.array(states)
    cols["new_frame"] = new_frame
    for name, v in stages.items():
        cols[f"stage_{name}_s"] = v
    return SimulationResult(cols, injected, list(runner.fault_log), period_s,
                            list(getattr(source, "fit_s", [])))


def _step(runner, ts: float, extra: dict):
    """One runner step; an injected overrun makes the compute clock jump inside the step."""
    if extra.pop("delay_pending", False):
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


# ---------------------------------------------------------------------------------------------
# what a run says


def time_to_safe(columns: dict, events, period_s: float) -> list[dict]:
    """For each scheduled fault: the first step at or after it that is not 'running', s."""
    t = columns["t_s"]
    st = columns["state"]
    out = []
    for te, name in events:
        after = np.nonzero(t >= te - 1e-12)[0]
        first = next((i for i in after if st[i] != "running"), None)
        out.append({"fault": name, "injected_s": float(te),
                    "state": None if first is None else str(st[first]),
                    "time_to_safe_s": None if first is None else float(t[first] - te),
                    "periods": None if first is None else float((t[first] - te) / period_s)})
    return out


def force_lag_s(reference, rendered, period_s: float, max_lag_s: float = 0.2) -> float:
    """Delay of ``rendered`` behind ``reference`` (s) maximizing their cross-correlation."""
    a = np.asarray(reference, float) - np.mean(reference)
    b = np.asarray(rendered, float) - np.mean(rendered)
    if not (np.any(a) and np.any(b)):
        return 0.0
    kmax = min(int(max_lag_s / period_s), len(a) - 1)
    scores = [np.dot(a[: len(a) - k], b[k:]) for k in range(kmax + 1)]
    return float(np.argmax(scores) * period_s)


def _p50_p99(x) -> dict:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if not len(x):
        return {"n": 0, "p50_s": None, "p99_s": None}
    return {"n": int(len(x)), "p50_s": float(np.percentile(x, 50)),
            "p99_s": float(np.percentile(x, 99))}


def loop_by_kind(result: SimulationResult) -> dict:
    """Compute time of the running steps without and with a new sensor result (p50, p99, s),
    per stage when the runner profiled, and of the fit on the sensor side."""
    c = result.columns
    running = c["state"] == "running"
    fresh = np.asarray(c.get("new_frame", np.zeros(len(running), bool)), bool)
    out = {"without_frame": _p50_p99(c["loop_s"][running & ~fresh]),
           "with_frame": _p50_p99(c["loop_s"][running & fresh]),
           "sensor_side_fit": _p50_p99(result.fit_s)}
    stages = [k for k in c if k.startswith("stage_")]
    if stages:
        out["stages"] = {k[6:-2]: {"without_frame": _p50_p99(c[k][running & ~fresh]),
                                   "with_frame": _p50_p99(c[k][running & fresh])}
                         for k in stages}
    return out


def summarize(result: SimulationResult, causes: dict | None = None) -> dict:
    """summary.json: force error RMS/p95, localization MAE, loop p50/p99, faults, time to safe."""
    c = result.columns
    running = c["state"] == "running"
    f_true = np.stack([c["fx_n"], c["fy_n"], c["fz_n"]], 1)
    f_obj = np.stack([c["fx_obj_n"], c["fy_obj_n"], c["fz_obj_n"]], 1)
    err = np.linalg.norm(f_true - f_obj, axis=1)[running]
    p_true = np.stack([c["x_m"], c["y_m"], c["z_m"]], 1)
    p_est = np.stack([c["xe_m"], c["ye_m"], c["ze_m"]], 1)
    fix = np.all(np.isfinite(p_est), axis=1)
    loc = np.linalg.norm(p_est - p_true, axis=1)[fix]
    loop = c["loop_s"][running]
    currents = np.stack([v for k, v in c.items() if k.startswith("cmd")], 1)

    def stats(x):
        return (float(np.sqrt(np.mean(x ** 2))) if len(x) else None,
                float(np.percentile(x, 95)) if len(x) else None)

    rms, p95 = stats(err)
    out = {
        "steps": int(len(c["t_s"])), "period_s": result.period_s,
        "running_fraction": float(np.mean(running)),
        "force_error_rms_n": rms, "force_error_p95_n": p95,
        "object_force_rms_n": stats(np.linalg.norm(f_obj, axis=1)[running])[0],
        "force_lag_s": force_lag_s(c["fz_obj_n"], c["fz_n"], result.period_s),
        "localization_mae_m": float(np.mean(loc)) if len(loc) else None,
        "localization_p95_m": float(np.percentile(loc, 95)) if len(loc) else None,
        "loop_p50_s": float(np.percentile(loop, 50)) if len(loop) else None,
        "loop_p99_s": float(np.percentile(loop, 99)) if len(loop) else None,
        "loop_by_kind": loop_by_kind(result),
        "max_command_a": float(np.abs(currents).max()),
        "max_total_command_a": float(np.abs(currents).sum(axis=1).max()),
        "faults": time_to_safe(c, result.faults, result.period_s),
        "fault_log": [{"t_s": float(t), "state": s, "detail": d} for t, s, d in result.fault_log],
    }
    if causes is not None:
        out["force_error_causes"] = causes
    return out


def write_run_csv(path, columns: dict) -> None:
    """run.csv: one row per control step, SI columns (see :func:`simulate`)."""
    from ._io import atomic_path

    order = ["t_s", "x_m", "y_m", "z_m", "xe_m", "ye_m", "ze_m", "fx_ref_n", "fy_ref_n",
             "fz_ref_n", "fx_n", "fy_n", "fz_n"]
    order += [k for k in columns if k.startswith("i") and k.endswith("_a")]
    order += [k for k in columns if k.startswith("cmd")]
    order += ["loop_s", "state"]
    with atomic_path(path) as tmp, tmp.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(order)
        cols = [columns[k] for k in order]
        for row in zip(*cols):
            w.writerow([v if isinstance(v, str) else f"{float(v):.9g}" for v in row])


def plot_run(result: SimulationResult, out_dir, *, surface_height=None, title: str = "") -> list:
    """Fig. 4.5-like figure (path vs object, desired vs rendered force, currents) and a
    loop-timing histogram; returns the PNG paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    c = result.columns
    t = c["t_s"]
    running = c["state"] == "running"
    fig, ax = plt.subplots(3, 1, figsize=(8.5, 9.5), constrained_layout=True)
    ax[0].plot(c["x_m"] * 1e3, c["z_m"] * 1e3, color="tab:blue", lw=1.5, label="finger (true)")
    est = np.isfinite(c["xe_m"])
    ax[0].plot(c["xe_m"][est] * 1e3, c["ze_m"][est] * 1e3, ".", ms=1.5, color="tab:orange",
               label="finger (estimated)")
    if surface_height is not None:
        xs = np.linspace(-60e-3, 60e-3, 400)
        h = np.asarray(surface_height(xs, np.zeros_like(xs)), float)
        ax[0].fill_between(xs * 1e3, 0, np.where(np.isfinite(h), h, 0) * 1e3, color="0.85",
                           label="object")
    ax[0].set_xlabel("x (mm)")
    ax[0].set_ylabel("z above the coil tops (mm)")
    ax[0].legend(loc="upper right", fontsize=8)
    ax[0].set_title(title or "finger path against the object")
    ax[1].plot(t, c["fz_obj_n"] * 1e3, color="k", lw=1.2, label="object force at the true position")
    ax[1].plot(t, c["fz_n"] * 1e3, color="tab:red", lw=1.0, label="rendered (true force on magnet)")
    ax[1].plot(t, c["fz_ref_n"] * 1e3, color="tab:green", lw=0.8, ls="--",
               label="object force at the estimate")
    _shade_faults(ax[1], t, running)
    ax[1].set_xlabel("time (s)")
    ax[1].set_ylabel("Fz (mN)")
    ax[1].legend(loc="upper right", fontsize=8)
    for k in range(sum(1 for key in c if key.startswith("cmd"))):
        ax[2].plot(t, c[f"i{k + 1}_a"], lw=1.0, label=f"coil {k + 1}")
    _shade_faults(ax[2], t, running)
    ax[2].set_xlabel("time (s)")
    ax[2].set_ylabel("coil current (A)")
    ax[2].legend(loc="upper right", fontsize=7, ncol=3)
    p1 = out_dir / "run.png"
    fig.savefig(p1, dpi=130)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6.5, 4), constrained_layout=True)
    loop_us = c["loop_s"][running] * 1e6
    if len(loop_us):
        ax.hist(loop_us, bins=60, color="tab:blue")
        for q, ls in ((50, "--"), (99, ":")):
            v = np.percentile(loop_us, q)
            ax.axvline(v, color="k", ls=ls, label=f"p{q} = {v:.0f} us")
        ax.axvline(result.period_s * 1e6, color="tab:red", label="control period")
        ax.legend()
    else:
        ax.text(0.5, 0.5, "no running step", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("compute time per control step (us)")
    ax.set_ylabel("steps")
    ax.set_title("runner loop timing (running steps)")
    p2 = out_dir / "loop_timing.png"
    fig.savefig(p2, dpi=130)
    plt.close(fig)
    return [p1, p2]


def _shade_faults(ax, t, running) -> None:
    off = ~running
    if not off.any():
        return
    edges = np.flatnonzero(np.diff(np.r_[0, off.astype(int), 0]))
    for a, b in zip(edges[::2], edges[1::2]):
        ax.axvspan(t[a], t[min(b, len(t) - 1)], color="tab:red", alpha=0.08, lw=0)


def force_error_causes(device: SimulatedDevice, fieldmap, result: SimulationResult, *,
                       max_steps: int = 500) -> dict:
    """Split the rendered-force error into its causes, over the running steps (at most
    ``max_steps`` of them, evenly spaced: the exact coupled model at each estimate is the
    costly part; RMS and p95 of an evenly spaced subsample of a 4000-step run).

    With p the true and q the estimated position, I* the command and I the true currents,
    F(.) / F0(.) the exact force per ampere and bias force and Fm / F0m the map's::

        F(p) I + F0(p) - f(p) =   [f(q) - f(p)] + [F(p) I* + F0(p) - F(q) I* - F0(q)]  localization
                                + [Fm(q) I* + F0m(q) - f(q)]                           allocation
                                + [F(q) I* + F0(q) - Fm(q) I* - F0m(q)]                map
                                + F(p) (I - I*)                                        current lag

    Returns RMS and p95 (N) of each term's Fz and of its magnitude, and of the total.
    """
    from .array import force_matrix

    c = result.columns
    run = np.flatnonzero(c["state"] == "running")
    if len(run) == 0:
        return {}
    n_running = len(run)
    if n_running > max_steps:
        run = run[np.unique(np.linspace(0, n_running - 1, max_steps).round().astype(int))]
    m = device.moment
    n = device.array.n_coils
    q = np.stack([c["xe_m"], c["ye_m"], c["ze_m"]], 1)[run]
    i_cmd = np.stack([c[f"cmd{k + 1}_a"] for k in range(n)], 1)[run]
    i_true = np.stack([c[f"i{k + 1}_a"] for k in range(n)], 1)[run]
    f_ref = np.stack([c["fx_ref_n"], c["fy_ref_n"], c["fz_ref_n"]], 1)[run]
    f_obj = np.stack([c["fx_obj_n"], c["fy_obj_n"], c["fz_obj_n"]], 1)[run]
    fm = force_matrix(m)
    f_exact_q = np.einsum("ij,kjl->kil", fm, device.array.actuation_matrix(q)[:, 3:, :])
    bias = getattr(device.array, "bias_force", None)
    f0_exact_q = (np.asarray(bias(q, m), float).reshape(-1, 3) if bias is not None
                  else np.zeros_like(q))
    inside = _inside(fieldmap, q)
    f_map_q = np.zeros_like(f_exact_q)
    f_map_q[inside] = np.einsum("ij,kjl->kil", fm, fieldmap.actuation(q[inside])[:, 3:, :])
    f0_map_q = np.zeros_like(q)
    if hasattr(fieldmap, "bias_force") and inside.any():
        f0_map_q[inside] = np.asarray(fieldmap.bias_force(q[inside]), float).reshape(-1, 3)
    f_p = device.force_per_amp[run]
    f0_p = device.bias_n[run]

    def mv(a, i):
        return np.einsum("kil,kl->ki", a, i)

    terms = {
        "localization": (f_ref - f_obj) + (mv(f_p, i_cmd) + f0_p - mv(f_exact_q, i_cmd)
                                           - f0_exact_q),
        "allocation": mv(f_map_q, i_cmd) + f0_map_q - f_ref,
        "map_interpolation": mv(f_exact_q, i_cmd) + f0_exact_q - mv(f_map_q, i_cmd) - f0_map_q,
        "current_lag": mv(f_p, i_true - i_cmd),
    }
    terms["total"] = mv(f_p, i_true) + f0_p - f_obj
    out = {}
    for name, v in terms.items():
        v = v[inside] if name != "total" else v
        mag = np.linalg.norm(v, axis=1)
        out[name] = {"fz_rms_n": float(np.sqrt(np.mean(v[:, 2] ** 2))),
                     "fz_p95_n": float(np.percentile(np.abs(v[:, 2]), 95)),
                     "norm_rms_n": float(np.sqrt(np.mean(mag ** 2))),
                     "norm_p95_n": float(np.percentile(mag, 95))}
    out["steps"] = int(n_running)
    out["steps_evaluated"] = int(len(run))
    return out


def _inside(fieldmap, q) -> np.ndarray:
    lo, hi = (np.asarray(b, float) for b in fieldmap.bounds)
    return np.all((q >= lo) & (q <= hi), axis=1)


# ---------------------------------------------------------------------------------------------
# the whole simulated run (designkit run --simulate)

def drive_data(design) -> dict:
    """:func:`designkit.electrical.drive_data` for the design's own (identical) coils."""
    from .coil import Coil

    return electrical.drive_data(design, [Coil.from_design(design)]
                                 * (design.array.rows * design.array.columns))


def run_simulation(*, design=None, obj: str = "hemisphere", trajectory: str = "slide",
                   duration_s: float | None = None, faults: str = "none", map_path=None,
                   method: str = "model", period_s: float = 1e-3, unipolar: bool = False,
                   lam_n_per_m: float | None = None, rows: str = "force", seed: int = 0,
                   out=Path("run-out"), progress: bool = True, array=None,
                   calibrate: bool = True, profile: bool = False,
                   skip_force_n: float = 0.0) -> dict:
    """Build (or load) the map, compile the scene, close the runner around the simulated device,
    and write run.csv, summary.json, run.png and loop_timing.png into ``out``. Returns the
    summary. Every input is checked before anything is computed.

    ``rows``: 'force' renders the object's 3-D force, 'fz' only its vertical component (the
    thesis' eq. 4.6; the runner then evaluates only the two rows of A(p) Fz needs). ``array``:
    the design's CoilArray when the caller has one (its coupled solve is reused).
    ``calibrate``: the start-up sensor calibration (:meth:`SimulatedDevice.calibrate_sensors`)
    before the run; the localizer then weighs the sensors with
    :data:`firmware_io.runner.CALIBRATED_RELATIVE_ERROR`. ``profile``: the runner times each stage of its step
    (summary ``loop_by_kind['stages']``). ``skip_force_n``: the runner's coil-skip force, N.
    """
    from firmware_io.allocation import Allocator
    from firmware_io.localization import Localizer
    from firmware_io.mapfile import MapFile
    from firmware_io.runner import (CALIBRATED_RELATIVE_ERROR, ConstantVelocityTracker, Runner,
                                    RunnerConfig, SceneForce)
    from firmware_io.scene import Scene

    from . import fieldmap
    from ._io import write_json_atomic
    from .array import CoilArray
    from .design import Design, load_design
    from .render.laws import ConstraintLaw
    from .render.scenefile import compile_scene, make_object

    design = design if isinstance(design, Design) else load_design(design)
    if rows not in ("force", "fz"):
        raise BadInputError("rows", "'force' (3-D) or 'fz' (the thesis' vertical force)", rows)
    if not 1e-4 <= period_s <= 0.05:
        raise BadInputError("period", "in [0.1, 50] ms", period_s * 1e3)
    virtual = make_object(obj)
    scripted = trajectory in ("slide", "poke")
    path = None if scripted else Trajectory.from_csv(trajectory)
    duration = float(duration_s or (path.duration_s if path is not None
                                     else 4.0 if trajectory == "slide" else 3.0))
    if not 0 < duration <= 600:
        raise BadInputError("duration", "in (0, 600] s", duration)
    schedule = FaultSchedule.parse(faults, duration)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    array = array if array is not None else CoilArray.from_design(design)
    if scripted:
        # the magnet cannot go below the upper sensor board: its centre stays half its length
        # and 1 mm (the board and the sensor package) above the highest sensor
        floor = (float(np.max(array.sensor_positions_m()[0, :, 2]))
                 + design.magnet.length_m / 2 + 1e-3)
        make = slide_trajectory if trajectory == "slide" else poke_trajectory
        path = make(lambda x, y: virtual.height(np.c_[x, y, np.zeros_like(x)]),
                    duration_s=duration, z_limits_m=(floor, 0.078))
    if map_path is None:
        map_path = out / "map.npz"
        data = fieldmap.build(design, array=array, progress=progress)
        fieldmap.write(map_path, data)
    fmap = MapFile.load(map_path, expected_design_sha256=design.spec_hash())
    lam = design.render.stiffness_n_per_m if lam_n_per_m is None else float(lam_n_per_m)
    scene_path = compile_scene(virtual, out / "scene.npz", lam_n_per_m=lam,
                               law=ConstraintLaw(lam), map_design_sha256=fmap.design_sha256,
                               extra_meta={"object": obj, "rows": rows})
    scene = Scene.load(scene_path, expected_design_sha256=fmap.design_sha256)
    drive = drive_data(design)
    device = SimulatedDevice(design, array, seed=seed, resistance_ohm=drive["resistance_ohm"][0],
                             inductance_h=drive["inductance_h"][0])

    # the map carries the magnet's cylinder (the localizer's exact magnet field); the sensors
    # are calibrated at start-up, coils only
    loc_kw = {}
    if calibrate and method != "learned":
        base = Localizer.from_map(map_path, method=method, **loc_kw)
        loc_kw.update(calibration=device.calibrate_sensors(base.model),
                      relative_error=CALIBRATED_RELATIVE_ERROR)

    def factory(source, clock, hook):
        cfg = RunnerConfig(**{k: tuple(v) if isinstance(v, list) else v
                              for k, v in drive.items()},
                           control_period_s=period_s, unipolar=unipolar,
                           force_axes="z" if rows == "fz" else "xyz",
                           skip_force_n=skip_force_n)
        localizer = Localizer.from_map(map_path, method=method, **loc_kw)
        runner = Runner(fmap, SceneForce(scene), localizer, ConstantVelocityTracker(),
                        hook(Allocator()), device.coils, source, cfg, clock=clock,
                        log=lambda line: print(line) if progress else None)
        runner.profile = profile
        runner.start()
        return runner

    res = simulate(device, factory, path, duration_s=duration, period_s=period_s,
                   faults=schedule, scene_force=SceneForce(scene).force, progress=progress)
    causes = force_error_causes(device, fmap, res)
    summary = summarize(res, causes)
    summary.update({"object": obj, "trajectory": str(trajectory), "design": design.name,
                    "rows": rows,
                    "lambda_n_per_m": lam, "method": method, "unipolar": unipolar,
                    "drive": drive})
    write_run_csv(out / "run.csv", res.columns)
    write_json_atomic(out / "summary.json", summary)
    plot_run(res, out, surface_height=lambda x, y: virtual.height(np.c_[x, y, np.zeros_like(x)]),
             title=f"{obj}: {trajectory}, lambda = {lam:g} N/m")
    return summary


