"""The sensor side for N magnets: one :class:`~firmware_io.runner.frames.SensorFrame` -> one
:class:`MagnetsFix` (a :class:`~firmware_io.runner.frames.Fix` per magnet).

The same checks as one magnet's :class:`~firmware_io.runner.pipeline.SensorPipeline` (each
sensor's health, the headroom rule with every magnet's dipole at its last trusted pose, the
latched liars), then one fit of all the magnets together by the N-magnet estimator
(``firmware_io.localization.MagnetsEstimator``: ``estimate(readings_t, currents_a, usable=,
seeds=, time_s=) -> .magnets``, a tuple of N ``Estimate`` in the design's magnet order, and
``frame_positions_m``, ``frame_covariances_m2``: each magnet's position from the frame alone,
or None), each magnet seeded with its own track's prediction at the frame's time: identity is
carried by the seed's index; the track takes the frame-alone position where there is one. A magnet is trusted only on the estimator's own verdict (its ``ok``): the
single-magnet acquisition rule (trust on the fault-free protection level) is not applied to N
magnets. docs/runner.md, "Several magnets".
"""

from __future__ import annotations

from collections.abc import Callable
import time

import numpy as np

from ..localization import Pose, multipole_field
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
    starts : (N, 3) m or None -- each magnet's reference before its first trusted fix
        (:class:`~firmware_io.runner.magnets_loop.MagnetsSettings`)
    clock : callable, s

    ``tracks``: each magnet's newest :class:`~firmware_io.runner.tracker.TrackedPose` (or None),
    set by the runner; ``reacquire`` makes the next fit start cold (every magnet).
    """

    def __init__(self, estimator, layout: SensorLayout, currents_at: Callable,
                 moments_a_m2, names=None, starts=None,
                 clock: Callable[[], float] = time.perf_counter):
        moments = np.asarray(moments_a_m2, float).reshape(-1, 3)
        super().__init__(estimator, layout, currents_at, moments[0], clock)
        self.names = [str(k) for k in range(len(moments))] if names is None else list(names)
        self.moments = moments.copy()
        self.tracks: list = [None] * len(moments)
        self.positions: list = ([None] * len(moments) if starts is None else
                                [np.asarray(p, float) for p in starts])

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
        seeds = [self._seed(i, t, cold) for i in range(len(self.tracks))]
        fit = self.estimator.estimate(readings, currents, seeds=seeds, time_s=t)
        fde = tuple(sorted(int(k) for k in fit.excluded_sensors))
        bg = np.asarray(fit.background_t, float)
        fixes = []
        frame = list(fit.frame_positions_m), list(fit.frame_covariances_m2)
        for i, est in enumerate(fit.magnets):
            alone = ((frame[0][i], frame[1][i]) if i < min(map(len, frame))
                     and frame[0][i] is not None and frame[1][i] is not None else None)
            fixes.append(self._magnet_fix(i, est, t, cold, fde, alone))
            if not est.ok:
                problems.append(("lost", f"{self.names[i]}: {est.reason or 'not trusted'}"))
        if any(f.ok for f in fixes):
            self.background_t = bg
        saturating = tuple(int(k) for k in np.flatnonzero(quiet))
        return MagnetsFix(fixes, t, problems, fde, saturating, self.clock() - t0)

    def _seed(self, i: int, t_s: float, cold: bool):
        """Magnet i's seed: its track's prediction at ``t_s`` (a prior), else its last trusted
        position (or start) as a reference without a covariance (which magnet is which), else
        None."""
        tr = self.tracks[i]
        if tr is not None and not cold:
            return tr.prior(t_s)
        p = self.positions[i]
        return None if p is None else Pose(p.copy(), self.moments[i].copy(), None)

    def _magnet_fix(self, i: int, est, t_s: float, cold: bool, fde: tuple, alone) -> Fix:
        """Magnet i's :class:`Fix` from its estimate (trusted on its own ``ok``). ``alone``:
        None, or its position (3,) m and covariance (3, 3) m^2 from this frame's sensors alone
        (the seed's prior taken out): then the tracker takes those, not the fix that already
        holds its prediction (which would count the prediction twice)."""
        ok = bool(est.ok)
        moment = np.asarray(est.moment_a_m2, float)
        if ok:
            self.positions[i] = np.asarray(est.position_m, float).copy()
            self.moments[i] = moment
        cov = None if est.covariance is None else np.asarray(est.covariance, float).copy()
        p = np.asarray(est.position_m, float).copy()
        if alone is not None:
            p = np.asarray(alone[0], float).copy()
            if cov is None:
                cov = np.asarray(alone[1], float).copy()
            else:
                cov[:3, :3] = alone[1]
        return Fix(p, moment.copy(), ok, t_s, (), self.excluded.copy(), 0.0,
                   None if cov is None else cov[:3, :3], float(est.protection_level_m), cold,
                   fde, (), "" if ok else est.reason, np.asarray(est.background_t, float), cov,
                   False, bool(est.prior_used), not ok and bool(est.consistent))
