"""The rendering runner: sensors -> position -> object force -> currents -> PWM, fail-safe.

Two sides. The sensor side (:class:`SensorPipeline`, run by the sensor thread
:class:`firmware_io.run.ThreadedSensorSource` on the controller, and modelled with the same
timing by designkit.plant's simulated source) reads the two arrays (10-20 ms per pass on one
400 kHz bus), checks each sensor's health and runs the localizer's fit, then publishes a
:class:`Fix` (estimate, frame time, sensor problems). The control step (period ``T``, default
1 ms) never fits::

    newest Fix, if any (estimate of a frame ~2 passes old)          [sensor side]
      -> Kalman update at the frame's time, prediction to now        [tracker]
      -> object force f at the predicted position                   [scene]
      -> currents: min ||F(p) I - (f - F0(p))|| within the bounds    [allocation]
      -> coil dynamics: voltage feed-forward so that the current reaches the command at the
         end of the period (within the supply), I^2 t thermal guard  [CoilDynamics, ThermalGuard]
      -> MD10C duty/direction, one block write per PCA9685           [CoilDriver]

Only the rows of A(p) the force law uses enter the force (:func:`force_law_rows`: Fz alone of a
z-dipole needs dBx/dx and dBy/dy, the 3-D force of a z-dipole four of the five gradient rows;
firmware_io.mapfile's one-point kernel evaluates all eight rows in one product, which costs less
than selecting rows inside it, so the runner slices them -- studies/bench_runner.py measures
both) and, with ``skip_force_n`` > 0, only the coils whose force at p could exceed it are
evaluated and allocated: a coil is left out (its current is 0) when :class:`CoilSkipBound`'s upper bound of its force
per ampere around p, times its current limit, is at most ``skip_force_n`` -- the force the
skipped coils could have added is below ``skip_force_n`` each.

Faults and the safe state. Every fault switches every coil off in the same step (one ALL_LED_OFF
write per board: :meth:`CoilDriver.all_off`), writes one log line and records the state name.

================  =========================================  ===================================
state             cause                                      resume policy
================  =========================================  ===================================
pwm_nack          a PCA9685 write was not acknowledged        boards re-initialised after
                                                             ``resume_after_s``; latched after
                                                             ``max_pwm_retries`` failures
sensor_stuck      a sensor's frame counter stopped            after ``resume_after_s``, with that
sensor_dead       a sensor NACKs / failed to configure        sensor excluded (NaN) for as long as
sensor_saturated  a sensor reads at the end of its range      it is unhealthy, if the estimate is ok
lost              the localizer flags its estimate (ok=False) when an estimate is ok again
out_of_box        the estimate left the map's box             when it is back inside the box
overrun           a step's compute time exceeded the period   after ``resume_after_s``
thermal           a coil's I^2 t exceeded its budget          when it fell below ``thermal_resume``
                                                             of the budget (cooled)
over_limit        a command above the per-coil limit or the   after ``resume_after_s``
                  total budget reached the output stage
================  =========================================  ===================================

Imports numpy only (plus the firmware_io drivers); the hardware entry point is
``python -m firmware_io.run``.
"""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .devices import TLV493D_LINEAR_RANGE_T
from .errors import BadInputError, CoilWriteError, FirmwareIOError
from .localization import ConstantVelocityKalman, multipole_field

SENSOR_FAULTS = {"stale": "sensor_stuck", "recovered": "sensor_stuck",
                 "saturated": "sensor_saturated", "nack": "sensor_dead", "failed": "sensor_dead",
                 "unconfigured": "sensor_dead", "not_ready": "sensor_dead",
                 "test_mode": "sensor_dead"}
"""Per-sensor status (firmware_io.sensors / devices.TLV493D) -> the runner's fault name; any status
but 'ok' excludes the sensor from localization."""

EXPECTED_SATURATION = 0.8
"""A sensor whose predicted field (coils at the modelled currents + the magnet's dipole at the
predicted position) exceeds this fraction of the TLV493D's +-130 mT linear range on some axis is
expected to saturate: it is excluded without a fault (full rendering currents saturate the sensor
above an energized iron-core coil). Any other reading beyond the linear range is a fault."""

FAULTS = ("pwm_nack", "sensor_stuck", "sensor_dead", "sensor_saturated", "lost", "out_of_box",
          "overrun", "thermal", "over_limit")


# ---------------------------------------------------------------------------------------------
# coil dynamics and thermal guard (pure numpy)


