"""How one frame's joint fit of several magnets starts and who is who: :func:`warm`,
:func:`acquire` and :func:`assign`.

- Warm: from the seeds (a tracker's predictions, their covariances as prior observations of
  each pose, as :mod:`.fix` uses one) or from the last trusted poses.
- Acquisition (cold): the global search (:class:`.search.GridSearch`) finds the strongest
  magnet; the magnets found so far are fitted jointly and their modelled fields subtracted;
  the search on what is left finds the next; the fit of all found so far is refined jointly
  (the search's best starts for the new one, the first consistent wins). It stops at the
  first count whose joint fit passes the residual test: a magnet whose field the frame does
  not show is not found (it left, or it is too far for the sensors).
- Identities: the found magnets are matched to the references (the seeds' positions, else the
  last trusted ones) by the assignment of least summed squared distance. An assignment is
  taken when every other is at least :data:`AMBIGUITY_RATIO` times worse; otherwise, for
  magnets whose fields differ, the joint fit of each close assignment decides by its chi2
  (by at least the chi-square(1) quantile at the integrity risk); magnets with the same field
  and no reference that tells them apart keep no identity (not ok, with the reason).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass

import numpy as np

from .integrity import chi2_quantile
from .magnets_fit import JointState, JointVerdict, MagnetsFit, judge

AMBIGUITY_RATIO = 4.0
"""An identity assignment is unambiguous when every other's summed squared distance to the
references is at least this many times its own (the magnets twice as close to their own
references, rms)."""

AMBIGUITY_FLOOR_M = 1e-3
"""Distance added to the best assignment's in the ratio test, m (magnets at their references
within a millimetre are not told apart by a ratio of two tiny numbers)."""

SEARCH_STARTS = 3
"""The global search's starts tried for each new magnet of an acquisition."""


@dataclass(frozen=True)
class FrameData:
    """One frame: data d (n, 3) T (0 where unusable), weights w (n,) 1 / sigma (0 where
    unusable), the readings a gain error would scale (n, 3) T, the usable sensors."""

    d: np.ndarray
    w: np.ndarray
    reading: np.ndarray
    blocks: np.ndarray

    @property
    def judged(self) -> tuple:
        return self.d, self.w, self.reading


def warm(fit: MagnetsFit, frame: FrameData, start: JointState, priors) -> JointVerdict:
    """The verdict of the joint fit from ``start``; ``priors``: one per spec (a
    :class:`.estimate.Pose` with a covariance, or None), observations of those poses. When it
    fails the residual test and the exclusion cannot name a liar (a gross fault drags the
    solve), the sensor the start explains worst (:func:`worst_block`) is left out and the fit
    solved again from the start: the better verdict wins (that exclusion is judged as any)."""
    b = frame.blocks
    fit.set_priors(priors)
    try:
        sol = fit.solve(start, b, frame.w[b], frame.d[b])
        verdict = judge(fit, sol, frame.judged)
        if verdict.consistent or fit.settings.max_exclusions < 1 or verdict.dof <= 3:
            return verdict
        suspect = worst_block(fit, frame, start)
        if suspect is None:
            return verdict
        rest = b[b != suspect]
        again = judge(fit, fit.solve(start, rest, frame.w[rest], frame.d[rest]), frame.judged,
                      (suspect,))
        return again if again.rank() < verdict.rank() else verdict
    finally:
        fit.set_priors([None] * len(fit.engines))


def worst_block(fit: MagnetsFit, frame: FrameData, start: JointState) -> int | None:
    """The sensor whose reading the start explains worst, when the start cannot explain it
    (its whitened innovation, the robust (median) uniform background of all sensors taken
    out, beyond the residual test's chi-square(3) threshold), else None."""
    b = frame.blocks
    w = frame.w[b]
    _, res = fit.rows(start, b, w, frame.d[b])
    rb = res[:3 * len(b)].reshape(len(b), 3)
    if fit.background:
        rb = rb - w[:, None] * np.median(rb / w[:, None], axis=0)
    r2 = np.einsum("bi,bi->b", rb, rb)
    j = int(np.argmax(r2))
    return int(b[j]) if r2[j] > fit.chi2_max[3] else None


