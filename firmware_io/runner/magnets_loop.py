"""The control loop for N magnets: one track (tracker and gate) per magnet, each magnet its own
contact with the scene, one bounded allocation of the stacked force rows, the pair force
compensated, and the safe state for N.

:class:`MagnetsRunner` is :class:`~firmware_io.runner.loop.Runner` (the faults, resume policy,
current path, thermal guard and drive are the same code) with N lanes: each frame's
:class:`~firmware_io.runner.magnets_pipeline.MagnetsFix` gives each magnet's fix to its own
lane (gate, protection level, freshness: :meth:`Runner._accept`, :meth:`Runner._freshness`),
the scene's force is evaluated at each predicted position, and the currents come from
:mod:`firmware_io.runner.magnets_force`'s weighted stack.

The safe state for N (docs/runner.md, "Several magnets"): the coils render only while EVERY
magnet has a trusted, fresh track inside the map's box; any magnet lost, gated, stale or out of
the box switches every coil off. The coils' field acts on every magnet in the workspace, so
currents allocated for the trusted magnets push the untrusted one by up to the coils' full
authority, and its pull on the others (0.1-0.5 N at 40-26 mm for the thesis magnets) is
unknown -- an untrusted magnet is not provably far. With one magnet this is the runner's rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import BadInputError
from ..magnet_pair import MagnetPairs
from .forcelaw import force_law_matrix, torque_matrix
from .frames import SensorFrame
from .gate import InnovationGate
from .loop import Runner, RunnerIO, StepRecord
from .magnets_force import bias_scale, condition_number, magnet_weights, stacked_rows
from .magnets_pipeline import MagnetsPipeline
from .tracker import PoseTracker


@dataclass(frozen=True)
class MagnetsSettings:
    """The magnets the runner renders on and how (SI).

    names : tuple of str -- in the design's magnet order
    radii_m, lengths_m : tuple of float, m -- each cylinder (for the pair force)
    moments_a_m2 : tuple of (3,) A m^2 -- each magnet's nominal moment (until a fix gives one)
    weights : tuple of float or None -- the priority of each magnet's force rows (weighted
        least squares; None: 1 each, :mod:`firmware_io.runner.magnets_force`)
    compensate_pair : bool -- subtract the magnets' direct pull on each other from the targets
    start_positions_m : tuple of (3,) m or None -- where each magnet is expected before its
        first trusted fix (the fingers' places at the start): the estimator's reference for
        which magnet is which (identical magnets are told apart only by where they are); the
        sensor side seeds a magnet without a track from its last trusted position, else from
        this (None: no reference)
    """

    names: tuple
    radii_m: tuple
    lengths_m: tuple
    moments_a_m2: tuple
    weights: tuple | None = None
    compensate_pair: bool = True
    start_positions_m: tuple | None = None

    def __post_init__(self):
        n = len(self.names)
        if n < 1 or len(set(self.names)) != n:
            raise BadInputError("magnets.names", "one or more distinct names", self.names)
        for key in ("radii_m", "lengths_m", "moments_a_m2"):
            if len(getattr(self, key)) != n:
                raise BadInputError(f"magnets.{key}", f"{n} entries, one per magnet",
                                    len(getattr(self, key)))
        magnet_weights(self.weights, n)
        if self.start_positions_m is not None:
            p = np.asarray(self.start_positions_m, float)
            if p.shape != (n, 3) or not np.all(np.isfinite(p)):
                raise BadInputError("magnets.start_positions_m", f"({n}, 3) finite positions, m",
                                    self.start_positions_m)

    @classmethod
    def of_specs(cls, specs, weights=None, compensate_pair: bool = True,
                 start_positions_m=None) -> "MagnetsSettings":
        """From magnet specs with ``name``, ``radius_m``, ``length_m`` and
        ``moment_vector_a_m2`` (a design's ``magnets``)."""
        specs = list(specs)
        starts = (None if start_positions_m is None else
                  tuple(tuple(float(c) for c in p) for p in start_positions_m))
        return cls(tuple(s.name for s in specs), tuple(float(s.radius_m) for s in specs),
                   tuple(float(s.length_m) for s in specs),
                   tuple(tuple(float(c) for c in s.moment_vector_a_m2) for s in specs),
                   None if weights is None else tuple(weights), compensate_pair, starts)


@dataclass(frozen=True)
class IntegrityTerms:
    """What the multi-frame protection level takes from the estimator: its integrity risk per
    fix and its model-bias bound, m (:func:`firmware_io.runner.gate.
    rendered_protection_level`)."""

    integrity_risk: float
    model_bias_m: float

    @classmethod
    def of(cls, estimator) -> "IntegrityTerms":
        """From an estimator's ``settings`` (``EstimatorSettings``) and ``calibration``."""
        s = estimator.settings
        return cls(float(s.integrity_risk),
                   float(s.model_bias_for(estimator.calibration is not None)))


@dataclass
class MagnetLane:
    """One magnet's track: its tracker and gate, whether it has an accepted fix and when it
    was taken (s)."""

    name: str
    index: int
    tracker: PoseTracker = field(default_factory=PoseTracker)
    gate: InnovationGate | None = None
    have_fix: bool = False
    accepted_at_s: float = -math.inf


@dataclass
class MagnetsStepRecord(StepRecord):
    """A step of :class:`MagnetsRunner`: the first magnet's values in the
    :class:`~firmware_io.runner.loop.StepRecord` fields, and every magnet's: predicted
    positions (N, 3) m (NaN: no track), object forces (N, 3) N, moments (N, 3) A m^2, torques
    (N, 3) N m of the commanded currents, the pair forces compensated (N, 3) N and the
    condition number of the stacked rows (0: not allocated)."""

    positions_m: np.ndarray = None
    forces_ref_n: np.ndarray = None
    moments_a_m2: np.ndarray = None
    torques_n_m: np.ndarray = None
    pair_forces_n: np.ndarray = None
    condition: float = 0.0


class MagnetsRunner(Runner):
    """The fail-safe loop for N magnets (module docstring).

    Parameters
    ----------
    fieldmap, io, config : as :class:`~firmware_io.runner.loop.Runner`
    scene : object -- ``forces(positions_m (N, 3), velocities_m_s (N, 3)) -> (N, 3)`` N, each
        magnet's own contact (:class:`~firmware_io.runner.loop.SceneForce`)
    estimator : the N-magnet estimator (``estimate(readings_t, currents_a, usable=, seeds=,
        time_s=) -> .magnets``, ``reset()``, ``settings``, ``calibration``:
        :class:`IntegrityTerms`)
    magnets : MagnetsSettings
    allocate : callable, optional -- as :class:`Runner`'s
    """

    def __init__(self, fieldmap, scene, estimator, io: RunnerIO, config, magnets:
                 MagnetsSettings, *, allocate=None):
        super().__init__(fieldmap, scene, estimator, io, config, allocate=allocate)
        self.magnets = magnets
        self.integrity = IntegrityTerms.of(estimator)
        n = len(magnets.names)
        self.weights = magnet_weights(magnets.weights, n)
        self.equal_weights = bool(np.all(self.weights == 1.0))
        self.nominal = np.asarray(magnets.moments_a_m2, float).reshape(n, 3)
        self.lanes = [MagnetLane(name, k, PoseTracker(), InnovationGate(config.gate_risk))
                      for k, name in enumerate(magnets.names)]
        self.tracker, self.gate = self.lanes[0].tracker, self.lanes[0].gate
        self.pairs = MagnetPairs(magnets.radii_m, magnets.lengths_m, names=magnets.names)
        self.pipeline = MagnetsPipeline(estimator, self.layout, self.history.at, self.nominal,
                                        magnets.names, magnets.start_positions_m)
        self.positions_m = np.full((n, 3), np.nan)
        self.torques_n_m = np.zeros((n, 3))
        self.pair_n = np.zeros((n, 3))
        self.condition = 0.0
        attach = getattr(io.sensors, "attach", None)
        if attach is not None:
            attach(self.pipeline)

    def start(self) -> None:
        """Warm the N-magnet allocation once (magnets spread along x about the box centre),
        then :meth:`Runner.start`."""
        n = len(self.lanes)
        centre = 0.5 * (self.lo + self.hi)
        span = 0.5 * (self.hi[0] - self.lo[0])
        ps = [centre + np.array([span * (k / max(n - 1, 1) - 0.5), 0.0, 0.0])
              for k in range(n)]
        self.allocate_forces(ps, [np.zeros(3)] * n, list(self.nominal))
        super().start()

    # -- the sensor side's results ------------------------------------------------------------
    def _take_fix(self, t_s: float) -> tuple[bool, list]:
        item = self.sensors(t_s)
        if isinstance(item, SensorFrame):
            item = self.pipeline.process(item)
        problems: list[tuple[str, str]] = []
        if item is None:
            return False, problems
        self._note_frame(item, t_s)
        problems.extend(item.problems)
        accepted = []
        for fix, lane in zip(item.fixes, self.lanes):
            own: list = []
            accepted.append(self._accept(fix, t_s, own, lane))
            problems.extend((name, f"{lane.name}: {detail}") for name, detail in own)
            self.pipeline.tracks[lane.index] = lane.tracker.snapshot()
        self.last_estimate_ok = all(accepted)
        self.accepted_in_row = self.accepted_in_row + 1 if all(accepted) else 0
        return True, problems

    def _forget_track(self, lane) -> None:
        self.pipeline.tracks[lane.index] = None

    # -- the step ------------------------------------------------------------------------------
    def _step(self, t_s: float, t0: float) -> MagnetsStepRecord:
        """One control step at ``t_s`` (s) for every magnet up to the coils' write
        (:meth:`Runner.step` runs it); never raises for a device fault or a bad frame."""
        self.history.push(t_s, self.path.current_a)
        new_frame, problems = self._take_fix(t_s)
        for lane in self.lanes:
            if lane.tracker.x is not None:
                own: list = []
                self._freshness(t_s, own, lane)
                problems.extend((name, f"{lane.name}: {d}") for name, d in own)
        n = len(self.lanes)
        nan = np.full((n, 3), np.nan)
        if not all(lane.have_fix for lane in self.lanes):
            # the safe state for N: a magnet without a trusted track -> every coil off
            problems[:0] = self._thermal_problem([])
            if problems and (self.fault is None or problems[0][0] != self.fault):
                self._enter_fault(t_s, *problems[0])
            return self._off(t_s, t0, nan, np.zeros((n, 3)), new_frame)
        ps = [np.asarray(lane.tracker.predict(t_s), float) for lane in self.lanes]
        vs = [np.asarray(lane.tracker.x[1], float) for lane in self.lanes]
        ms = self._moments()
        self.positions_m = np.array(ps)
        self.position_m = ps[0]
        for p, lane in zip(ps, self.lanes):
            if not (np.all(p >= self.lo) and np.all(p <= self.hi)):
                problems.append(("out_of_box", f"{lane.name}: estimate "
                                 f"{np.round(p * 1e3, 1).tolist()} mm outside the map box"))
        self._thermal_problem(problems)
        if self._still_off(t_s, problems):
            return self._off(t_s, t0, self.positions_m, np.zeros((n, 3)), new_frame)
        f_refs = np.asarray(self.scene.forces(self.positions_m, np.array(vs)), float)
        command = self.allocate_forces(ps, f_refs, ms)
        if command is None:
            self._enter_fault(t_s, "lost", "the estimates of two magnets overlap")
            return self._off(t_s, t0, self.positions_m, f_refs, new_frame)
        if self._over_limit(t_s, command):
            return self._off(t_s, t0, self.positions_m, f_refs, new_frame)
        rec = self._drive(t_s, t0, ps[0], f_refs[0], command, new_frame)
        return self._extend(rec, self.positions_m, f_refs)

    def _moments(self) -> list:
        """Each magnet's moment rendered on, A m^2: its track's, else the nominal one."""
        return [self.nominal[k] if lane.tracker.moment_a_m2 is None
                else lane.tracker.moment_a_m2.copy() for k, lane in enumerate(self.lanes)]

    def allocate_forces(self, ps, f_refs, ms) -> np.ndarray | None:
        """Currents (n,) A rendering ``f_refs`` (N, 3) N on the magnets at ``ps`` (N, 3) m with
        moments ``ms`` (N, 3) A m^2 (:mod:`firmware_io.runner.magnets_force`); sets the torques,
        the pair forces and the condition number. None when two estimates overlap."""
        cfg = self.cfg
        rows, targets, fields = [], [], []
        for p, f, m in zip(ps, f_refs, ms):
            a = self.map.actuation(p)
            rows.append(force_law_matrix(m) @ a[3:])
            targets.append(np.subtract(f, bias_scale(m, self.moment) * self.map.bias_force(p)))
            fields.append(a[:3])
        pair = np.zeros((len(ps), 3))
        if self.magnets.compensate_pair and len(ps) > 1:
            try:
                pair = self.pairs.forces(np.array(ps), np.array(ms))[0]
            except BadInputError:
                return None
        targets = [t - q for t, q in zip(targets, pair)]
        if self.z_only:
            rows, targets = [r[2:3] for r in rows], [t[2:3] for t in targets]
        fm, target = stacked_rows(rows, targets, self.weights)
        # unweighted: the weights scale whole rows; with equal weights the stack is the same
        self.condition = condition_number(fm if self.equal_weights else np.concatenate(rows))
        i, g = self._currents_for(fm, target, self.limit, {"unipolar": cfg.unipolar}, None)
        self.pair_n = pair
        self.torques_n_m = np.array([torque_matrix(m) @ (b @ g) for m, b in zip(ms, fields)])
        self.torque_n_m = self.torques_n_m[0]
        return i

    def _off(self, t_s, t0, positions, f_refs, new_frame) -> MagnetsStepRecord:
        self.torques_n_m = np.zeros_like(self.torques_n_m)
        self.condition = 0.0
        rec = self._record(t_s, t0, positions[0], f_refs[0], new_frame, off=True)
        return self._extend(rec, positions, f_refs)

    def _extend(self, rec: StepRecord, positions, f_refs) -> MagnetsStepRecord:
        return MagnetsStepRecord(**vars(rec), positions_m=np.array(positions, float),
                                 forces_ref_n=np.array(f_refs, float),
                                 moments_a_m2=np.array(self._moments()),
                                 torques_n_m=self.torques_n_m.copy(),
                                 pair_forces_n=self.pair_n.copy(), condition=self.condition)