def feedforward_voltage(target_a, current_a, resistance_ohm, inductance_h, period_s,
                        supply_v):
    """Voltage that takes an R-L coil from ``current_a`` to ``target_a`` in one period.

    With a constant voltage V over the period T the current of an R-L coil is
    ``I(T) = V/R + (I0 - V/R) exp(-T R / L)`` exactly, so
    ``V = R (I* - I0 e) / (1 - e)`` with ``e = exp(-T R / L)``. The result is clipped to
    ``[-supply_v, supply_v]`` (the MD10C's sign-magnitude output); then the target is reached
    later, never overshot, because I(t) is monotone under a constant V.

    Parameters
    ----------
    target_a, current_a : ndarray, shape (n,), A
    resistance_ohm, inductance_h : ndarray, shape (n,), ohm and H (> 0)
    period_s, supply_v : float, s and V

    Returns
    -------
    ndarray, shape (n,), V
    """
    e = np.exp(-period_s * resistance_ohm / inductance_h)
    v = resistance_ohm * (target_a - current_a * e) / (1.0 - e)
    return np.clip(v, -supply_v, supply_v)


def rl_step(current_a, voltage_v, resistance_ohm, inductance_h, period_s):
    """Exact R-L response to a constant voltage over one period: I(T), A, shape (n,)."""
    e = np.exp(-period_s * resistance_ohm / inductance_h)
    i_inf = voltage_v / resistance_ohm
    return i_inf + (current_a - i_inf) * e


@dataclass
class ThermalGuard:
    """I^2 t budget per coil with first-order cooling.

    ``E_k <- E_k exp(-T / tau) + I_k^2 T``; a coil carrying ``continuous_current_a`` forever
    settles at ``E = I_c^2 tau (1 - ...)`` -> the budget is ``I_c^2 * tau``. A fault when any
    ``E_k`` exceeds the budget; cleared when every ``E_k`` is below ``resume_fraction`` of it.

    Attributes
    ----------
    continuous_current_a : float, A
        Current the coil can carry indefinitely without reaching its temperature limit.
    time_constant_s : float, s
        Thermal time constant of the winding.
    """

    n_coils: int
    continuous_current_a: float
    time_constant_s: float
    resume_fraction: float = 0.8
    energy_a2s: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self):
        if not (self.continuous_current_a > 0 and math.isfinite(self.continuous_current_a)):
            raise BadInputError("continuous_current_a", "a finite current > 0 A",
                                self.continuous_current_a)
        if not (self.time_constant_s > 0 and math.isfinite(self.time_constant_s)):
            raise BadInputError("time_constant_s", "a finite time > 0 s", self.time_constant_s)
        if self.energy_a2s is None:
            self.energy_a2s = np.zeros(self.n_coils)

    @property
    def budget_a2s(self) -> float:
        return self.continuous_current_a ** 2 * self.time_constant_s

    def update(self, current_a: np.ndarray, period_s: float) -> None:
        self.energy_a2s *= math.exp(-period_s / self.time_constant_s)
        self.energy_a2s += np.square(current_a) * period_s

    def exceeded(self) -> bool:
        return bool(np.any(self.energy_a2s > self.budget_a2s))

    def cooled(self) -> bool:
        return bool(np.all(self.energy_a2s < self.resume_fraction * self.budget_a2s))


# ---------------------------------------------------------------------------------------------
# what the force law needs of A(p)


def force_law_rows(moment_a_m2, axes: str = "xyz") -> tuple[np.ndarray, np.ndarray]:
    """Rows of A(p) (indices into Bx, By, Bz, dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz) the force
    on a dipole ``moment_a_m2`` uses, and the matrix that maps them to the force per ampere.

    F = M(m) G5 (thesis eq. 2.5) with G5 = rows 3..7; a column of M(m) that is zero (for the
    rendered axes) marks a row not needed: for a z-dipole the 3-D force needs dBx/dx, dBx/dz,
    dBy/dy, dBy/dz, and Fz alone (``axes='z'``) dBx/dx and dBy/dy.

    Returns
    -------
    rows : ndarray of int, shape (r,)
    matrix : ndarray, shape (3, r) or (1, r) -- force per ampere = matrix @ A[rows]
    """
    mx, my, mz = (float(v) for v in moment_a_m2)
    # F = F(m) G5 (thesis eq. 2.5), the one numpy definition on the controller side
    full = np.array([[mx, my, mz, 0.0, 0.0],
                     [0.0, mx, 0.0, my, mz],
                     [-mz, 0.0, mx, -mz, my]])
    if axes == "z":
        full = full[2:3]
    used = np.flatnonzero(np.any(full != 0.0, axis=0))
    return used + 3, full[:, used].copy()


def _accepts_selection(fieldmap, point) -> bool:
    """True when ``fieldmap.actuation`` takes ``rows=`` and ``coils=`` (firmware_io.mapfile)."""
    try:
        fieldmap.actuation(point, rows=(3,), coils=(0,))
    except TypeError:
        return False
    return True


