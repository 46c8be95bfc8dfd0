"""Several finger magnets from one frame of the Hall sensors: :class:`MagnetsEstimator`.

    est = MagnetsEstimator(model, design.magnets)          # or .from_map(path, magnets)
    fit = est.estimate(readings_t, currents_a, seeds=[pose_a, pose_b])   # seeds optional
    for m in fit.magnets:                                  # the design's magnet order
        if m.ok: m.position_m, m.moment_a_m2               # trusted: identity and pose

The joint fit of every present magnet (:mod:`.magnets_fit`: the fields superposed, 5 unknowns a
magnet and the background) with integrity per magnet; warm from the seeds (a tracker's
predictions: a seed's index is its magnet's identity, its covariance a prior observation) or
from the last trusted poses, else the cold acquisition and the identities by the nearest
references (:mod:`.magnets_locate`). A magnet is not ok when the frame does not show it (it
left; it is re-acquired when it comes back), when it is too close to another for the sensors
to separate them (its protection level beyond the alert limit while it would be within alone),
or when its identity is unknown (identical magnets and no seed or trusted history). With one
magnet the fix is :class:`.model_estimator.ModelEstimator`'s. Never raises on a frame.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import BadInputError
from .calibration import SensorCalibration
from .estimate import Estimate, Pose
from .frame import check_currents, check_readings
from .magnets_estimate import MagnetsEstimate
from .magnets_fit import (MAGNET_UNKNOWNS, JointState, JointVerdict, MagnetSpec, MagnetsFit,
                          spec_model)
from .magnets_locate import FrameData, acquire, assign, moved_m, warm
from .model_estimator import ModelEstimator
from .pose import tangent_axes
from .pose_fit import State
from .sensor_model import SensorModel
from .settings import EstimatorSettings


def magnet_specs(magnets, names=None) -> tuple:
    """The :class:`.magnets_fit.MagnetSpec` of each magnet: anything with ``radius_m``,
    ``length_m`` and ``moment_a_m2`` (|m| or the moment vector, A m^2), e.g. a
    :class:`firmware_io.cylinder_magnet.CylinderMagnet` or a design's magnet; ``names``
    (default 'magnet 0', ...)."""
    try:
        mags = list(magnets)
    except TypeError:
        raise BadInputError("magnets", "a sequence of >= 1 magnet specs",
                            type(magnets).__name__) from None
    if not mags:
        raise BadInputError("magnets", "a sequence of >= 1 magnet specs", "empty")
    names = [f"magnet {k}" for k in range(len(mags))] if names is None else list(names)
    if len(names) != len(mags) or len(set(names)) != len(names):
        raise BadInputError("names", f"{len(mags)} distinct names", names)
    specs = []
    for k, m in enumerate(mags):
        try:
            size = float(np.linalg.norm(np.asarray(m.moment_a_m2, float)))
            a, length = float(m.radius_m), float(m.length_m)
        except (AttributeError, TypeError, ValueError):
            raise BadInputError(f"magnets[{k}]", "radius_m, length_m (m) and moment_a_m2 "
                                "(A m^2)", type(m).__name__) from None
        if not all(math.isfinite(x) and x > 0 for x in (size, a, length)):
            raise BadInputError(f"magnets[{k}]", "|moment| > 0 A m^2, radius and length > 0 m",
                                (size, a, length))
        specs.append(MagnetSpec(size, a, length, str(names[k])))
    return tuple(specs)


class MagnetsEstimator:
    """N magnets' poses from one frame (module docstring).

    Parameters
    ----------
    model : SensorModel (the sensors, the coils' field there, the cores' relay)
    magnets : sequence of N >= 1 magnet specs in the design's magnet order
        (:func:`magnet_specs`)
    settings : EstimatorSettings (default: its defaults; for N > 1 the direction is fitted,
        |m| is the spec's -- other choices are refused -- and the gradient is not fitted)
    calibration : SensorCalibration, a path to a saved one, or None
    names : the magnets' names (default 'magnet 0', ...)
    """

    method = "model"

    def __init__(self, model: SensorModel, magnets, settings: EstimatorSettings | None = None,
                 calibration=None, *, names=None):
        if not isinstance(model, SensorModel):
            raise BadInputError("model", "a SensorModel", type(model).__name__)
        self.model = model
        self.specs = magnet_specs(magnets, names)
        self.settings = settings if settings is not None else EstimatorSettings()
        if calibration is not None and not isinstance(calibration, (SensorCalibration, tuple)):
            calibration = SensorCalibration.load(calibration)
        self.single = None
        self.fit = None
        if len(self.specs) == 1:
            self.single = ModelEstimator(self._one_model(), self.settings,
                                         calibration=calibration)
            self.calibration = self.single.calibration
        else:
            self.fit = MagnetsFit(model, self.specs, self.settings, calibration)
            self.calibration = self.fit.calibration
        self.last: list = [None] * len(self.specs)     # last trusted State, warm starts
        self.history: list = [None] * len(self.specs)  # last trusted position, identities
        self.last_b = np.zeros(3)

    @classmethod
    def from_map(cls, path, magnets, settings: EstimatorSettings | None = None,
                 calibration=None, *, names=None,
                 expected_design_sha256: str | None = None) -> "MagnetsEstimator":
        """The estimator of a v2 map file's sensors (:meth:`SensorModel.from_map`)."""
        model = SensorModel.from_map(path, expected_design_sha256=expected_design_sha256)
        return cls(model, magnets, settings, calibration, names=names)

    def _one_model(self) -> SensorModel:
        """The model with the one magnet's spec (the model itself when it already has it)."""
        spec, m = self.specs[0], self.model
        same = (math.isclose(spec.moment_a_m2, float(np.linalg.norm(m.moment_a_m2)),
                             rel_tol=1e-9) and m.magnet_size_m is not None
                and np.allclose(m.magnet_size_m, (spec.radius_m, spec.length_m), rtol=1e-9))
        if same:
            return m
        return spec_model(m, spec)

    @property
    def n_magnets(self) -> int:
        return len(self.specs)

    @property
    def names(self) -> tuple:
        return tuple(s.name for s in self.specs)

    def reset(self) -> None:
        """Forget the warm starts and the identities' history: the next frame starts cold."""
        self.last = [None] * self.n_magnets
        self.history = [None] * self.n_magnets
        self.last_b = np.zeros(3)
        if self.single is not None:
            self.single.reset()

    # -- one frame -------------------------------------------------------------------------
    def estimate(self, readings_t, currents_a, *, usable=None, seeds=None,
                 time_s: float | None = None) -> MagnetsEstimate:
        """The magnets' poses from one frame; never raises on the frame's contents.

        readings_t : (n_sensors, 3) T, each sensor in its own frame, NaN = unusable
        currents_a : (n_coils,) A
        usable : (n_sensors,) bool, optional
        seeds : None or N entries (Pose | None): each magnet's prediction (identity: index)
        time_s : the frame's time (accepted for the interface; unused)
        """
        try:
            readings = check_readings(readings_t, self.model.n_sensors, usable)
            currents = check_currents(currents_a, self.model.n_coils)
            seeds = self._check_seeds(seeds)
        except BadInputError as exc:
            # the warm starts are forgotten (as the single-magnet estimator's); the identities'
            # history is kept: one bad frame does not make the magnets anonymous
            self.last = [None] * self.n_magnets
            if self.single is not None:
                self.single.reset()
            return self._refused(f"bad frame: {exc}")
        try:
            if self.single is not None:
                return self._one(readings, currents, seeds)
            return self._fit(readings, currents, seeds)
        except (ArithmeticError, np.linalg.LinAlgError, ValueError) as exc:
            self.reset()
            return self._refused(f"numerical failure: {exc}")

    def _check_seeds(self, seeds):
        """The seeds as a list of N (Pose | None), or BadInputError."""
        if seeds is None:
            return None
        n = self.n_magnets
        try:
            seeds = list(seeds)
        except TypeError:
            raise BadInputError("seeds", f"None or {n} entries (Pose or None)",
                                type(seeds).__name__) from None
        if len(seeds) != n:
            raise BadInputError("seeds", f"None or {n} entries (Pose or None), one a magnet",
                                f"{len(seeds)} entries")
        for k, s in enumerate(seeds):
            if s is None:
                continue
            if not isinstance(s, Pose):
                raise BadInputError(f"seeds[{k}]", "a Pose or None", type(s).__name__)
            p, m = np.asarray(s.position_m, float), np.asarray(s.moment_a_m2, float)
            if (p.shape != (3,) or m.shape != (3,) or not np.all(np.isfinite(p))
                    or not np.all(np.isfinite(m)) or not np.linalg.norm(m) > 0):
                raise BadInputError(f"seeds[{k}]", "finite position (3,) m and non-zero "
                                    "moment (3,) A m^2", (p.tolist(), m.tolist()))
            if s.covariance is not None:
                c = np.asarray(s.covariance, float)
                if (c.shape != (5, 5) or not np.all(np.isfinite(c))
                        or not np.all(np.linalg.eigvalsh(0.5 * (c + c.T)) > 0)):
                    raise BadInputError(f"seeds[{k}].covariance", "a positive definite (5, 5)",
                                        f"shape {c.shape}")
        return seeds

    def _fallback(self, k: int) -> np.ndarray:
        if self.history[k] is not None:
            return self.history[k].copy()
        return 0.5 * (np.asarray(self.model.box_lower_m) + np.asarray(self.model.box_upper_m))

    def _moment(self, k: int, u=None) -> np.ndarray:
        u0 = self.model.moment_a_m2 / float(np.linalg.norm(self.model.moment_a_m2))
        return self.specs[k].moment_a_m2 * (u0 if u is None else u)

    def _refused(self, reason: str) -> MagnetsEstimate:
        return MagnetsEstimate.refused(
            [Estimate.refused(self._fallback(k), self._moment(k), reason, self.method)
             for k in range(self.n_magnets)], reason)

    def _one(self, readings, currents, seeds) -> MagnetsEstimate:
        """N = 1: the single-magnet estimator's fix."""
        fix = self.single.fit(readings, currents, None if seeds is None else seeds[0], None)
        if fix.ok:
            self.history[0] = fix.position_m.copy()
        return MagnetsEstimate((fix,), fix.excluded_sensors, fix.consistent,
                               fix.background_t.copy(), fix.chi2, fix.dof,
                               "" if fix.ok else f"{self.specs[0].name}: {fix.reason}",
                               (None,), (None,))

    def _fit(self, readings, currents, seeds) -> MagnetsEstimate:
        fit = self.fit
        d, use, sigma, field = fit.frame(readings, currents)
        blocks = np.flatnonzero(use)
        need = -(-(fit.n_unknowns(1) + 1) // 3)
        if len(blocks) < need:
            return self._refused(f"only {len(blocks)} usable sensors (need {need})")
        frame = FrameData(d, np.where(use, 1.0 / sigma, 0.0), np.nan_to_num(field), blocks)
        tried = self._warm(frame, seeds)
        if tried is not None and tried[1]:
            return self._result(tried[0], (), tried[2], len(blocks))
        best = None if tried is None else tried[0]
        cold = acquire(fit, frame, self.n_magnets)
        unknown = ()
        if cold is not None:
            cold, unknown = assign(fit, frame, cold, self._references(seeds))
            if best is None or cold.rank() <= best.rank():
                best = cold
            else:
                unknown = ()
        if best is None:
            return self._refused("no magnet found: the global search found no start")
        return self._result(best, unknown, False, len(blocks))

    def _warm(self, frame: FrameData, seeds):
        """(verdict, accepted, prior used) of the warm fit, or None without a start: from every
        seed when all are given (accepted when consistent with a prior, when trusted without),
        else from the last trusted poses (accepted when all are trusted and none moved
        farther than ``reacquire_m``)."""
        fit = self.fit
        if seeds is not None and all(s is not None for s in seeds):
            start = fit.start(range(self.n_magnets), [s.position_m for s in seeds],
                              [s.moment_a_m2 for s in seeds], self.last_b)
            priors = [s if s.covariance is not None else None for s in seeds]
            v = warm(fit, frame, start, priors)
            with_prior = any(p is not None for p in priors)
            accepted = v.consistent if with_prior else v.ok
            return v, accepted, with_prior and accepted
        if seeds is not None or not any(s is not None for s in self.last):
            return None
        ids = tuple(k for k in range(self.n_magnets) if self.last[k] is not None)
        start = JointState(ids, tuple(self.last[k] for k in ids), self.last_b)
        v = warm(fit, frame, start, [None] * self.n_magnets)
        return v, v.ok and moved_m(start, v.solution.state) <= self.settings.reacquire_m, False

    def _references(self, seeds) -> list:
        """Each magnet's reference position for the identities: its seed's, else its last
        trusted one, else None."""
        return [np.asarray(seeds[k].position_m, float) if seeds is not None and seeds[k]
                is not None else self.history[k] for k in range(self.n_magnets)]

    def _result(self, v: JointVerdict, unknown: tuple, prior_used: bool,
                n_used: int) -> MagnetsEstimate:
        """The estimate of every magnet from the verdict; updates the warm starts and the
        identities' history."""
        st = v.solution.state
        found = dict(zip(st.ids, range(len(st.ids))))
        excluded = tuple(sorted(v.excluded))
        out, reasons = [], []
        for k in range(self.n_magnets):
            if k not in found:
                why = ("not found: the frame is explained without it (it left, or its field "
                       "is below the noise)" if v.consistent else
                       f"not found: {v.reason or 'the joint fit failed'}")
                out.append(Estimate.refused(self._fallback(k), self._moment(k), why,
                                            self.method))
                self.last[k] = None
                reasons.append(f"{self.specs[k].name}: {why}")
                continue
            j = found[k]
            est = self._magnet_estimate(v, j, k, j in unknown, prior_used, n_used)
            out.append(est)
            self.last[k] = st.poses[j] if est.ok else None
            if est.ok:
                self.history[k] = st.poses[j].p.copy()
            else:
                reasons.append(f"{self.specs[k].name}: {est.reason}")
        if v.consistent:
            self.last_b = st.b.copy()
        alone = [v.magnets[found[k]].frame if k in found else None
                 for k in range(self.n_magnets)]
        return MagnetsEstimate(tuple(out), excluded, v.consistent, st.b.copy(),
                               float(v.solution.chi2), v.dof,
                               "" if not reasons else v.reason or reasons[0],
                               tuple(None if a is None else a[0] for a in alone),
                               tuple(None if a is None else a[1] for a in alone))

    def _magnet_estimate(self, v: JointVerdict, j: int, k: int, unknown: bool,
                         prior_used: bool, n_used: int) -> Estimate:
        """Magnet k's estimate from the found magnet j of verdict ``v``."""
        st = v.solution.state
        pose: State = st.poses[j]
        m = v.magnets[j]
        reason = m.reason
        if not reason and unknown:
            reason = (f"identity unknown: another magnet makes the same field and no seed or "
                      f"trusted history tells which is {self.specs[k].name}")
        elif (m.reason and v.consistent and m.pl_m > self.settings.alert_limit_m
              and m.alone_m <= self.settings.alert_limit_m):
            near = self._nearest(st, j)
            reason += (f" -- too close to {near} for the sensors to separate them "
                       f"(alone its level would be {m.alone_m * 1e3:.3g} mm)")
        ok = v.consistent and not reason
        return Estimate(pose.p.copy(), self._moment(k, pose.u), ok, reason, m.covariance,
                        m.pl_m, m.pl_rad, tuple(sorted(v.excluded)), st.b.copy(),
                        float(v.solution.chi2), v.dof, n_used, v.solution.iterations,
                        self.method, tangent_axes(pose.u), None, v.consistent and not unknown,
                        m.free[0], m.free[1], prior_used)

    def _nearest(self, st: JointState, j: int) -> str:
        """The name and distance of the magnet nearest to found magnet j."""
        p = st.poses[j].p
        dist = [(float(np.linalg.norm(q.p - p)), i) for jj, (i, q) in
                enumerate(zip(st.ids, st.poses)) if jj != j]
        if not dist:
            return "another magnet"
        d, i = min(dist)
        return f"{self.specs[i].name} ({d * 1e3:.0f} mm away)"


__all__ = ["MagnetsEstimator", "MAGNET_UNKNOWNS", "magnet_specs"]
