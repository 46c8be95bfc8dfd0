"""The sensor side of the runner: one :class:`~firmware_io.runner.frames.SensorFrame` -> one
:class:`~firmware_io.runner.frames.Fix`.

Run by the sensor thread (:class:`firmware_io.run.ThreadedSensorSource`) on the controller and
with the same timing by designkit.sim's simulated source. For each frame (fields in T, NaN
where unusable, each sensor's driver status) it excludes the unhealthy sensors, those the model
predicts beyond :data:`~firmware_io.runner.headroom.EXPECTED_SATURATION` of their linear range
at the frame's currents and pose, and those latched out, then runs the pose estimator with the
coil currents of the frame's own time (:class:`~firmware_io.runner.history.CurrentHistory`).
It never raises on a bad frame. Fault names and the exclusion policy: docs/runner.md.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..hw.tlv493d import TLV493D_LINEAR_RANGE_T
from .frames import Fix, SensorFrame
from .headroom import SensorLayout, expected_saturation
from .sensor_faults import SENSOR_FAULTS, ExclusionLatch


class SensorPipeline:
    """The sensor side: one :class:`SensorFrame` -> one :class:`Fix` (checks, exclusions, fit).

    Parameters
    ----------
    estimator : firmware_io.localization.Estimator
        ``estimate(readings_t (n_sensors, 3), currents_a) -> Estimate`` (never raises on a
        frame) and ``reset()``.
    layout : SensorLayout -- the sensors in the estimator's order
    currents_at : callable -- ``currents_at(t_s) -> (n_coils,)`` A, the modelled currents when
        a frame was sampled
    moment_a_m2 : ndarray (3,), A m^2 -- the magnet's moment until the estimator finds one
    clock : callable, s
    """

    def __init__(self, estimator, layout: SensorLayout, currents_at: Callable,
                 moment_a_m2, clock: Callable[[], float] = time.perf_counter):
        self.estimator, self.layout = estimator, layout
        self.n = layout.n_sensors
        self.currents_at, self.clock = currents_at, clock
        self.moment = np.asarray(moment_a_m2, float)
        self.excluded = np.zeros(self.n, dtype=bool)
        self.latch = ExclusionLatch(self.n)
        self.position_m: np.ndarray | None = None     # the last trusted pose
        self.background_t = np.zeros(3)
        self.reacquire = False     # set by the control loop: the next fit starts cold

    def expected_saturation(self, currents_a: np.ndarray) -> np.ndarray:
        """(n_sensors,) bool: sensors the model puts beyond
        :data:`~firmware_io.runner.headroom.EXPECTED_SATURATION` of the linear range with the
        coils at ``currents_a`` (A) and the magnet at the last trusted pose."""
        if self.layout.coil_field_t_per_a is None:
            return np.zeros(self.n, dtype=bool)
        return expected_saturation(self.layout.predicted_t(
            currents_a, self.position_m, self.moment, self.background_t))

    def process(self, frame: SensorFrame) -> Fix:
        """Checks, exclusions and the fit of one frame."""
        t0 = self.clock()
        bad = self._bad_frame(frame)
        if bad:
            return self._refused(frame, bad, t0)
        values = np.asarray(frame.readings_t, float)
        status = list(frame.status)
        # beyond the linear range (or Inf): saturated, whatever the driver said
        with np.errstate(invalid="ignore"):
            beyond = np.any(np.abs(values) > TLV493D_LINEAR_RANGE_T, axis=1)
        for i in np.flatnonzero(beyond):
            if status[i] == "ok":
                status[i] = "saturated"
        # the currents the coils really carried when the frame's field was sampled (R-L
        # model), not the command they lag nor today's
        currents = self.currents_at(frame.t_s)
        predicted = self.expected_saturation(currents)
        healthy = np.array([s == "ok" for s in status])
        # the one headroom rule: predicted beyond EXPECTED_SATURATION -> left out, no fault
        # (whatever the sensor reads, also a saturated reading the model expected)
        quiet = predicted & (healthy | np.array([s == "saturated" for s in status]))
        out = ~healthy & ~quiet
        newly = [i for i in np.flatnonzero(out) if not self.excluded[i]]
        problems = []
        if newly:
            i = newly[0]
            problems.append((SENSOR_FAULTS.get(status[i], "sensor_dead"),
                             f"sensor {i} reports {status[i]!r}; excluded"))
        self.excluded = out | quiet | self.latch.latched
        readings = np.where(self.excluded[:, None], np.nan, values)
        cold = self.reacquire
        if cold:
            self.reacquire = False
            self.estimator.reset()
        est = self.estimator.estimate(readings, currents)
        ok = bool(est.ok)
        fde = tuple(int(k) for k in est.excluded_sensors)
        for k in self.latch.update(fde, ok):
            problems.append(("sensor_value", f"sensor {k} excluded by the estimator's fault "
                             f"detection in {self.latch.passes} trusted frames in a row; "
                             "left out from now on"))
        moment = np.asarray(est.moment_a_m2, float)
        if ok:
            self.position_m = np.asarray(est.position_m, float).copy()
            self.moment = moment
            self.background_t = np.asarray(est.background_t, float)
        else:
            problems.append(("lost", est.reason or "the estimator does not trust its pose"))
        cov = est.position_covariance_m2
        return Fix(np.asarray(est.position_m, float).copy(), moment.copy(), ok,
                   float(frame.t_s), tuple(problems), self.excluded.copy(), self.clock() - t0,
                   None if cov is None else np.asarray(cov, float),
                   float(est.protection_level_m), cold, fde,
                   tuple(int(k) for k in np.flatnonzero(quiet)), est.reason,
                   np.asarray(est.background_t, float))

    def _bad_frame(self, frame) -> str:
        """Why ``frame`` cannot be fitted ('' when it can): the shapes."""
        try:
            shape = np.shape(frame.readings_t)
            n_status = len(frame.status)
            float(frame.t_s)
        except (TypeError, ValueError, AttributeError) as exc:
            return f"bad frame: {exc}"
        if shape != (self.n, 3) or n_status != self.n:
            return (f"bad frame: readings of shape {shape} and {n_status} statuses (expected "
                    f"({self.n}, 3) and {self.n})")
        try:
            np.asarray(frame.readings_t, float)
        except (TypeError, ValueError) as exc:
            return f"bad frame: readings are not numbers ({exc})"
        return ""

    def _refused(self, frame, reason: str, t0: float) -> Fix:
        """A malformed frame is not fitted: not ok, with the reason; the next fit starts cold."""
        self.reacquire = True
        p = np.zeros(3) if self.position_m is None else self.position_m.copy()
        try:
            t = float(frame.t_s)
        except (TypeError, ValueError, AttributeError):
            t = float("nan")
        return Fix(p, self.moment.copy(), False, t, (("lost", reason),),
                   self.excluded.copy(), self.clock() - t0, reason=reason)