class CoilSkipBound:
    """Upper bound of each coil's force per ampere |F_k| (N/A) near a point, from a grid.

    At start-up the force per ampere of every coil is evaluated at the nodes of a grid of
    spacing <= ``spacing_m`` over the map's box. In a cell, with c_max and c_min the largest and
    smallest of |F_k| at its eight corners, the bound is ``c_max + (c_max - c_min)``: a smooth
    |F_k| sampled finely enough that it varies within a cell by no more than between the cell's
    corners stays below it (the coils' fields vary on the coil-size scale, ~20 mm; the default
    spacing is 5 mm). A coil is skipped at p when bound_k(cell(p)) * I_limit,k <= the stated
    force; the force the skipped coils could add is then at most that force each.

    Parameters
    ----------
    fieldmap : object with ``actuation(points (N, 3)) -> (N, 8, n)`` and ``bounds``
    rows, matrix : from :func:`force_law_rows`
    spacing_m : float
    """

    def __init__(self, fieldmap, rows, matrix, spacing_m: float = 5e-3):
        lo, hi = (np.asarray(b, float) for b in fieldmap.bounds)
        counts = [max(2, int(math.ceil((hi[k] - lo[k]) / spacing_m)) + 1) for k in range(3)]
        axes = [np.linspace(lo[k], hi[k], counts[k]) for k in range(3)]
        g = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
        a = np.asarray(fieldmap.actuation(g), float)[:, rows]          # (N, r, n)
        f = np.linalg.norm(np.einsum("ij,njk->nik", matrix, a), axis=1)  # (N, n)
        f = f.reshape(*counts, -1)
        corners = [f[i:i + counts[0] - 1, j:j + counts[1] - 1, k:k + counts[2] - 1]
                   for i in (0, 1) for j in (0, 1) for k in (0, 1)]
        cmax = np.maximum.reduce(corners)
        cmin = np.minimum.reduce(corners)
        self.bound_n_per_a = cmax + (cmax - cmin)        # (cx, cy, cz, n)
        self.lo = lo
        self.step = (hi - lo) / (np.asarray(counts) - 1)
        self.cells = [c - 2 for c in counts]

    def at(self, p) -> np.ndarray:
        """(n,) N/A: the bound of each coil's force per ampere in the cell holding p (the
        nearest cell outside the box)."""
        idx = [min(max(int((p[k] - self.lo[k]) / self.step[k]), 0), self.cells[k])
               for k in range(3)]
        return self.bound_n_per_a[idx[0], idx[1], idx[2]]

    def keep(self, p, limit_a: np.ndarray, force_n: float) -> np.ndarray:
        """Indices of the coils whose force at their limit could exceed ``force_n`` near p."""
        return np.flatnonzero(self.at(p) * limit_a > force_n)


# ---------------------------------------------------------------------------------------------
# configuration and records


@dataclass(frozen=True)
class RunnerConfig:
    """Everything the loop needs besides its devices, SI units.

    Attributes
    ----------
    resistance_ohm, inductance_h : tuple of float, one per coil
        Coil resistance at the operating temperature and inductance (secant, at the operating
        current) -> the L/R lag the feed-forward compensates.
    supply_voltage_v : float
        MD10C motor supply, V (<= 30 V).
    current_limit_a, total_current_a : float
        Per-coil bound |I_k| <= u and the budget sum |I_k| <= I_t, A.
    unipolar : bool
        0 <= I_k (the thesis' drive) instead of the MD10C's bipolar drive.
    control_period_s : float
        Step period T, s (default 1 ms).
    force_axes : {'z', 'xyz'}
        Force components to render: 'z' evaluates only the two rows of A(p) that Fz of a
        z-dipole needs.
    skip_force_n : float
        Leave a coil out when the bound of the force it could add at its current limit near p
        is at most this, N (0: never skip; see :class:`CoilSkipBound`).
    feedforward : bool
        Voltage feed-forward through the L/R model (off: the duty is the steady-state one).
    thermal_continuous_current_a, thermal_time_constant_s : float
        :class:`ThermalGuard` parameters.
    resume_after_s : float
        Fault-free time before a transient fault is cleared, s.
    max_pwm_retries : int
        PCA9685 re-initialisations before a ``pwm_nack`` is latched.
    overrun_factor : float
        A step is an overrun when its compute time exceeds ``overrun_factor * control_period_s``
        (default 10: the coils then held one command for 10 ms, a third of an iron-core coil's
        L/R; a slow step of a 1 kHz loop is a late update, not a hazard, while a stalled loop
        is. The benchmark's target is p99 <= 1 period; a step with a new sensor frame takes
        longer today, see studies/bench_runner.py).
    """

    resistance_ohm: tuple
    inductance_h: tuple
    supply_voltage_v: float
    current_limit_a: float
    total_current_a: float
    unipolar: bool = False
    control_period_s: float = 1e-3
    force_axes: str = "z"
    skip_force_n: float = 0.0
    feedforward: bool = True
    thermal_continuous_current_a: float = 3.0
    thermal_time_constant_s: float = 300.0
    resume_after_s: float = 0.25
    max_pwm_retries: int = 3
    overrun_factor: float = 10.0

    def __post_init__(self):
        n = len(self.resistance_ohm)
        r = np.asarray(self.resistance_ohm, float)
        ind = np.asarray(self.inductance_h, float)
        if n == 0 or not np.all(np.isfinite(r)) or np.any(r <= 0):
            raise BadInputError("resistance_ohm", "one finite value > 0 ohm per coil",
                                self.resistance_ohm)
        if ind.shape != (n,) or not np.all(np.isfinite(ind)) or np.any(ind <= 0):
            raise BadInputError("inductance_h", f"{n} finite values > 0 H", self.inductance_h)
        if not 5.0 <= self.supply_voltage_v <= 30.0:
            raise BadInputError("supply_voltage_v", "in [5, 30] V (MD10C rating)",
                                self.supply_voltage_v)
        if not (0 < self.current_limit_a <= 13.0):
            raise BadInputError("current_limit_a", "in (0, 13] A", self.current_limit_a)
        if not (self.total_current_a >= 0 and math.isfinite(self.total_current_a)):
            raise BadInputError("total_current_a", "a finite value >= 0 A", self.total_current_a)
        if not (0 < self.control_period_s <= 0.1):
            raise BadInputError("control_period_s", "in (0, 0.1] s", self.control_period_s)
        if self.force_axes not in ("z", "xyz"):
            raise BadInputError("force_axes", "'z' or 'xyz'", self.force_axes)
        if not (0 <= self.skip_force_n and math.isfinite(self.skip_force_n)):
            raise BadInputError("skip_force_n", "a finite force >= 0 N", self.skip_force_n)

    @property
    def n_coils(self) -> int:
        return len(self.resistance_ohm)


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


