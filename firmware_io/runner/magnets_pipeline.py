"""The sensor side for N magnets: one :class:`~firmware_io.runner.frames.SensorFrame` -> one
:class:`MagnetsFix` (a :class:`~firmware_io.runner.frames.Fix` per magnet).

The same checks as one magnet's :class:`~firmware_io.runner.pipeline.SensorPipeline` (each
sensor's health, the headroom rule with every magnet's dipole at its last trusted pose, the
latched liars), then one fit of all the magnets together by the N-magnet estimator
(``firmware_io.localization.MagnetsEstimator``: ``estimate(readings_t, currents_a, usable=,
seeds=, time_s=) -> .magnets``, a tuple of N ``Estimate`` in the design's magnet order), each
magnet seeded with its own track's prediction at the frame's time: identity is carried by the
seed's index. A magnet is trusted only on the estimator's own verdict (its ``ok``): the
single-magnet acquisition rule (trust on the fault-free protection level) is not applied to N
magnets. docs/runner.md, "Several magnets".
"""

from __future__ import annotations

from collections.abc import Callable
import time

import numpy as np

from ..localization import multipole_field
from .frames import Fix, SensorFrame
from .headroom import SensorLayout, expected_saturation
from .pipeline import SensorPipeline


class MagnetsFix:
    """One frame's result for N magnets: ``fixes`` (tuple of N :class:`Fix`, the design's
    magnet order) and what they share (the frame time s, the sensor problems, the sensors left
    out and those fault detection excluded, the fit's compute time s). ``frame_t_s``,
    ``problems``, ``fault_excluded``, ``saturating`` as on a :class:`Fix`."""

    __slots__ = ("fixes", "frame_t_s", "problems", "fault_excluded", "saturating", "fit_s")

    def __init__(self, fixes, frame_t_s, problems, fault_excluded=(), saturating=(),
                 fit_s=0.0):
        self.fixes = tuple(fixes)
        self.frame_t_s = float(frame_t_s)
        self.problems = tuple(problems)
        self.fault_excluded = tuple(fault_excluded)
        self.saturating = tuple(saturating)
        self.fit_s = float(fit_s)

    @property
    def ok(self) -> bool:
        """Every magnet trusted."""
        return all(f.ok for f in self.fixes)


class MagnetsPipeline(SensorPipeline):
    """The sensor side for N magnets (module docstring).

    Parameters
    ----------
    estimator : the N-magnet estimator (module docstring)
    layout : SensorLayout -- the sensors in the estimator's order
    currents_at : callable -- ``currents_at(t_s) -> (n_coils,)`` A at a frame's time
    moments_a_m2 : (N, 3) A m^2 -- each magnet's moment until the estimator finds one
    names : sequence of N str -- what the problems call each magnet (default its index)
    clock : callable, s

    ``tracks``: each magnet's newest :class:`~firmware_io.runner.tracker.TrackedPose` (or None),
    set by the runner; ``reacquire`` makes the next fit start cold (every magnet).
    """

    def __init__(self, estimator, layout: SensorLayout, currents_at: Callable,
                 moments_a_m2, names=None, clock: Callable[[], float] = time.perf_counter):
        moments = np.asarray(moments_a_m2, float).reshape(-1, 3)
        super().__init__(estimator, layout, currents_at, moments[0], clock)
        self.names = [str(k) for k in range(len(moments))] if names is None else list(names)
        self.moments = moments.copy()
        self.tracks: list = [None] * len(moments)
        self.positions: list = [None] * len(moments)

    def expected_saturation(self, currents_a: np.ndarray) -> np.ndarray:
        """(n_sensors,) bool: sensors the model puts beyond the headroom with the coils at
        ``currents_a`` (A) and every magnet at its last trusted pose (dipoles)."""
        if self.layout.coil_field_t_per_a is None:
            return np.zeros(self.n, dtype=bool)
        b = self.layout.predicted_t(currents_a, None, None, self.background_t)
        for p, m in zip(self.positions, self.moments):
            if p is not None:
                b = b + multipole_field(self.layout.positions_m, p, m)
        return expected_saturation(b)

    def process(self, frame: SensorFrame) -> MagnetsFix:
        """Checks, exclusions and the joint fit of one frame."""
        t0 = self.clock()
        bad = self._bad_frame(frame)
        if bad:
            refused = self._refused(frame, bad, t0)
            fixes = [Fix(np.zeros(3) if p is None else p.copy(), m.copy(), False,
                         refused.frame_t_s, (), refused.excluded, 0.0, reason=bad)
                     for p, m in zip(self.positions, self.moments)]
            return MagnetsFix(fixes, refused.frame_t_s, refused.problems, fit_s=refused.fit_s)
        readings, currents, problems, quiet = self._screen(frame)
        cold = self.reacquire
        if cold:
            self.reacquire = False
            self.estimator.reset()
        t = float(frame.t_s)
        seeds = [None if (cold or tr is None) else tr.prior(t) for tr in self.tracks]
        fit = self.estimator.estimate(readings, currents, seeds=seeds, time_s=t)
        fde = tuple(sorted(int(k) for k in fit.excluded_sensors))
        bg = np.asarray(fit.background_t, float)
        fixes = []
        for i, est in enumerate(fit.magnets):
            fixes.append(self._magnet_fix(i, est, t, cold, fde))
            if not est.ok:
                problems.append(("lost", f"{self.names[i]}: {est.reason or 'not trusted'}"))
        if any(f.ok for f in fixes):
            self.background_t = bg
        saturating = tuple(int(k) for k in np.flatnonzero(quiet))
        return MagnetsFix(fixes, t, problems, fde, saturating, self.clock() - t0)

    def _magnet_fix(self, i: int, est, t_s: float, cold: bool, fde: tuple) -> Fix:
        """Magnet i's :class:`Fix` from its estimate (trusted on its own ``ok``)."""
        ok = bool(est.ok)
        moment = np.asarray(est.moment_a_m2, float)
        if ok:
            self.positions[i] = np.asarray(est.position_m, float).copy()
            self.moments[i] = moment
        cov = est.covariance
        return Fix(np.asarray(est.position_m, float).copy(), moment.copy(), ok, t_s, (),
                   self.excluded.copy(), 0.0,
                   None if cov is None else np.asarray(cov, float)[:3, :3],
                   float(est.protection_level_m), cold, fde, (),
                   "" if ok else est.reason, np.asarray(est.background_t, float),
                   None if cov is None else np.asarray(cov, float).copy(),
                   False, bool(est.prior_used), False)
