"""Where a board can carry a Hall sensor: the board planes, the sites on them, and the headroom
each site keeps at the currents the design allows.

The design's boards lie ``sensors.offset_m`` above the highest coil top face and below the
lowest bottom face (horizontal planes, the default layout's); a user may name another height
instead, above or below the coils and clear of the workspace. Sites form a square grid over the
boards' outline (the workspace's and the layout's footprint together); a site inside a coil's
winding or core is not one. Headroom: the coils' field at a sensor is linear in the currents,
B = C I (C from :meth:`designkit.model.array.CoilArray.actuation_matrix`, the coupled cores
included); with every coil at |I| and the worst signs a chip axis reads |I| sum_k |C_ak|, so the
sensor stays within ``level_t`` up to I = level_t / max_a sum_k |C_ak| (and one coil alone up to
level_t / max_a,k |C_ak|). Chips lie flat on a board, their axes the array's. SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import BadInputError
from ..model.overlap import coil_solids, sensor_inside


@dataclass(frozen=True)
class Board:
    """A horizontal board: ``name`` ('upper', 'lower' or 'plane') at ``height_m``."""

    name: str
    height_m: float


@dataclass(frozen=True)
class Headroom:
    """Per sensor: ``worst_signs_a`` the current on every coil (worst signs) that puts a chip
    axis at the level, A; ``one_coil_a`` the current one coil alone needs, A, and ``coil`` which
    (inf and -1 where no coil reaches the sensor)."""

    worst_signs_a: np.ndarray
    one_coil_a: np.ndarray
    coil: np.ndarray


@dataclass(frozen=True)
class Sites:
    """Candidate sensor sites: ``positions_m`` (n, 3), chip ``frames`` (n, 3, 3), ``board``
    (n,) index into ``boards``, their ``headroom``; ``excluded`` counts the grid points left
    out, by reason."""

    positions_m: np.ndarray
    frames: np.ndarray
    board: np.ndarray
    boards: tuple[Board, ...]
    headroom: Headroom
    excluded: dict


def coil_span_m(coils) -> tuple[float, float]:
    """Lowest and highest z (m) of every coil's winding and core, whatever their tilt."""
    lo, hi = math.inf, -math.inf
    for c in coils:
        axis = c.pose.matrix[:, 2]
        side = math.sqrt(max(0.0, 1.0 - axis[2] ** 2))
        for _, r, z0, z1 in coil_solids(c):
            mid = np.asarray(c.pose.position) + axis * 0.5 * (z0 + z1)
            reach = 0.5 * (z1 - z0) * abs(axis[2]) + r * side
            lo, hi = min(lo, mid[2] - reach), max(hi, mid[2] + reach)
    return lo, hi


def design_boards(design) -> tuple[Board, Board]:
    """The upper and lower boards: ``sensors.offset_m`` above the highest coil top-face centre
    and below the lowest bottom-face centre."""
    tops = np.array([np.asarray(p.position) + p.matrix[:, 2] * design.coil_spec(k).length_m / 2
                     for k, p in enumerate(design.coil_poses())])
    bottoms = np.array([np.asarray(p.position) - p.matrix[:, 2] * design.coil_spec(k).length_m
                        / 2 for k, p in enumerate(design.coil_poses())])
    off = design.sensors.offset_m
    return Board("upper", float(tops[:, 2].max() + off)), Board("lower",
                                                                float(bottoms[:, 2].min() - off))


def user_board(design, coils, height_m: float, param: str = "--plane") -> Board:
    """A board at ``height_m``, refused (one line naming ``param``) inside the coils' span or
    where the magnet moves (the workspace's heights, half a magnet beyond)."""
    lo, hi = coil_span_m(coils)
    ws = design.workspace
    half = max(m.length_m for m in design.magnets) / 2
    w_lo, w_hi = ws.z_min_m - half, ws.z_max_m + half
    if lo < height_m < hi:
        raise BadInputError(param, f"a height above {hi * 1e3:.4g} mm or below {lo * 1e3:.4g} "
                            f"mm (the coils and their cores span {lo * 1e3:.4g} to "
                            f"{hi * 1e3:.4g} mm)", f"{height_m * 1e3:g} mm")
    if w_lo < height_m < w_hi:
        raise BadInputError(param, f"a height outside {w_lo * 1e3:.4g} to {w_hi * 1e3:.4g} mm "
                            "(the workspace's heights, half a magnet beyond: the magnet moves "
                            "there)", f"{height_m * 1e3:g} mm")
    return Board("plane", float(height_m))