@dataclass
class SensorFrame:
    """Two arrays of readings (T, NaN where unusable), their status and the time of the frame."""

    top_t: np.ndarray
    bottom_t: np.ndarray
    status: tuple
    t_s: float


@dataclass
class Fix:
    """What the sensor side publishes for one frame (SI).

    Attributes
    ----------
    position_m : ndarray, shape (3,), m -- the localizer's estimate
    ok : bool -- the localizer trusts it
    frame_t_s : float, s -- when the frame's field was sampled
    problems : tuple of (fault name, detail)
    excluded : ndarray, shape (2 n,), bool -- sensors left out of the fit
    fit_s : float, s -- compute time of the health checks and the fit
    """

    position_m: np.ndarray
    ok: bool
    frame_t_s: float
    problems: tuple
    excluded: np.ndarray
    fit_s: float


class CurrentHistory:
    """Ring buffer of the modelled coil currents at the start of each control step.

    Written by the control loop, read by the sensor thread (a frame is ~2 bus passes old: the
    fit needs the currents its field was sampled at). A row's current is written before its
    time, so a reader never takes a half-written row unless the frame is older than the whole
    buffer (``length`` steps).
    """

    def __init__(self, n_coils: int, length: int):
        self.t_s = np.full(length, -math.inf)
        self.current_a = np.zeros((length, n_coils))
        self.k = 0

    def push(self, t_s: float, current_a: np.ndarray) -> None:
        j = self.k % len(self.t_s)
        self.current_a[j] = current_a
        self.t_s[j] = t_s
        self.k += 1

    def at(self, t_s: float) -> np.ndarray:
        """Currents (n,) A of the newest step that started at or before ``t_s`` (the oldest
        kept when none did; zeros before the first step)."""
        t = self.t_s
        before = t <= t_s + 1e-12
        if not before.any():
            if self.k == 0:
                return np.zeros(self.current_a.shape[1])
            return self.current_a[int(np.argmin(t))].copy()
        return self.current_a[int(np.argmax(np.where(before, t, -math.inf)))].copy()


