"""The simulated device: register-level PWM boards and Hall sensors on two simulated I2C buses,
driven by exact array physics and R-L coil currents.

The coil currents (A) follow the voltage each coil driver applies from the drive record's
supply (the design's: what the coils see), read back from the simulated PCA9685 registers (PWM
duty, DIR level), so the bytes the runner wrote are what moves the current. The true force on
the magnet (N) comes from designkit's array model at the true pose -- its position and the
moment the finger's tilt gives it (``CoilArray`` A(p) with F = F(m) G5, + the pull of the cores
on the magnet as the finite cylinder it is; 1010-steel cores saturate at the true currents,
:mod:`designkit.sim.saturation`) -- never the map, so that the map's, the estimator's and the
allocator's errors show up in a run. The sensors see the tilted magnet's exact field through
their errors and noise (designkit.sim.readings.SensorSimulator).
"""

from __future__ import annotations

import numpy as np

from firmware_io.hw.coils import CoilDriver
from firmware_io.hw.pca9685 import PCA9685
from firmware_io.runner import (CALIBRATION_CURRENT_A, calibrate_sensors, calibration_currents,
                                record_calibration, rl_step)
from firmware_io.hw.sensors import SensorArrays, default_sensor_layout
from firmware_io.hw.sim import SimBus, SimClock, SimPCA9685, SimTCA9548A, SimTLV493D
from firmware_io.mapfile.drive import DriveRecord

from ..model.array import CoilArray, force_matrix
from ..model.coil import Coil
from ..model.electrical import drive_data
from .readings import SensorSimulator, analog_reading, magnet_field
from .samples import (Sampled, bias_force_any, finite_size_bias, induced_field_any, memoized,
                      sample_steps)
from .saturation import PATH_STEP_M, PlantSaturation
from .sensors import MODELLED_FIT_S, SimSensorSource


FINITE_SIZE_STEP_M = 1e-3
"""Path step of the finite-size part of F0 (:func:`designkit.sim.samples.finite_size_bias`), m."""


