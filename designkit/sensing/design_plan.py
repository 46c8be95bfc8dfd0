"""A design's sensor layout planned and judged: the boards and their sites (:mod:`.sites`), the
scenarios (:mod:`.region`), one response of every pose at every site and at the design's own
sensors, the search (:mod:`.planner`), and both layouts' bounds, summaries and headroom.

With two magnets the search minimizes the pairs' worst bound (a pair's bound is never below
one magnet's at the same place) and both layouts are also judged with one magnet. SI units.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import BadInputError
from ..model.array import array_for_design
from .crb import BoundSettings, pose_bound
from .maps import Layout, scenario_response, summary
from .planner import Plan, PlanSettings, minimum_count, plan_sensors
from .region import RegionSettings, magnet_pairs, one_magnet, one_magnet_of
from .response import Response
from .sites import (Headroom, board_outline_m, candidate_sites, design_boards, grid_xy, headroom,
                    user_board)

MAX_SITES = 4000
"""Candidate sites a plan may search (a finer --spacing is refused before any work: the
response is computed at every site for every magnet pose, minutes beyond this)."""
MAX_GRID_POINTS = 6 * MAX_SITES
"""Grid points on the boards before the headroom keeps the sites (the headroom's coupled field
at each point takes about a second per thousand): a finer --spacing is refused before it."""


@dataclass(frozen=True)
class PlanRequest:
    """What to plan: ``count`` sensors for ``magnets`` (1 or 2) magnets over ``region``, sites
    every ``spacing_m`` on the design's boards (or on one board at ``plane_m``), linear at
    ``max_current_a`` on every coil (None: the design's limit), bounds under ``bound``."""

    count: int
    magnets: int
    region: RegionSettings
    spacing_m: float = 0.010
    plane_m: float | None = None
    max_current_a: float | None = None
    bound: BoundSettings = field(default_factory=BoundSettings)
    search: PlanSettings | None = None


@dataclass
class PlanOutcome:
    """The plan and both layouts judged: ``layouts`` {'design', 'planned'}; ``bounds`` and
    ``summaries`` {scenario kind: {layout name: ...}}; ``headroom`` {layout name:
    :class:`.sites.Headroom` at the usable level}; ``boards_of`` {layout name: board name per
    sensor}; ``scenarios`` {kind: Scenarios}; ``sites``; ``plan``; ``max_current_a``."""

    layouts: dict
    bounds: dict
    summaries: dict
    headroom: dict
    boards_of: dict
    scenarios: dict
    sites: object
    plan: Plan
    max_current_a: float


def check_magnets(design, magnets: int, param: str = "--magnets") -> int:
    """1 or 2, and no more than the coils can serve (3 force rows a magnet)."""
    most = min(2, max(design.n_coils // 3, 1))
    if isinstance(magnets, bool) or magnets not in range(1, most + 1):
        raise BadInputError(param, f"{' or '.join(map(str, range(1, most + 1)))} (a design of {design.n_coils} coils serves "
                            f"{max(design.n_coils // 3, 1)} magnet(s): 3 force rows each; the "
                            "planner does 1 or 2)", magnets)
    return int(magnets)


def check_count(count: int, magnets: int, settings: BoundSettings,
                param: str = "--count") -> int:
    """At least ceil(P / 3) sensors for P unknowns."""
    need = minimum_count(magnets, settings)
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < need:
        p = settings.n_unknowns(magnets)
        raise BadInputError(param, f"at least {need} sensors for {magnets} magnet(s) "
                            f"({settings.magnet_dof} x {magnets}"
                            + (" + 3 background" if settings.background == "uniform" else "")
                            + f" = {p} unknowns, 3 readings a sensor)", count)
    return int(count)


def board_names(positions_m: np.ndarray, boards) -> list[str]:
    """The board each sensor lies on (within 1 mm of its height), else 'plane'."""
    out = []
    for z in np.asarray(positions_m)[:, 2]:
        hit = [b.name for b in boards if abs(b.height_m - z) < 1e-3]
        out.append(hit[0] if hit else "plane")
    return out


@dataclass(frozen=True)
class Prepared:
    """A checked request's coupled ``array``, ``boards``, the current every sensor must stay
    linear at (A), the candidate ``sites`` (:class:`.sites.Sites`) and the ``scenarios``
    (:func:`scenario_sets`)."""

    array: object
    boards: tuple
    max_current_a: float
    sites: object
    scenarios: dict


def _limit_spacing(spacing_m: float, count: int, limit: int, what: str, unit: str,
                   why: str) -> None:
    """Refuse a ``--spacing`` (m) that leaves ``count`` > ``limit`` of ``what`` (a board's
    points scale as 1 / spacing^2: the coarser spacing that fits is named)."""
    if count > limit:
        coarser = spacing_m * (count / limit) ** 0.5
        raise BadInputError("--spacing", f"a spacing that leaves at most {limit} {what} "
                            f"(here >= {coarser * 1e3:.2g} mm)",
                            f"{spacing_m * 1e3:g} mm ({count} {unit})", why)


def prepare(design, request: PlanRequest) -> Prepared:
    """The boards and their sites for ``request``, every refusal of it raised here (before any
    long work starts): the magnets, the count, the plane, a count above the sites left, a
    lattice or separation that leaves no scenario."""
    magnets = check_magnets(design, request.magnets)
    check_count(request.count, magnets, request.bound)
    array = array_for_design(design)
    boards = (design_boards(design) if request.plane_m is None else
              (user_board(design, array.coils, request.plane_m),))
    current = (design.drive.max_current_a if request.max_current_a is None
               else request.max_current_a)
    n_grid = len(grid_xy(*board_outline_m(design), request.spacing_m)) * len(boards)
    _limit_spacing(request.spacing_m, n_grid, MAX_GRID_POINTS, "grid points on the boards",
                   "points", "Each point's headroom is checked before the sites are kept.")
    level = request.bound.usable_fraction * request.bound.range_t
    sites = candidate_sites(design, array, boards, request.spacing_m, current, level)
    n_sites = len(sites.positions_m)
    _limit_spacing(request.spacing_m, n_sites, MAX_SITES, "candidate sites", "sites",
                   "The search's cost grows with the sites times the magnet poses.")
    if n_sites < request.count:
        raise BadInputError("--count", f"at most {len(sites.positions_m)} sensors (the sites "
                            f"left on the boards at a {request.spacing_m * 1e3:g} mm spacing "
                            f"within the headroom at {current:g} A; "
                            + ", ".join(f"{v} {k}" for k, v in sites.excluded.items())
                            + "; a finer "
                            "--spacing or a lower --max-current gives more)", request.count)
    return Prepared(array, tuple(boards), float(current), sites,
                    scenario_sets(design, request.region, magnets))


def plan_design(design, request: PlanRequest, bar=None,
                prepared: Prepared | None = None) -> PlanOutcome:
    """Plan ``request.count`` sensors for ``design`` and judge them against its own layout
    (``prepared``: :func:`prepare`'s result for this request, when the caller has it)."""
    ready = prepare(design, request) if prepared is None else prepared
    magnets, array, boards = request.magnets, ready.array, ready.boards
    current, level = ready.max_current_a, request.bound.usable_fraction * request.bound.range_t
    sites, scenarios = ready.sites, ready.scenarios
    pos, frames = design.sensor_poses()
    every = np.r_[sites.positions_m, pos]
    kind = "two magnets" if magnets == 2 else "one magnet"
    _say(bar, f"the field of {len(scenarios[kind].positions_m)} magnet poses at "
              f"{len(every)} sites")
    response = scenario_response(design, every, scenarios[kind], request.bound, array)
    _say(bar, f"search over {len(scenarios[kind].index)} scenarios")
    n = len(sites.positions_m)
    search_sites = Response(response.field_t[:n], response.jacobian[:n], response.tangents)
    settings = request.search or PlanSettings(count=request.count)
    plan = plan_sensors(search_sites, scenarios[kind].index, sites.frames, request.bound,
                        settings, bar)
    layouts = {"design": Layout("design", pos, frames),
               "planned": Layout("planned", sites.positions_m[plan.sites],
                                 sites.frames[plan.sites])}
    indices = {"design": np.arange(n, n + len(pos)), "planned": plan.sites}
    bounds, summaries = {}, {}
    for k, scen in scenarios.items():
        bounds[k] = {name: pose_bound(response, scen.index, indices[name], lay.frames,
                                      request.bound) for name, lay in layouts.items()}
        summaries[k] = {name: summary(b, scen) for name, b in bounds[k].items()}
    chosen = sites.headroom
    room = {"design": headroom(array, pos, frames, level),
            "planned": Headroom(chosen.worst_signs_a[plan.sites], chosen.one_coil_a[plan.sites],
                                chosen.coil[plan.sites])}
    return PlanOutcome(layouts, bounds, summaries, room,
                       {name: board_names(lay.positions_m, boards)
                        for name, lay in layouts.items()},
                       scenarios, sites, plan, current)


def scenario_sets(design, region: RegionSettings, magnets: int) -> dict:
    """{'one magnet': ..., 'two magnets': ... (when asked)} on shared poses."""
    ws = design.workspace_region()
    mags = design.magnets
    if magnets == 1:
        return {"one magnet": one_magnet(ws, region, mags[0].direction)}
    second = mags[1] if len(mags) > 1 else mags[0]
    pairs = magnet_pairs(ws, region, [mags[0].direction, second.direction])
    return {"one magnet": one_magnet_of(pairs), "two magnets": pairs}



def _say(bar, text: str) -> None:
    """The phase on the progress bar, when there is one."""
    if bar is not None:
        bar.set_postfix_str(text)