class SensorPipeline:
    """The sensor side: one :class:`SensorFrame` -> one :class:`Fix` (health checks, fit).

    Parameters
    ----------
    localizer : object
        ``locate(top, bottom, currents=None)`` -> an estimate with ``position_m`` and ``ok``.
    fieldmap : object
        Optionally ``sensor_coil_field() -> (2, n, 3, n)`` T/A and ``sensor_positions_m``
        (2, n, 3) m: the expected-saturation test (:data:`EXPECTED_SATURATION`).
    n_coils : int
    currents_at : callable
        ``currents_at(t_s) -> (n,)`` A: the modelled currents when the frame was sampled.
    moment_a_m2 : ndarray, shape (3,)
    clock : callable, s
    """

    def __init__(self, localizer, fieldmap, n_coils: int, currents_at: Callable,
                 moment_a_m2, clock: Callable[[], float] = time.perf_counter):
        self.localizer, self.map, self.n = localizer, fieldmap, n_coils
        self.currents_at, self.clock = currents_at, clock
        self.moment = np.asarray(moment_a_m2, float)
        self.excluded = np.zeros(2 * n_coils, dtype=bool)
        self.position_m: np.ndarray | None = None     # last ok estimate
        coil_field = getattr(fieldmap, "sensor_coil_field", None)
        self._coil_field = None
        if coil_field is not None:
            g = np.asarray(coil_field(), float) if callable(coil_field) else None
            if g is not None and g.shape == (2, n_coils, 3, n_coils):
                self._coil_field = g.reshape(2 * n_coils * 3, n_coils)
                self._sensor_pts = np.asarray(fieldmap.sensor_positions_m,
                                              float).reshape(-1, 3)

    def expected_saturation(self, currents_a: np.ndarray) -> np.ndarray:
        """(2 n,) bool: sensors the model expects beyond :data:`EXPECTED_SATURATION` of the
        linear range (coils at ``currents_a``, plus the magnet's dipole at the last estimate)."""
        if self._coil_field is None:
            return np.zeros(2 * self.n, dtype=bool)
        b = (self._coil_field @ currents_a).reshape(2 * self.n, 3)
        if self.position_m is not None:
            b = b + multipole_field(self._sensor_pts, self.position_m, self.moment)
        return np.any(np.abs(b) > EXPECTED_SATURATION * TLV493D_LINEAR_RANGE_T, axis=1)

    def process(self, frame: SensorFrame) -> Fix:
        t0 = self.clock()
        n = self.n
        status = list(frame.status)
        values = np.concatenate([frame.top_t, frame.bottom_t])
        beyond = np.any(np.abs(values) > TLV493D_LINEAR_RANGE_T, axis=1)
        for i in np.flatnonzero(beyond):
            if status[i] == "ok":
                status[i] = "saturated"
        # the currents the coils really carried when the frame's field was sampled (R-L
        # model), not the command they lag nor today's
        currents = self.currents_at(frame.t_s)
        expected = self.expected_saturation(currents)
        healthy = np.array([s == "ok" for s in status])
        # an expected saturation: excluded, not a fault
        quiet = expected & ~healthy & np.array([s == "saturated" for s in status])
        self.excluded |= quiet
        newly = [(i, s) for i, s in enumerate(status)
                 if not healthy[i] and not self.excluded[i]]
        self.excluded = ~healthy
        problems = []
        if newly:
            i, s = newly[0]
            problems.append((SENSOR_FAULTS.get(s, "sensor_dead"),
                             f"sensor {i} ({'top' if i < n else 'bottom'} {i % n}) reports "
                             f"{s!r}; excluded"))
        top = np.where(self.excluded[:n, None], np.nan, frame.top_t)
        bottom = np.where(self.excluded[n:, None], np.nan, frame.bottom_t)
        est = self.localizer.locate(top, bottom, currents=currents)
        ok = bool(est.ok)
        p = np.asarray(est.position_m, float).copy()
        if ok:
            self.position_m = p
        else:
            problems.append(("lost", "the localizer flagged its estimate (residual test)"))
        return Fix(p, ok, float(frame.t_s), tuple(problems), self.excluded.copy(),
                   self.clock() - t0)


class ConstantVelocityTracker(ConstantVelocityKalman):
    """:class:`firmware_io.localization.ConstantVelocityKalman` with the runner's tuning
    (``update(position_m, time_s, ok)``, ``predict(time_s)``, ``x`` (2, 3) position, velocity).

    Defaults: a finger's accelerations while exploring a surface, ~2 m/s^2 rms; the
    measurement variance is that of the calibrated fit on the simulated device (raw error
    median 0.5 mm, p95 1.7 mm along a slide over the hemisphere, correlated over many
    frames). Only the ratio accel/meas matters for the gain; replaying one simulated slide
    (133 frames/s, 15 ms old at hand-over) the tracked error (mean / p95) was 0.87 / 2.07 mm at
    the ratio 4000 s^-2 (2 m/s^2, 0.5 mm), 0.69 / 1.46 mm at 1000 and 0.70 / 1.32 mm at 500;
    1333 (2 m/s^2, 1.5 mm) keeps the filter responsive for faster fingers.
    """

    def __init__(self, accel_rms_m_s2: float = 2.0, meas_rms_m: float = 1.5e-3):
        super().__init__(accel_rms_m_s2, meas_rms_m)


# ---------------------------------------------------------------------------------------------
# the runner