class SimulatedDevice:
    """Register-level PWM boards and sensors on two simulated buses, driven by exact physics.

    Parameters
    ----------
    design : Design
    array : CoilArray
        The physics (default ``CoilArray.from_design(design)``).
    noise_t : float
        Sensor noise, T rms per axis (TLV493D datasheet: 0.1 mT), added before quantization.
    sensor_errors : {'default', 'ideal'} or designkit.sim.readings.SensorErrors
        Offsets, gains and mounting errors of the sensors (designkit.sim.readings's stated defaults:
        0.5 mm, 1 degree, 1 % gain, 0.01 mT offset after calibration).
    seed : int
    drive : firmware_io.mapfile.drive.DriveRecord, optional
        The coils' drive (default: :func:`designkit.model.electrical.drive_data` of the design's
        coils): its supply, driver, and each coil's R (at the operating temperature) and L are
        the simulated coils' (a design with coils of several sizes drives each by its own).

    The coil bus runs at 1 MHz (the PCA9685s on their own adapter: Fm+, per the PCA9685
    datasheet), the sensor bus at 400 kHz (the TCA9548A's limit); each has its own simulated
    clock.
    """

    def __init__(self, design, array=None, *, noise_t: float = 1e-4, seed: int = 0,
                 sensor_errors="default", drive: DriveRecord | None = None):
        self.design = design
        self.array = array if array is not None else CoilArray.from_design(design)
        n = self.array.n_coils
        self.drive = (drive if drive is not None
                      else drive_data(design, [Coil.of_design(design, k) for k in range(n)]))
        self.resistance_ohm = np.asarray(self.drive.resistance_ohm, float)   # (n,) ohm
        self.inductance_h = np.asarray(self.drive.inductance_h, float)       # (n,) H
        self.supply_v = self.drive.supply_voltage_v
        # the cores' saturation up to the largest current the supply can drive
        top_a = max(self.drive.current_limit_a, self.supply_v / float(self.resistance_ohm.min()))
        self.saturation = PlantSaturation.of(self.array, top_a)
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
        self.coils = CoilDriver(boards, list(self.drive.drives), sleep=self.coil_clock.sleep)

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
        self.ambient_t = np.zeros(3)     # a uniform field in the room (array frame), T
        self._in_flight: tuple[float, float, object] | None = None
        self._last_set_s = 0.0

    # -- coils ----------------------------------------------------------------------------------
    def applied_voltage_v(self) -> np.ndarray:
        """Voltage each driver applies now, from the PCA9685 registers (PWM duty, DIR level)."""
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
    def prepare(self, positions_m, directions=None, *, sample_step_m: float = 2.5e-4,
                max_stride: int = 10, induced_step_m: float = 2e-3) -> None:
        """Evaluate the array model in a few batches along every step's true pose.

        The finger's path and tilt are scripted, so the model is never called inside the loop:
        A(p) is evaluated where the path has moved ``sample_step_m`` or the magnet turned 0.5
        degrees since the last sample (at least every ``max_stride`` steps, and on both sides of
        a jump) and interpolated linearly in between; for a path that moves 0.25 mm between
        samples the interpolation error of A is ~(0.25 mm / 30 mm)^2 ~ 1e-4 relative at the
        design point (the field varies on the coil-size scale). The magnet-induced core field
        at the sensors, a small smooth term, every ``induced_step_m`` or 2 degrees.

        Parameters
        ----------
        positions_m : (k, 3) m -- the true position at each step
        directions : (k, 3) unit vectors, optional -- the true moment direction at each step
            (default: the design's)
        """
        p = np.asarray(positions_m, float).reshape(-1, 3)
        mag = float(np.linalg.norm(self.moment))
        u = (np.tile(self.moment / mag, (len(p), 1)) if directions is None
             else np.asarray(directions, float).reshape(-1, 3))
        self.path_m, self.moment_steps = p, mag * u
        idx = sample_steps(p, u, step_m=sample_step_m, turn_rad=np.radians(0.5),
                           max_stride=max_stride)
        a = self.array.actuation_matrix(p[idx])
        self.g5 = Sampled(idx, a[:, 3:, :])          # gradient rows per ampere, T/(m A)
        self.b_per_amp = Sampled(idx, a[:, :3, :])   # field per ampere at the magnet, T/A
        # F0 of the point dipole along the path, plus what the cylinder changes in it (sampled
        # every mm: ~4 % of F0 at 20 mm, its interpolation within ~0.1 % of F0)
        at = sample_steps(p, u, step_m=FINITE_SIZE_STEP_M, turn_rad=np.radians(2.0))
        mg = self.design.magnet
        size = Sampled(at, memoized(finite_size_bias, self.array, p[at], self.moment_steps[at],
                                    (mg.radius_m, mg.length_m)))
        self.bias = Sampled(idx, memoized(bias_force_any, self.array, p[idx],
                                          self.moment_steps[idx]) + size.all(idx))
        self.sat_deltas = None
        if self.saturation is not None:    # the cores' field only: the moment does not enter
            at = sample_steps(p, np.tile([0.0, 0.0, 1.0], (len(p), 1)), step_m=PATH_STEP_M,
                              turn_rad=np.pi)
            self.sat_deltas = Sampled(at, self.saturation.deltas(p[at]))
        coarse = sample_steps(p, u, step_m=induced_step_m, turn_rad=np.radians(2.0))
        pts = self.sensor_sim.true_m.reshape(-1, 3)
        self.induced = Sampled(coarse, memoized(induced_field_any, self.array, pts, p[coarse],
                                                self.moment_steps[coarse]))

    def actuation(self, step: int, current_a) -> np.ndarray:
        """The plant's A at the true position of step ``step`` for the currents ``current_a``
        (n,) A: (8, n), each column at its coil's |I| when the cores saturate."""
        a = np.concatenate([self.b_per_amp.at(step), self.g5.at(step)])
        if self.sat_deltas is None:
            return a
        return self.saturation.columns(a, self.sat_deltas.at(step), current_a)

    def true_force_n(self, step: int, current_a) -> np.ndarray:
        """Force on the true magnet (its moment at step ``step``) at its true position, N, (3,):
        F(m) G5(p, I) I + F0(p, m)."""
        return self.force_per_amp(step, current_a) @ current_a + self.bias.at(step)

    def true_torque_n_m(self, step: int, current_a) -> np.ndarray:
        """Torque m x B of the coils' field on the true magnet at step ``step``, N m, (3,)."""
        b = self.actuation(step, current_a)[:3]
        return np.cross(self.moment_steps[step], b @ current_a)

    def force_per_amp(self, step: int, current_a) -> np.ndarray:
        """The true magnet's force per ampere at step ``step`` with the currents ``current_a``
        (the saturating cores' columns at them), (3, n) N/A."""
        return force_matrix(self.moment_steps[step]) @ self.actuation(step, current_a)[3:]

    def saturated(self, points_m, a_linear, current_a) -> np.ndarray:
        """The plant's exact A at any points (k, 3) m for the currents (k, n) A there: (k, 8, n)
        from the coupled (linear) ``a_linear`` (k, 8, n) there, each column at its coil's |I|
        (``a_linear`` itself when no core saturates)."""
        if self.saturation is None:
            return a_linear
        p = np.asarray(points_m, float).reshape(-1, 3)
        d = self.saturation.deltas(p)
        i = np.asarray(current_a, float).reshape(len(p), -1)
        return np.stack([self.saturation.columns(a_linear[k], d[k], i[k])
                         for k in range(len(p))])

    def sensor_readings_t(self, step: int, position_m, current_a) -> np.ndarray:
        """(n_sensors, 3) T, what each sensor's ADC converts at step ``step`` (the magnet at
        ``position_m`` with its moment at that step): the field (magnet, coils, induced cores)
        through the sensor errors, plus noise and injected offsets, with the room's uniform field
        ``ambient_t``; the TLV493D models quantize and clip it."""
        sim = self.sensor_sim
        mg = self.design.magnet
        pts = sim.true_m.reshape(-1, 3)
        magnet = magnet_field(pts, np.asarray(position_m, float), self.moment_steps[step],
                              mg.radius_m, mg.length_m)
        b = (magnet + self.induced.at(step) + self.ambient_t).reshape(sim.true_m.shape) \
            + sim.coil_part(np.asarray(current_a, float)[None])[0]
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
                  self.supply_v / float(self.resistance_ohm.max()))
        currents = calibration_currents(self.array.n_coils, amp, frames)
        tau = float(np.max(self.inductance_h / self.resistance_ohm))   # the slowest coil
        readings, applied = record_calibration(self.coils, self.sensors, currents,
                                               settle_s=7 * tau, sleep=settle)
        settle(7 * tau)          # coils off: decayed before the run starts
        self.current_a[:] = 0.0
        return calibrate_sensors(model, readings, applied)

    def sensor_source(self, position_at, period_s: float,
                      fit_time_s: float | None = MODELLED_FIT_S) -> SimSensorSource:
        """The runner's sensor source on this device; ``position_at(t_s)`` is the true position
        (the path given to :meth:`prepare`, one sample per control period ``period_s``);
        ``fit_time_s``: the fit's compute time in the timeline (None: measured)."""
        return SimSensorSource(self, position_at, period_s, fit_time_s)
