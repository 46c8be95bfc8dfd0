"""The magnet poses a sensor layout is judged over: one magnet anywhere in the workspace, or two
magnets side by side at a range of separations.

Positions lie on a lattice: the workspace's x-y grid (:meth:`designkit.design.workspace.
Workspace.grid_xy`, spacing ``spacing_m``) at heights every ``height_step_m`` from the lowest to
the highest asked (both included). A pair is two lattice points whose separation lies in the
asked range and whose offset points along x, y or a diagonal; the two may be at different
heights. Every magnet's moment keeps its design direction. SI units, array frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..errors import BadInputError

PAIR_DIRECTIONS_DEG = (0.0, 45.0, 90.0, 135.0)
"""Directions of a pair's offset in the x-y plane, degrees from +x."""


@dataclass(frozen=True)
class RegionSettings:
    """``heights_m`` (low, high) magnet-centre heights; ``spacing_m`` the lattice's x-y step;
    ``height_step_m`` its step in z; ``separation_m`` (low, high) of a pair's centres."""

    heights_m: tuple[float, float]
    spacing_m: float = 0.015
    height_step_m: float = 0.015
    separation_m: tuple[float, float] = (0.030, 0.060)


@dataclass(frozen=True)
class Scenarios:
    """``positions_m`` (n_poses, 3) and ``directions`` (n_poses, 3): every magnet pose used;
    ``index`` (n_scenarios, n_magnets): the poses estimated together in each scenario;
    ``kind`` 'one magnet' or 'two magnets'; ``separation_m`` (n_scenarios,) (0 for one)."""

    positions_m: np.ndarray
    directions: np.ndarray
    index: np.ndarray
    kind: Literal["one magnet", "two magnets"]
    separation_m: np.ndarray

    @property
    def n_magnets(self) -> int:
        return self.index.shape[1]

    def heights_m(self) -> np.ndarray:
        """(n_scenarios, n_magnets) each magnet's height, m."""
        return self.positions_m[self.index, 2]

    def centres_m(self) -> np.ndarray:
        """(n_scenarios, 3): the mean of each scenario's magnet positions, m."""
        return self.positions_m[self.index].mean(axis=1)


def height_levels(heights_m: tuple[float, float], step_m: float) -> np.ndarray:
    """Heights from low to high every ``step_m`` (the high one included), m."""
    lo, hi = heights_m
    n = max(int(math.floor((hi - lo) / step_m + 1e-9)), 0)
    levels = lo + step_m * np.arange(n + 1)
    return levels if hi - levels[-1] < 1e-9 else np.r_[levels, hi]


def lattice(workspace, settings: RegionSettings) -> np.ndarray:
    """(n, 3) lattice points of the workspace at the asked heights, m."""
    xy = workspace.grid_xy(settings.spacing_m)
    z = height_levels(settings.heights_m, settings.height_step_m)
    if len(xy) == 0:
        raise BadInputError("--lattice", "a lattice step that leaves points in the workspace",
                            f"{settings.spacing_m * 1e3:g} mm")
    return np.concatenate([np.c_[xy, np.full(len(xy), h)] for h in z])


def one_magnet(workspace, settings: RegionSettings, direction) -> Scenarios:
    """One magnet at every lattice point."""
    pts = lattice(workspace, settings)
    dirs = np.tile(np.asarray(direction, dtype=float), (len(pts), 1))
    return Scenarios(pts, dirs, np.arange(len(pts))[:, None], "one magnet", np.zeros(len(pts)))


def magnet_pairs(workspace, settings: RegionSettings, directions) -> Scenarios:
    """Two magnets (``directions`` (2, 3): the first's and the second's moment directions) on
    the lattice, separated by ``separation_m`` along x, y or a diagonal, each at any of the
    heights. Both orders of a pair at different heights are kept."""
    pts = lattice(workspace, settings)
    h = settings.spacing_m
    lo, hi = settings.separation_m
    offsets = []
    for deg in PAIR_DIRECTIONS_DEG:
        a = math.radians(deg)
        step = np.array([round(math.cos(a)), round(math.sin(a))])  # lattice steps
        unit = h * math.hypot(*step)
        for n in range(1, int(hi / unit + 1e-9) + 1):
            if lo - 1e-9 <= n * unit <= hi + 1e-9:
                offsets.append(n * step * h)
    if not offsets:
        raise BadInputError("--separation", "a range holding a multiple of the lattice step "
                            f"{h * 1e3:g} mm (--lattice) or of its diagonal",
                            f"{lo * 1e3:g}:{hi * 1e3:g} mm")
    key = {tuple(np.round(p * 1e9).astype(np.int64)): i for i, p in enumerate(pts)}
    z = np.unique(pts[:, 2])
    pairs, seps = [], []
    for i, p in enumerate(pts):
        for off in offsets:
            for zq in z:
                if zq < p[2] - 1e-12:
                    continue  # each unordered height pair once; both orders below
                q = np.array([p[0] + off[0], p[1] + off[1], zq])
                j = key.get(tuple(np.round(q * 1e9).astype(np.int64)))
                if j is None:
                    continue
                pairs.append((i, j))
                seps.append(float(np.hypot(*off)))
                if zq > p[2] + 1e-12:
                    # the same x-y places with the heights swapped
                    jp = key.get(tuple(np.round(np.r_[p[:2], zq] * 1e9).astype(np.int64)))
                    iq = key.get(tuple(np.round(np.r_[q[:2], p[2]] * 1e9).astype(np.int64)))
                    if jp is not None and iq is not None:
                        pairs.append((jp, iq))
                        seps.append(float(np.hypot(*off)))
    if not pairs:
        raise BadInputError("--separation", "a range that fits two magnets in the workspace "
                            f"(lattice step {h * 1e3:g} mm)", f"{lo * 1e3:g}:{hi * 1e3:g} mm")
    d = np.asarray(directions, dtype=float).reshape(2, 3)
    index = np.array(pairs, dtype=int).reshape(-1, 2)
    if np.allclose(d[0], d[1]):
        positions, dirs = pts, np.tile(d[0], (len(pts), 1))
    else:  # each magnet its own poses: the first magnet's, then the second's
        positions = np.r_[pts, pts]
        dirs = np.r_[np.tile(d[0], (len(pts), 1)), np.tile(d[1], (len(pts), 1))]
        index[:, 1] += len(pts)
    return Scenarios(positions, dirs, index, "two magnets", np.array(seps))


def one_magnet_of(pairs: Scenarios) -> Scenarios:
    """One magnet (the first magnet's direction) at every lattice point of ``pairs``, on the
    same poses (a response computed for the pairs serves both)."""
    first = pairs.directions[0]
    n = int(np.sum(np.all(np.isclose(pairs.directions, first), axis=1)))
    return Scenarios(pairs.positions_m, pairs.directions, np.arange(n)[:, None], "one magnet",
                     np.zeros(n))