def acquire(fit: MagnetsFit, frame: FrameData, n_max: int) -> JointVerdict | None:
    """The cold acquisition of up to ``n_max`` magnets (module docstring); the found magnets
    carry the placeholder identities 0 .. k - 1 (:func:`assign` gives the real ones). None
    when the search finds nothing."""
    b = frame.blocks
    w, db = frame.w[b], frame.d[b]
    weights = frame.w ** 2
    residual = frame.d
    state, best = None, None
    for k in range(1, n_max + 1):
        new = None
        for p0, m0 in fit.search.starts(residual, weights, fit.background, SEARCH_STARTS):
            pose = fit.engines[k - 1].initial_state(p0, m0)
            st = (JointState((0,), (pose,), np.zeros(3)) if state is None else
                  JointState(tuple(range(k)), state.poses + (pose,), state.b))
            v = judge(fit, fit.solve(st, b, w, db, cold=True), frame.judged)
            if new is None or v.rank() < new.rank():
                new = v
            if v.consistent:
                break
        if new is None:
            return best
        best = new
        if new.consistent:
            return new
        state = new.solution.state
        used = frame.w > 0
        residual = np.where(used[:, None], frame.d - fit.fields(state).sum(axis=0), 0.0)
    return best


def assignment_costs(found: np.ndarray, refs, n: int) -> list:
    """[(cost m^2, ids)] of every injective assignment of the found positions (k, 3) to the
    identities 0 .. n - 1, best first: the summed squared distance to the references ``refs``
    (n entries, (3,) m or None: no reference, no cost)."""
    out = []
    for ids in itertools.permutations(range(n), len(found)):
        cost = sum(float(np.sum((found[j] - refs[i]) ** 2)) for j, i in enumerate(ids)
                   if refs[i] is not None)
        out.append((cost, ids))
    out.sort(key=lambda c: c[0])
    return out


def assign(fit: MagnetsFit, frame: FrameData, verdict: JointVerdict, refs):
    """(the verdict with the found magnets' identities, the indices of the found magnets
    whose identity is unknown) (module docstring)."""
    st = verdict.solution.state
    costs = assignment_costs(st.positions(), refs, len(fit.specs))
    best_cost, best_ids = costs[0]
    close = [ids for cost, ids in costs
             if cost <= AMBIGUITY_RATIO * (best_cost + AMBIGUITY_FLOOR_M ** 2)]
    if len(close) > 1:
        judged = [(_relabeled(fit, frame, verdict, ids), ids) for ids in close]
        judged.sort(key=lambda v: v[0].solution.chi2)
        margin = chi2_quantile(fit.settings.integrity_risk, 1)
        best, best_ids = judged[0]
        unknown = set()
        for v, ids in judged[1:]:
            if v.solution.chi2 - best.solution.chi2 <= margin:
                unknown |= {j for j in range(len(ids)) if ids[j] != best_ids[j]}
        return best, tuple(sorted(unknown))
    return _relabeled(fit, frame, verdict, best_ids), ()


def _relabeled(fit: MagnetsFit, frame: FrameData, verdict: JointVerdict, ids) -> JointVerdict:
    """The verdict with the found magnets given identities ``ids``: relabeled when their specs
    make the same fields as the placeholders', else the joint fit solved again with theirs."""
    st = verdict.solution.state
    same = all(fit.specs[i].same_field(fit.specs[j]) for i, j in zip(ids, st.ids))
    if same:
        sol = verdict.solution
        new = JointState(tuple(ids), st.poses, st.b)
        return JointVerdict(dataclasses.replace(sol, state=new),
                            verdict.consistent, verdict.reason, verdict.magnets, verdict.dof,
                            verdict.excluded)
    start = JointState(tuple(ids), tuple(fit.engines[i].initial_state(p.p, p.u)
                                         for i, p in zip(ids, st.poses)), st.b)
    b = frame.blocks[~np.isin(frame.blocks, verdict.excluded)]
    return judge(fit, fit.solve(start, b, frame.w[b], frame.d[b]), frame.judged,
                 verdict.excluded)


def moved_m(start: JointState, end: JointState) -> float:
    """The largest move of a magnet between two states with the same identities, m."""
    if start.ids != end.ids:
        return math.inf
    return max((float(np.linalg.norm(a.p - b.p)) for a, b in zip(start.poses, end.poses)),
               default=0.0)