class Runner:
    """Compose map, scene, localizer, allocator and drivers into the fail-safe control loop.

    Parameters
    ----------
    fieldmap : object
        ``actuation(point) -> (8, n)`` (rows Bx, By, Bz, dBx/dx, dBx/dy, dBx/dz, dBy/dy,
        dBy/dz, per ampere), ``bounds`` (lower (3,), upper (3,)) m, ``moment_a_m2`` (3,), and
        optionally ``bias_force(point) -> (3,)`` N and ``actuation_rows(point, rows)``.
    scene : object
        ``force(position_m, velocity_m_s) -> (3,)`` N, the object's force on the finger.
    localizer : object
        ``locate(top, bottom, currents=None)`` -> an estimate with ``position_m`` and ``ok``.
    tracker : object
        A constant-velocity filter over the estimates between frames
        (:class:`firmware_io.localization.ConstantVelocityKalman`): ``update(position_m, time_s,
        ok)``, ``predict(time_s) -> position_m`` and its state ``x`` ((2, 3): position, velocity).
    allocate : callable
        ``allocate(force_matrix, target, current_limit, total_limit, unipolar=...)``
        -> (currents, residual) (firmware_io.allocation).
    coils : CoilDriver
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
        self.r = np.asarray(config.resistance_ohm, float)
        self.ind = np.asarray(config.inductance_h, float)
        self.limit = np.full(n, config.current_limit_a)
        self.thermal = ThermalGuard(n, config.thermal_continuous_current_a,
                                    config.thermal_time_constant_s)
        m = np.asarray(fieldmap.moment_a_m2, float)
        self.moment = m
        mx, my, mz = m
        self.z_only = config.force_axes == "z" and abs(mx) + abs(my) <= 1e-12 * abs(mz)
        self.law_rows, self.law_matrix = force_law_rows(m, "z" if self.z_only else "xyz")
        self.lo, self.hi = (np.asarray(b, float) for b in fieldmap.bounds)
        self._rows_api = _accepts_selection(fieldmap, 0.5 * (self.lo + self.hi))
        self.skip = (CoilSkipBound(fieldmap, self.law_rows, self.law_matrix)
                     if config.skip_force_n > 0 else None)
        self.current_a = np.zeros(n)   # model of the coil currents (feed-forward state)
        self.command_a = np.zeros(n)
        self.state = "safe"
        self.fault: str | None = None
        self.fault_since_s = -math.inf
        self.clear_since_s: float | None = None
        self.latched = False
        self.pwm_failures = 0
        self.pwm_reinit_needed = False
        self.last_estimate_ok = False
        self.have_fix = False
        self.position_m = np.full(3, np.nan)
        self.fault_log: list[tuple[float, str, str]] = []
        # modelled currents at the start of each of the last 0.2 s of steps (frames arrive late)
        self.history = CurrentHistory(n, max(16, int(0.2 / config.control_period_s)))
        self.pipeline = SensorPipeline(localizer, fieldmap, n, self.history.at, m)
        self.last_fix: Fix | None = None
        # per-stage compute times of the last step (s), when ``profile`` is set
        self.profile = False
        self.stages: dict[str, float] = {}
        attach = getattr(sensors, "attach", None)
        if attach is not None:
            attach(self.pipeline)       # the source runs the fit on its side

    # -- life cycle ----------------------------------------------------------------------------
    def start(self, pwm_frequency_hz: float = 1526.0) -> None:
        """Initialise every PWM board into the safe state (all coils off), then run the step's
        computations once at the box centre so that the first real step is not slowed by
        first-call costs (an overrun)."""
        self.coils.initialize(pwm_frequency_hz)
        self.coils.all_off()
        self.current_a[:] = 0.0
        self.state = "safe"
        centre = 0.5 * (self.lo + self.hi)
        self._allocate(centre, np.asarray(self.scene.force(centre, np.zeros(3)), float))
        feedforward_voltage(self.current_a, self.current_a, self.r, self.ind,
                            self.cfg.control_period_s, self.cfg.supply_voltage_v)
        self.coils.plan(np.zeros(self.cfg.n_coils))
        # A full (generation 2) collection walks every object the map, scene and localizer made
        # at start-up: 12-29 ms measured, an overrun at 10 periods. Collect once now and move
        # the survivors out of the collector's reach; later collections see only what the loop
        # allocates.
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
        unconfirmed = self.coils.all_off()
        if unconfirmed:
            self.latched = True
            self.log(f"[{t_s:9.4f} s] all-off NOT confirmed on {unconfirmed}: latched")
        self.command_a[:] = 0.0
        self.state = name

    def _may_resume(self, t_s: float, clear: bool) -> bool:
        """True once the fault condition has been clear for ``resume_after_s``."""
        if self.latched:
            return False
        if not clear:
            self.clear_since_s = None
            return False
        if self.clear_since_s is None:
            self.clear_since_s = t_s
        if t_s - self.clear_since_s + 1e-12 >= self.cfg.resume_after_s:
            if self.pwm_reinit_needed and not self._reinit_pwm(t_s):
                return False
            self.log(f"[{t_s:9.4f} s] resume after {self.fault}")
            self.fault = None
            self.clear_since_s = None
            return True
        return False

    # -- the step ------------------------------------------------------------------------------
    def _mark(self, name: str, t_prev: float) -> float:
        t = self.clock()
        self.stages[name] = t - t_prev
        return t

    def step(self, t_s: float) -> StepRecord:
        """One control step at time ``t_s`` (s). Never raises for a device fault.

        ``self.sensors(t_s)`` hands over the newest :class:`Fix` of the sensor side, or None;
        a source that hands over raw :class:`SensorFrame` s instead has them processed here
        (the single-threaded fallback: the fit then counts in this step).
        """
        t0 = self.clock()
        cfg = self.cfg
        prof = self.profile
        self.history.push(t_s, self.current_a)
        item = self.sensors(t_s)
        if isinstance(item, SensorFrame):
            item = self.pipeline.process(item)
        fix: Fix | None = item
        new_frame = fix is not None
        problems: list[tuple[str, str]] = []
        if new_frame:
            self.last_fix = fix
            problems.extend(fix.problems)
            self.last_estimate_ok = fix.ok
            if fix.ok:
                self.tracker.update(fix.position_m, fix.frame_t_s, True)
                self.have_fix = True
        tm = self._mark("fix", t0) if prof else t0
        if not self.have_fix:
            return self._record(t_s, t0, np.full(3, np.nan), np.zeros(3), new_frame,
                                off=True)
        p = np.asarray(self.tracker.predict(t_s), float)
        vel = np.asarray(self.tracker.x[1], float)
        self.position_m = p
        inside = bool(np.all(p >= self.lo) and np.all(p <= self.hi))
        if not inside:
            problems.append(("out_of_box", f"estimate {np.round(p * 1e3, 1).tolist()} mm outside "
                             f"the map box"))
        if self.thermal.exceeded():
            problems.append(("thermal", f"I^2 t {self.thermal.energy_a2s.max():.0f} A^2 s above "
                             f"the budget {self.thermal.budget_a2s:.0f} A^2 s"))

        # fault handling: enter, or stay until the resume condition holds
        if problems and (self.fault is None or problems[0][0] != self.fault):
            name, detail = problems[0]
            self._enter_fault(t_s, name, detail)
        elif self.fault is not None:
            if self.fault == "thermal":
                ok_now = self.thermal.cooled()
            else:
                ok_now = not problems
            if not self._may_resume(t_s, ok_now):
                return self._record(t_s, t0, p, np.zeros(3), new_frame, off=True)
        if self.fault is not None:
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
                              f"(limits {cfg.current_limit_a} A, {cfg.total_current_a} A)")
            return self._record(t_s, t0, p, f_ref, new_frame, off=True)
        return self._drive(t_s, t0, p, f_ref, command, new_frame)

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

    def force_matrix(self, p: np.ndarray, coils=None) -> np.ndarray:
        """Force per ampere at p: (1, n) N/A (Fz of a z-dipole) or (3, n); with ``coils`` (index
        array) only those columns."""
        # the map's one-point kernel evaluates all rows in one product: slicing the rows the law
        # uses afterwards is cheaper than selecting them inside (studies/bench_runner.py); the
        # coils are selected inside (their coefficients are skipped)
        if coils is not None and self._rows_api:
            a = self.map.actuation(p, coils=coils)
        else:
            a = self.map.actuation(p)
            if coils is not None:
                a = a[:, coils]
        return self.law_matrix @ a[self.law_rows]

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
        if cfg.feedforward:
            v = feedforward_voltage(command, self.current_a, self.r, self.ind,
                                    cfg.control_period_s, cfg.supply_voltage_v)
        else:
            v = np.clip(command * self.r, -cfg.supply_voltage_v, cfg.supply_voltage_v)
        try:
            result = self.coils.command(v / self.r)
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
        v_out = np.asarray(result.current_a, float) * self.r     # what the duty really applies
        self.command_a = command
        self.current_a = rl_step(self.current_a, v_out, self.r, self.ind, cfg.control_period_s)
        self.thermal.update(self.current_a, cfg.control_period_s)
        self.state = "running"
        if self.profile:
            self._mark("drive", tm)
        return StepRecord(t_s, p, f_ref, command.copy(), v_out, self.current_a.copy(),
                          self.clock() - t0, self.state, new_frame)

    def _record(self, t_s, t0, p, f_ref, new_frame, *, off: bool) -> StepRecord:
        cfg = self.cfg
        if off:
            if self.fault is None:
                self.state = "safe"
                if np.any(self.command_a != 0) or np.any(np.abs(self.current_a) > 0):
                    self.coils.all_off()
            self.command_a = np.zeros(cfg.n_coils)
            self.current_a = rl_step(self.current_a, np.zeros(cfg.n_coils), self.r, self.ind,
                                     cfg.control_period_s)
            self.thermal.update(self.current_a, cfg.control_period_s)
        return StepRecord(t_s, np.asarray(p, float).copy(), np.asarray(f_ref, float),
                          self.command_a.copy(), np.zeros(cfg.n_coils), self.current_a.copy(),
                          self.clock() - t0, self.state, new_frame)


# ---------------------------------------------------------------------------------------------
# sensor calibration at start-up (coils only, no magnet on the board)

CALIBRATION_CURRENT_A = 2.0
"""Largest calibration current per coil, A: the iron cores stay near their linear range and the
sensors above them below the TLV493D's linear range, while every sensor sees a coil field many
times its noise along three independent directions."""


CALIBRATED_RELATIVE_ERROR = 0.005
"""Relative model error of a calibrated sensor's reading (the localizer's sensor weights): what
the affine calibration leaves of the 1 % gain and 1 degree mounting errors is the mounting shift
and the coils' nonlinearity, a fraction of a percent (studies/localization.py's 'model-cal')."""


def calibration_currents(n_coils: int, amplitude_a: float = CALIBRATION_CURRENT_A,
                         frames: int = 40, seed: int = 0) -> np.ndarray:
    """Current patterns for :func:`record_calibration`, (frames, n_coils) A: a zero frame (the
    offsets) then uniform random patterns in [-amplitude, amplitude] (with nine coils every
    sensor sees coil fields along three independent directions; fixed seed: repeatable)."""
    if not (0 < amplitude_a <= 13.0):
        raise BadInputError("amplitude_a", "in (0, 13] A", amplitude_a)
    if frames < 8:
        raise BadInputError("frames", ">= 8 (4 unknowns per sensor axis, with margin)", frames)
    rng = np.random.default_rng(seed)
    out = rng.uniform(-amplitude_a, amplitude_a, (frames, n_coils))
    out[0] = 0.0
    return out


def record_calibration(coils, arrays, currents_a: np.ndarray, *, settle_s: float,
                       sleep: Callable[[float], None] = time.sleep):
    """Initialise the PWM boards, drive each current pattern, wait ``settle_s`` (several L/R),
    read the arrays twice (a
    master-controlled TLV493D returns the conversion the previous read triggered) and keep the
    second frame; all coils off at the end, also on an error.

    The finger magnet must be away from the board (its field would be taken for an offset).

    Returns
    -------
    top_t, bottom_t : ndarray, shape (k, n, 3), T (NaN where a sensor was not 'ok')
    applied_a : ndarray, shape (k, n_coils), A -- the steady-state currents of the duties
        written (quantized, clamped by the drive)
    """
    i = np.asarray(currents_a, float)
    tops, bottoms, applied = [], [], []
    coils.initialize()
    try:
        for row in i:
            res = coils.command(row)
            sleep(settle_s)
            arrays.read()
            r = arrays.read()
            bad = np.array([s != "ok" for s in r.status])
            n = len(bad) // 2
            tops.append(np.where(bad[:n, None], np.nan, r.top_t))
            bottoms.append(np.where(bad[n:, None], np.nan, r.bottom_t))
            applied.append(np.asarray(res.current_a, float))
    finally:
        coils.all_off()
    return np.array(tops), np.array(bottoms), np.array(applied)


def calibrate_sensors(model, top_t, bottom_t, applied_a):
    """Per-sensor calibration (gain, mounting rotation, offset) from coil-only frames:
    :func:`firmware_io.localization.calibrate`, checked to be finite. Returns what it returns,
    for the Localizer's ``calibration``."""
    from .localization import calibrate

    try:
        cal = calibrate(top_t, bottom_t, applied_a, model)
    except (np.linalg.LinAlgError, ValueError):
        cal = (np.full(1, np.nan),)
    # (gain_inverse, offsets) or the localizer's calibration object with those attributes
    parts = cal if isinstance(cal, tuple) else [
        getattr(cal, a) for a in ("gain_inverse", "offsets_t", "shift_m", "coil_field_t_per_a")
        if getattr(cal, a, None) is not None]
    if not all(np.all(np.isfinite(c)) for c in parts):
        raise FirmwareIOError("sensor calibration failed (a sensor saw too few usable frames); "
                              "check the sensors and that the magnet is away from the board")
    return cal


