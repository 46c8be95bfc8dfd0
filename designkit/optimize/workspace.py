"""The rendering region: where the finger magnet can be above the array (SI: m).

The magnet's centre cannot go below the upper Hall-sensor board's top plus its half length
(:func:`designkit.rules.reachable_height_m`); :func:`workspace_region` samples the region the
rendering objective is judged on, and :func:`fold_points` keeps one point of each set the
array's mirror symmetries map onto each other.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .. import rules
from ..design import Design

def workspace_region(design: Design, *, half_width_m: float | None = None,
                     heights_m: Sequence[float] | None = None, n_xy: int = 3) -> np.ndarray:
    """Points of the rendering region, (n, 3) m: an n_xy x n_xy grid over +/- half_width_m
    (default: one pitch, the inner array) at ``heights_m`` (default: the lowest height the
    magnet reaches above the upper sensor board -- board top + magnet half length, at least
    workspace.z_min_m -- and the design height)."""
    hw = design.array.pitch_m if half_width_m is None else float(half_width_m)
    if heights_m is None:
        reach = rules.reachable_height_m(design)
        heights_m = (max(design.workspace.z_min_m, reach), design.optimize.height_m)
    xs = np.linspace(-hw, hw, n_xy)
    X, Y, Z = np.meshgrid(xs, xs, np.asarray(heights_m, dtype=float), indexing="ij")
    return np.c_[X.ravel(), Y.ravel(), Z.ravel()]


def fold_points(points_m: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """The distinct points under the mirror symmetries the array's centres have (x -> -x,
    y -> -y, x <-> y): symmetric points see the same forces, so each is solved once, m."""
    pts = np.array(points_m, dtype=float)
    c = np.asarray(centres, dtype=float)

    def key(a):
        return set(map(tuple, np.round(a, 12) + 0.0))  # + 0.0: -0.0 -> 0.0

    def same(mapped):
        return key(mapped) == key(c)

    if same(c * [-1.0, 1.0]):
        pts[:, 0] = np.abs(pts[:, 0])
    if same(c * [1.0, -1.0]):
        pts[:, 1] = np.abs(pts[:, 1])
    if same(c[:, ::-1].copy()):
        pts[:, :2] = np.sort(pts[:, :2], axis=1)
    return np.unique(np.round(pts, 12), axis=0)


