"""The simulated device: register-level PWM boards and Hall sensors on two simulated I2C buses,
driven by exact array physics and R-L coil currents.

The coil currents (A) follow the voltage each MD10C applies, read back from the simulated
PCA9685 registers (PWM duty, DIR level), so the bytes the runner wrote are what moves the
current. The true force on the magnet (N) comes from designkit's array model at the true
position (``CoilArray.force`` + the magnet's pull on the cores), never the map, so that the
map's and the allocator's errors show up in a run. The sensors see that field through their
errors and noise (designkit.sensor_sim.SensorSimulator).
"""

from __future__ import annotations

import numpy as np

from firmware_io.hw.coils import CoilDriver
from firmware_io.hw.pca9685 import PCA9685
from firmware_io.hw.md10c import CoilDrive
from firmware_io.runner import (CALIBRATION_CURRENT_A, calibrate_sensors, calibration_currents,
                                record_calibration, rl_step)
from firmware_io.hw.sensors import SensorArrays, default_sensor_layout
from firmware_io.hw.sim import SimBus, SimClock, SimPCA9685, SimTCA9548A, SimTLV493D

from ..array import CoilArray, force_matrix
from ..coil import Coil
from ..sensor_sim import SensorSimulator, analog_reading
from .sensors import SimSensorSource


class SimulatedDevice:
    """Register-level PWM boards and sensors on two simulated buses, driven by exact physics.

    Parameters
    ----------
    design : Design
    array : CoilArray
        The physics (default ``CoilArray.from_design(design)``).
    noise_t : float
        Sensor noise, T rms per axis (TLV493D datasheet: 0.1 mT), added before quantization.
    sensor_errors : {'default', 'ideal'} or designkit.sensor_sim.SensorErrors
        Offsets, gains and mounting errors of the sensors (designkit.sensor_sim's stated defaults:
        0.5 mm, 1 degree, 1 % gain, 0.01 mT offset after calibration).
    seed : int
    resistance_ohm, inductance_h : float, optional
        The coils' true R and L (default: from the design's coil model).

    The coil bus runs at 1 MHz (the PCA9685s on their own adapter: Fm+, per the PCA9685
    datasheet), the sensor bus at 400 kHz (the TCA9548A's limit); each has its own simulated
    clock.
    """

    def __init__(self, design, array=None, *, noise_t: float = 1e-4, seed: int = 0,
                 sensor_errors="default", resistance_ohm: float | None = None,
                 inductance_h: float | None = None):
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
        self.moment = np.asarray(design.magnet.moment_vector_a_m2, float)
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
        # the runner commands voltages: the drive may apply any voltage within the supply
        drive = CoilDrive.supply_limited(self.supply_v, self.resistance_ohm, self.inductance_h)
        self.coils = CoilDriver(boards, [drive] * n, sleep=self.coil_clock.sleep)

        self.sensor_clock = SimClock()
        self.sensor_bus = SimBus(scl_hz=400e3, clock=self.sensor_clock)
        n_sensors = 2 * self.sensor_sim.n     # both arrays, any board size
        muxes = [self.sensor_bus.attach(SimTCA9548A(0x71 + k)) for k in range((n_sensors + 7) // 8)]
        self.tlv = [muxes[i // 8].attach(i % 8, SimTLV493D()) for i in range(n_sensors)]
        self.sensors = SensorArrays(self.sensor_bus, default_sensor_layout(n_sensors),
                                    sleep=self.sensor_clock.sleep, clock=self.sensor_clock.now)
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

        Returns the estimator's ``calibration`` (gain_inverse (2, n, 3, 3), offsets (2, n, 3)).
        """
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

    def sensor_source(self, position_at, period_s: float) -> SimSensorSource:
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


