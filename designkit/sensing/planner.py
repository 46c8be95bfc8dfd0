"""Place N Hall sensors on candidate sites to minimize the worst Cramer-Rao bound of the magnet
positions over a set of scenarios (:mod:`.region`).

Greedy selection, then exchange (Fedorov's: each chosen site in turn is taken out and the best
site put back), on a soft worst -- the power mean (mean v^p)^(1/p) of the scenarios' bounds v
(each the largest of its magnets' position rms), which follows the worst but still rewards the
rest -- then a last exchange on the worst itself. Adding a sensor is a rank-3 update of each
scenario's information, so a candidate's effect on every bound is one 3 x 3 inverse
(Woodbury). A weak prior (:data:`PRIOR_SD`) keeps the first steps defined; every reported
bound is computed without it. Many scenarios are handled by an active set: the plan is made on
a subset, the worst of the rest are added and the exchange repeated until the worst scenario is
in the set. Deterministic: the seed orders the exchange and picks the first subset.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import BadInputError
from .crb import BoundSettings, pose_bound, scenario_jacobians, usable_sensors
from .response import Response

PRIOR_SD = {"position_m": 1.0, "angle_rad": 10.0, "background_t": 1.0}
"""Standard deviations of the weak prior the search adds to every scenario's information."""
UNIT = {"position": 1e-3, "angle": 1.0, "background": 1e-3}
"""The search works in mm, rad and mT (the information matrices stay well scaled)."""


@dataclass(frozen=True)
class PlanSettings:
    """``count`` sensors; ``seed``; ``active_scenarios`` the active set's size;
    ``rounds`` of growing it; ``exchange_passes`` per round; ``power`` of the soft worst."""

    count: int
    seed: int = 0
    active_scenarios: int = 256
    rounds: int = 4
    exchange_passes: int = 3
    power: float = 8.0


@dataclass
class Plan:
    """``sites``: the chosen sites' indices, in the order chosen; ``worst_m``: the worst
    scenario's position rms bound over every scenario; ``history``: (phase, worst_m) after
    each phase."""

    sites: np.ndarray
    worst_m: float
    history: list = field(default_factory=list)