def board_outline_m(design) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper x-y corners (2,) m of the boards: the workspace's outline and the
    layout's footprint together."""
    pts = np.r_[np.asarray(design.workspace_region().outline), design.array.footprint_m()]
    return pts.min(axis=0), pts.max(axis=0)


def grid_xy(lo: np.ndarray, hi: np.ndarray, spacing_m: float) -> np.ndarray:
    """(n, 2) square grid of ``spacing_m`` over [lo, hi], symmetric about its centre, m."""
    axes = []
    for k in range(2):
        n = int(math.floor((hi[k] - lo[k]) / spacing_m + 1e-9))
        axes.append(0.5 * (lo[k] + hi[k]) + (np.arange(n + 1) - n / 2) * spacing_m)
    xx, yy = np.meshgrid(*axes, indexing="xy")
    return np.c_[xx.ravel(), yy.ravel()]


def saturation_currents(coil_field_t_per_a: np.ndarray, frames: np.ndarray,
                        level_t: float) -> Headroom:
    """:class:`Headroom` of sensors whose coils' field is ``coil_field_t_per_a`` (n, 3,
    n_coils) T/A in the array frame, read on chip axes ``frames`` (n, 3, 3)."""
    c = np.abs(np.einsum("sai,sak->sik", frames, coil_field_t_per_a))
    total = c.sum(axis=2).max(axis=1)
    flat = c.reshape(len(c), -1)
    best = flat.argmax(axis=1)
    one = flat[np.arange(len(c)), best]
    with np.errstate(divide="ignore"):
        worst = np.where(total > 0, level_t / np.where(total > 0, total, 1.0), math.inf)
        single = np.where(one > 0, level_t / np.where(one > 0, one, 1.0), math.inf)
    return Headroom(worst, single, np.where(one > 0, best % c.shape[2], -1))


def headroom(array, positions_m, frames, level_t: float) -> Headroom:
    """:class:`Headroom` of sensors at ``positions_m`` (n, 3) with ``frames`` in ``array``."""
    b = array.actuation_matrix(np.atleast_2d(positions_m))[:, :3, :]
    return saturation_currents(b, np.asarray(frames, dtype=float), level_t)


def candidate_sites(design, array, boards, spacing_m: float, max_current_a: float,
                    level_t: float) -> Sites:
    """The grid points of ``boards`` outside every winding and core that keep every chip axis
    within ``level_t`` with all coils at ``max_current_a`` (worst signs)."""
    lo, hi = board_outline_m(design)
    xy = grid_xy(lo, hi, spacing_m)
    pts = np.concatenate([np.c_[xy, np.full(len(xy), b.height_m)] for b in boards])
    which = np.repeat(np.arange(len(boards)), len(xy))
    inside = np.array([sensor_inside(array.coils, p) is not None for p in pts], dtype=bool)
    pts, which = pts[~inside], which[~inside]
    frames = np.tile(np.eye(3), (len(pts), 1, 1))
    room = headroom(array, pts, frames, level_t)
    keep = room.worst_signs_a >= max_current_a * (1 - 1e-9)
    excluded = {"inside a winding or core": int(inside.sum()),
                f"beyond the headroom at {max_current_a:g} A": int((~keep).sum())}
    room = Headroom(room.worst_signs_a[keep], room.one_coil_a[keep], room.coil[keep])
    return Sites(pts[keep], frames[keep], which[keep], tuple(boards), room, excluded)
