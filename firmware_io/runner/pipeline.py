"""The sensor side of the runner: one frame of the two sensor arrays -> one :class:`Fix`.

Run by the sensor thread (:class:`firmware_io.run.ThreadedSensorSource`) on the controller and
with the same timing by designkit.sim's simulated source. For each frame (fields in T, NaN
where unusable, and each sensor's status) it checks each sensor's health, excludes the
unhealthy and the expectedly saturated sensors, and runs the localizer's fit with the coil
currents of the frame's own time (:class:`CurrentHistory`). The fault names it reports and
the exclusion policy: docs/runner.md.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..hw.tlv493d import TLV493D_LINEAR_RANGE_T
from ..localization import multipole_field

SENSOR_FAULTS = {"stale": "sensor_stuck", "recovered": "sensor_stuck", "hung": "sensor_stuck",
                 "saturated": "sensor_saturated", "nack": "sensor_dead", "failed": "sensor_dead",
                 "unconfigured": "sensor_dead", "not_ready": "sensor_dead",
                 "test_mode": "sensor_dead"}
"""Per-sensor status (firmware_io.hw.sensors / devices.TLV493D) -> the runner's fault name; any status
but 'ok' excludes the sensor from localization."""

EXPECTED_SATURATION = 0.8
"""A sensor whose predicted field (coils at the modelled currents + the magnet's dipole at the
predicted position) exceeds this fraction of the TLV493D's +-130 mT linear range on some axis is
expected to saturate: it is excluded without a fault (full rendering currents saturate the sensor
above an energized iron-core coil). Any other reading beyond the linear range is a fault."""


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
    covariance_m2 : ndarray (3, 3) m^2 or None -- the fit's covariance (None: unknown)
    protection_level_m : float, m -- bound on the error at the localizer's integrity risk (0
        when the localizer states none: its ``ok`` alone decides)
    reacquired : bool -- the fit started from the global search at the loop's request
    """

    position_m: np.ndarray
    ok: bool
    frame_t_s: float
    problems: tuple
    excluded: np.ndarray
    fit_s: float
    covariance_m2: np.ndarray | None = None
    protection_level_m: float = 0.0
    reacquired: bool = False


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
        """Record the currents (n,) A of the step starting at ``t_s`` (s)."""
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
    localizer : firmware_io.localization.Estimator
        ``estimate(readings_t (2 n, 3), currents_a)`` -> an Estimate (upper array, then lower).
    fieldmap : object
        Optionally ``sensor_coil_field() -> (2, n, 3, n)`` T/A and ``sensor_positions_m``
        (2, n, 3) m: the expected-saturation test (:data:`EXPECTED_SATURATION`).
    n_coils : int
    n_sensors : int or None -- sensors per array (default: the map's sensor positions, else the
        localizer model's, else one per coil)
    currents_at : callable
        ``currents_at(t_s) -> (n,)`` A: the modelled currents when the frame was sampled.
    moment_a_m2 : ndarray, shape (3,), A m^2
    clock : callable, s
    """

    def __init__(self, localizer, fieldmap, n_coils: int, currents_at: Callable,
                 moment_a_m2, clock: Callable[[], float] = time.perf_counter,
                 n_sensors: int | None = None):
        self.localizer, self.map = localizer, fieldmap
        self.n = _sensors_per_array(fieldmap, localizer, n_coils) if n_sensors is None \
            else int(n_sensors)
        self.currents_at, self.clock = currents_at, clock
        self.moment = np.asarray(moment_a_m2, float)
        self.excluded = np.zeros(2 * self.n, dtype=bool)
        self.position_m: np.ndarray | None = None     # last ok estimate
        self.reacquire = False     # set by the control loop: the next fit starts cold
        coil_field = getattr(fieldmap, "sensor_coil_field", None)
        self._coil_field = None
        if coil_field is not None:
            g = np.asarray(coil_field(), float) if callable(coil_field) else None
            if g is not None and g.shape == (2, self.n, 3, n_coils):
                self._coil_field = g.reshape(2 * self.n * 3, n_coils)
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
        """Health checks, exclusions and the fit of one frame."""
        t0 = self.clock()
        n = self.n
        shapes = (np.shape(frame.top_t), np.shape(frame.bottom_t), len(frame.status))
        if shapes != ((n, 3), (n, 3), 2 * n):
            # a malformed frame is not fitted: not ok, with the reason, never an exception
            p = np.zeros(3) if self.position_m is None else self.position_m.copy()
            return Fix(p, False, float(frame.t_s),
                       (("lost", f"bad frame: arrays of shape {shapes[0]}, {shapes[1]} and "
                                 f"{shapes[2]} statuses (expected ({n}, 3) each, {2 * n})"),),
                       self.excluded.copy(), self.clock() - t0)
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
        cold = self.reacquire
        if cold:
            self.reacquire = False
            getattr(self.localizer, "reset", lambda: None)()
        # the estimator never raises on a bad frame: a not-ok estimate with its reason
        est = self.localizer.estimate(np.concatenate([top, bottom]), currents)
        ok = bool(est.ok)
        p = np.asarray(est.position_m, float).copy()
        if ok:
            self.position_m = p
        else:
            problems.append(("lost", est.reason or "the localizer flagged its estimate"))
        cov = est.position_covariance_m2
        return Fix(p, ok, float(frame.t_s), tuple(problems), self.excluded.copy(),
                   self.clock() - t0, None if cov is None else np.asarray(cov, float),
                   float(est.protection_level_m), cold)


def _sensors_per_array(fieldmap, localizer, n_coils: int) -> int:
    """Sensors per array: the map's sensor positions (2, n, 3), else the localizer model's,
    else one per coil."""
    for owner in (fieldmap, getattr(localizer, "model", None)):
        pts = getattr(owner, "sensor_positions_m", None)
        if pts is not None and np.ndim(pts) == 3 and np.shape(pts)[0] == 2:
            return int(np.shape(pts)[1])
    return int(n_coils)