def minimum_count(n_magnets: int, settings: BoundSettings) -> int:
    """The fewest sensors (3 readings each) that can hold the unknowns: ceil(P / 3)."""
    return -(-settings.n_unknowns(n_magnets) // 3)


class Search:
    """The information of the active scenarios under a selection, and what a candidate adds."""

    def __init__(self, response: Response, scenarios: np.ndarray, frames: np.ndarray,
                 settings: BoundSettings):
        self.response, self.scenarios, self.frames = response, scenarios, frames
        self.settings = settings
        d, n = settings.magnet_dof, scenarios.shape[1]
        unit = [UNIT["position"]] * 3 + [UNIT["angle"]] * (d - 3)
        self.scale = np.array(unit * n + ([UNIT["background"]] * 3
                                          if settings.background == "uniform" else []))
        sd = [PRIOR_SD["position_m"]] * 3 + [PRIOR_SD["angle_rad"]] * (d - 3)
        prior = np.array(sd * n + ([PRIOR_SD["background_t"]] * 3
                                   if settings.background == "uniform" else [])) / self.scale
        self.prior = np.diag(1.0 / prior ** 2)
        self.pos = [np.arange(k * d, k * d + 3) for k in range(n)]
        self.set_active(np.arange(len(scenarios)))

    def set_active(self, active: np.ndarray) -> None:
        """Scenarios the search works on; their candidates' rows are made once here."""
        self.active = np.asarray(active, dtype=int)
        n_sites = self.response.field_t.shape[0]
        jac, field_t = scenario_jacobians(self.response, self.scenarios[self.active],
                                          np.arange(n_sites), self.settings)
        usable = usable_sensors(field_t, self.frames, self.settings)
        chip = np.einsum("sai,snap->snip", self.frames, jac)
        self.rows = chip * (usable[:, :, None, None] * self.scale
                            / np.sqrt(self.settings.variance_t2))

    def information(self, selection) -> np.ndarray:
        """(n_active, P, P) prior + the selected sites' information."""
        r = self.rows[np.asarray(selection, dtype=int)]
        return self.prior + np.einsum("snip,sniq->npq", r, r)

    def values(self, cov: np.ndarray, candidates: np.ndarray, chunk: int = 32) -> np.ndarray:
        """(n_candidates, n_active): each scenario's bound (largest position rms over its
        magnets, mm) once the candidate is added to the selection of covariance ``cov``."""
        tr = np.stack([np.einsum("nii->n", cov[:, p][:, :, p]) for p in self.pos], axis=1)
        out = np.empty((len(candidates), len(self.active)))
        eye = np.eye(3)
        for a in range(0, len(candidates), chunk):
            u = self.rows[candidates[a:a + chunk]]            # (c, n, 3, P)
            v = u @ cov[None]                                  # (c, n, 3, P)
            s_inv = np.linalg.inv(eye + v @ np.swapaxes(u, -1, -2))
            red = np.stack([np.einsum("cnij,cnjk,cnik->cn", s_inv, v[..., p],
                                      v[..., p]) for p in self.pos], axis=-1)
            out[a:a + chunk] = np.sqrt(np.maximum(tr[None] - red, 0.0)).max(axis=-1)
        return out


def aggregate(values: np.ndarray, power: float | None) -> np.ndarray:
    """The soft worst (power mean) along the last axis; ``power`` None: the worst."""
    if power is None:
        return values.max(axis=-1)
    top = values.max(axis=-1, keepdims=True)
    return top[..., 0] * np.mean((values / top) ** power, axis=-1) ** (1.0 / power)


def best_addition(search: Search, selection: list, power, exclude=()) -> tuple[int, float]:
    """The candidate site whose addition to ``selection`` gives the lowest aggregate, and it."""
    cov = np.linalg.inv(search.information(selection))
    taken = set(selection) | set(exclude)
    cand = np.array([s for s in range(len(search.rows)) if s not in taken], dtype=int)
    obj = aggregate(search.values(cov, cand), power)
    k = int(np.argmin(obj))
    return int(cand[k]), float(obj[k])


def current_objective(search: Search, selection: list, power) -> float:
    cov = np.linalg.inv(search.information(selection[:-1]))
    return float(aggregate(search.values(cov, np.array(selection[-1:])), power)[0])


def exchange(search: Search, selection: list, power, rng, bar=None) -> bool:
    """One pass of exchange over ``selection`` (in a seeded order), in place; True when a site
    changed."""
    changed = False
    current = current_objective(search, selection, power)
    for i in rng.permutation(len(selection)):
        rest = selection[:i] + selection[i + 1:]
        site, obj = best_addition(search, rest, power)
        if site != selection[i] and obj < current * (1 - 1e-9):
            selection[i], current, changed = site, obj, True
        if bar is not None:
            bar.update(1)
    return changed


def plan_sensors(response: Response, scenarios: np.ndarray, frames: np.ndarray,
                 settings: BoundSettings, plan: PlanSettings, bar=None) -> Plan:
    """Choose ``plan.count`` of the response's sites (chip ``frames`` (n_sites, 3, 3)) for the
    scenarios (n_scenarios, n_magnets) pose indices; ``bar``: a progress bar (update(n))."""
    n_sites = response.field_t.shape[0]
    need = minimum_count(scenarios.shape[1], settings)
    if not need <= plan.count <= n_sites:
        raise BadInputError("count", f"{need} to {n_sites} sensors ({settings.n_unknowns(scenarios.shape[1])} "
                            f"unknowns need {need}; {n_sites} candidate sites)", plan.count)
    rng = np.random.default_rng(plan.seed)
    search = Search(response, scenarios, frames, settings)
    n = len(scenarios)
    if n > plan.active_scenarios:
        search.set_active(np.sort(rng.permutation(n)[:plan.active_scenarios]))
    selection: list[int] = []
    for _ in range(plan.count):
        selection.append(best_addition(search, selection, plan.power)[0])
        if bar is not None:
            bar.update(1)
    result = Plan(np.array(selection), np.inf)
    result.history.append(("greedy", worst_bound(response, scenarios, selection, frames,
                                                 settings)))
    for rnd in range(plan.rounds):
        for _ in range(plan.exchange_passes):
            if not exchange(search, selection, plan.power, rng, bar):
                break
        exchange(search, selection, None, rng, bar)
        bound = pose_bound(response, scenarios, selection, frames[selection], settings)
        worst = bound.position_rms_m.max(axis=1)
        result.history.append((f"exchange {rnd + 1}", float(worst.max())))
        missing = np.setdiff1d(np.argsort(worst)[::-1][:max(plan.active_scenarios // 4, 1)],
                               search.active)
        if int(np.argmax(worst)) in set(search.active.tolist()) or not len(missing):
            break
        search.set_active(np.union1d(search.active, missing))
    result.sites = np.array(selection)
    result.worst_m = result.history[-1][1]
    return result


def worst_bound(response, scenarios, selection, frames, settings) -> float:
    """The largest position rms bound over every scenario and magnet, m."""
    b = pose_bound(response, scenarios, selection, frames[np.asarray(selection)], settings)
    return float(b.position_rms_m.max())