def config_from_map(fieldmap, **overrides) -> RunnerConfig:
    """RunnerConfig from the drive data a map file carries (``meta['drive']``, SI keys)."""
    d = dict(fieldmap.meta.get("drive") or {})
    need = ("resistance_ohm", "inductance_h", "supply_voltage_v", "current_limit_a",
            "total_current_a")
    missing = [k for k in need if k not in d]
    if missing:
        raise FirmwareIOError(f"the map file carries no drive data {missing}: rebuild it with "
                              "`designkit map` (map format v2)")
    n = fieldmap.n_coils
    kw = {k: d[k] for k in need}
    for k in ("resistance_ohm", "inductance_h"):
        v = kw[k]
        kw[k] = tuple(float(x) for x in (v if isinstance(v, (list, tuple)) else [v] * n))
    for k in ("thermal_continuous_current_a", "thermal_time_constant_s"):
        if k in d:
            kw[k] = float(d[k])
    kw.update(overrides)
    return RunnerConfig(**kw)


class SceneForce:
    """A compiled scene (:class:`firmware_io.scene.Scene`) as the runner's one-point interface:
    ``force(position_m (3,), velocity_m_s (3,)) -> (3,)`` N."""

    def __init__(self, scene):
        self.scene = scene

    def force(self, p, v):
        return self.scene.force(np.asarray(p, float)[None], np.asarray(v, float)[None])[0]
