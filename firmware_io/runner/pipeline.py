"""The sensor side of the runner: one :class:`~firmware_io.runner.frames.SensorFrame` -> one
:class:`~firmware_io.runner.frames.Fix`.

Run by the sensor thread (:class:`firmware_io.run.ThreadedSensorSource`) on the controller and
with the same timing by designkit.sim's simulated source. For each frame (fields in T, NaN
where unusable, each sensor's driver status) it excludes the unhealthy sensors, those the model
predicts beyond :data:`~firmware_io.runner.headroom.EXPECTED_SATURATION` of their linear range
at the frame's currents and pose, and those latched out, then runs the pose estimator with the
coil currents of the frame's own time (:class:`~firmware_io.runner.history.CurrentHistory`)
and, while the control step tracks the finger, its tracker's prediction at that time as the
prior (:class:`~firmware_io.runner.tracker.TrackedPose`). Without a track it acquires
(:class:`Acquisition`). It never raises on a bad frame. Fault names, the exclusion policy and
why acquisition keeps integrity: docs/runner.md ("Priors and acquisition").
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import BadInputError
from ..hw.tlv493d import TLV493D_LINEAR_RANGE_T
from ..localization.integrity import chi2_quantile
from .frames import Fix, SensorFrame
from .headroom import SensorLayout, expected_saturation
from .sensor_faults import SENSOR_FAULTS, ExclusionLatch


@dataclass(frozen=True)
class Acquisition:
    """When a fix the estimator does not trust is trusted on its fault-free protection level:
    how the runner acquires (a cold frame with one sensor per coil is rarely trusted on its own:
    the undetected single-sensor fault's term; docs/localization.md, "Integrity") and how a
    weak prior grows into a strong one.

    Such a fix passed every test but the alert limits (``Estimate.consistent``), its fault-free
    protection levels are within the estimator's alert limits, it uses no suspect sensor, and
    the sensors were checked at most ``hold_s`` before its frame: at the start, by a fix the
    estimator trusted with a prior and without naming a liar (there a bounded fault on any
    used sensor is detected or its effect bounded), or by a frame without a magnet that the
    coils' field and a uniform background explain (there an offset beyond the noise fails the
    residual test). A sensor the estimator's fault detection excluded is suspect: a fix that
    uses it is trusted only on the estimator's own verdict (and, if not, solved again without
    it), until a prior-aided fix the estimator trusts uses it or a check without a magnet
    clears it. What is left is a fault that begins within ``hold_s`` of a check, escapes every
    frame's test until then and sits where it moves a cold fix most: a sensor value fault is
    rare, so the exposure (its rate times the window) stays small with a window of a minute.
    While a track exists, a fix solved cold (the frame rejected the track's prior) counts only
    when it lies farther from the prior than its own protection level (which bounds any
    bounded fault's effect) plus ``jump_sigmas`` of the prior's sd: the finger moved. A prior
    whose sd is at least the fix's protection level (an acquiring track's first far guess)
    says less than the fix and counts as none.

    A suspect also clears after ``clear_passes`` frames in a row whose fit used it, passed the
    residual test and named no one: the naming was transient (a pass whose reads straddle a
    move of the finger), and a fault that escapes the test that often is one the test bounds.

    hold_s : s; jump_risk : the probability that a correct prior lies beyond ``jump_sigmas``
        (chi-square(3)); clear_passes : frames
    """

    hold_s: float = 60.0
    jump_risk: float = 1e-4
    clear_passes: int = 5

    def __post_init__(self):
        if not (isinstance(self.hold_s, (int, float)) and 0 <= self.hold_s < math.inf):
            raise BadInputError("hold_s", "a time >= 0 s", self.hold_s)
        if not (isinstance(self.jump_risk, (int, float)) and 0 < self.jump_risk < 0.5):
            raise BadInputError("jump_risk", "a probability in (0, 0.5)", self.jump_risk)
        if not (isinstance(self.clear_passes, int) and 1 <= self.clear_passes <= 1000):
            raise BadInputError("clear_passes", "an integer in [1, 1000] frames",
                                self.clear_passes)

    @property
    def jump_sigmas(self) -> float:
        return math.sqrt(chi2_quantile(self.jump_risk, 3))


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
    acquisition : Acquisition (default: its defaults)

    ``track``: the control step's newest :class:`~firmware_io.runner.tracker.TrackedPose` (or
    None: no track), set by the runner; each frame is fitted with its prior at the frame time.
    """

    def __init__(self, estimator, layout: SensorLayout, currents_at: Callable,
                 moment_a_m2, clock: Callable[[], float] = time.perf_counter,
                 acquisition: Acquisition | None = None):
        self.estimator, self.layout = estimator, layout
        self.acquisition = acquisition if acquisition is not None else Acquisition()
        self.track = None
        self.checked_s: float | None = None   # the sensors' last check (None: the start's)
        self.n = layout.n_sensors
        self.suspect = np.zeros(self.n, dtype=bool)   # excluded by fault detection, not cleared
        self.clean = np.zeros(self.n, dtype=int)      # a suspect's frames in a row found agreeing
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
        readings, currents, problems, quiet = self._screen(frame)
        cold = self.reacquire
        if cold:
            self.reacquire = False
            self.estimator.reset()
        track = None if cold else self.track
        t = float(frame.t_s)
        if self.checked_s is None:
            self.checked_s = t      # the start-up check (docs/runner.md)
        seed = track.prior(t) if track is not None else None
        est, fde, named, (candidate, acquired) = self._fit(readings, currents, seed, t)
        ok = bool(est.ok) or acquired
        vouched = np.flatnonzero(np.isfinite(readings).all(axis=1)) if ok else ()
        vouched = [k for k in vouched if k not in fde]
        for k in self.latch.update(named, bool(est.ok or est.consistent), vouched):
            problems.append(("sensor_value", f"sensor {k} excluded by the estimator's fault "
                             f"detection in {self.latch.passes} frames, no trusted fix using "
                             "it in between; left out from now on"))
        moment = np.asarray(est.moment_a_m2, float)
        if ok:
            self.position_m = np.asarray(est.position_m, float).copy()
            self.moment = moment
            self.background_t = np.asarray(est.background_t, float)
        else:
            problems.append(("lost", est.reason or "the estimator does not trust its pose"))
        cov = est.covariance
        pl = (est.fault_free_protection_level_m if acquired else est.protection_level_m)
        return Fix(np.asarray(est.position_m, float).copy(), moment.copy(), ok, t,
                   tuple(problems), self.excluded.copy(), self.clock() - t0,
                   None if cov is None else np.asarray(cov, float)[:3, :3], float(pl), cold,
                   fde, tuple(int(k) for k in np.flatnonzero(quiet)),
                   "" if ok else est.reason, np.asarray(est.background_t, float),
                   None if cov is None else np.asarray(cov, float).copy(),
                   acquired, bool(est.prior_used), candidate and not acquired)

    def _screen(self, frame: SensorFrame):
        """The frame's health and headroom checks: (readings (n_sensors, 3) T with NaN where a
        sensor is left out, the modelled currents (n_coils,) A at the frame's time, the sensor
        problems it raises, the sensors left out for predicted saturation (bool))."""
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
        return readings, currents, problems, quiet

    def _fit(self, readings: np.ndarray, currents, seed, t_s: float):
        """The estimate of one frame with the sensor side's trust: (estimate, the sensors fault
        detection excluded or left out as suspects, those the estimator named in this frame,
        (may it acquire, is it trusted) by :class:`Acquisition`). A fix
        the estimator does not trust that uses a suspect sensor is solved again without it;
        a fix the estimator trusts with a prior clears the suspects it used (its protection
        level covers their undetected bounded faults)."""
        est = self.estimator.estimate(readings, currents, seed=seed, time_s=t_s)
        named = tuple(int(k) for k in est.excluded_sensors)   # liars named in this frame
        fde = set(named)
        used = np.isfinite(readings).all(axis=1)
        used[list(fde)] = False
        self._count_agreement(est, used, named)
        left = self.suspect & used
        if not est.ok and est.consistent and left.any():
            again = self.estimator.estimate(readings, currents, usable=~left, seed=seed,
                                            time_s=t_s)
            if again.ok or again.consistent:
                est = again
                named = tuple(int(k) for k in again.excluded_sensors)
                fde = set(named) | {int(k) for k in np.flatnonzero(left)}
                used &= ~left
                used[[int(k) for k in again.excluded_sensors]] = False
        self.suspect[list(fde)] = True
        if est.ok and est.prior_used:
            self.suspect &= ~used
            if not named:
                self.checked_s = t_s        # a bounded fault on any used sensor would show
        candidate = self._candidate(est, seed, t_s) and not np.any(self.suspect & used)
        acquired = candidate and self._within_limits(est)
        if (seed is None and not est.ok and not est.consistent
                and self.estimator.magnet_free(readings, currents)):
            self.checked_s = t_s            # no magnet, and every sensor agrees with the others
            self.suspect &= ~used
        return est, tuple(sorted(fde)), named, (candidate, acquired)

    def _count_agreement(self, est, used: np.ndarray, named: tuple) -> None:
        """A transient naming ends: a suspect that an all-sensor fit used while it passed its
        residual test and named no one, in :attr:`Acquisition.clear_passes` frames in a row,
        is no longer suspect (a sensor named once while the finger moved between its reads
        would otherwise block acquisition for good). A naming or a failed test restarts the
        count of the sensors it concerns."""
        if est.consistent and not named:
            self.clean[self.suspect & used] += 1
        else:
            self.clean[list(named) if est.consistent else slice(None)] = 0
        cleared = self.suspect & (self.clean >= self.acquisition.clear_passes)
        self.suspect &= ~cleared
        self.clean[~self.suspect] = 0

    def _candidate(self, est, seed, t_s: float) -> bool:
        """May a fix the estimator does not trust be trusted on its fault-free protection
        levels (:class:`Acquisition`, its limits aside)?"""
        if est.ok or not est.consistent:
            return False
        if t_s - self.checked_s > self.acquisition.hold_s:
            return False
        if seed is None or est.prior_used:
            return True
        # the frame rejected the track's prior: a jump, unless a bounded fault could explain it;
        # a prior vaguer than the fix's own bound (an acquiring track's first guess) is no prior
        sd = math.sqrt(float(np.max(np.diag(seed.covariance)[:3])))
        if sd >= est.protection_level_m:
            return True
        far = float(np.linalg.norm(np.asarray(est.position_m, float) - seed.position_m))
        return far > est.protection_level_m + self.acquisition.jump_sigmas * sd

    def _within_limits(self, est) -> bool:
        """Are the fault-free protection levels within the estimator's alert limits?"""
        s = self.estimator.settings
        return est.fault_free_protection_level_m <= s.alert_limit_m and (
            est.orientation_axes is None
            or est.fault_free_orientation_protection_level_rad <= s.orientation_alert_limit_rad)

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
