"""The rendering region: where the finger magnet can be above the array (SI: m).

The rendering objective is judged over the design's workspace (:meth:`Design.workspace_region`)
where it lies over the coils: its outline clipped to the hull of the coils' top-face centres
(beyond the outer axes no coil pushes up without pulling sideways), from the lowest height the
magnet reaches above the sensor boards and frame (:func:`designkit.rules.reachable_height_m`)
to the design height. :func:`fold_points` keeps one point of each set the array's mirror
symmetries (of coil positions and axes together) map onto each other.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .. import rules
from ..design import Design
from ..design.layouts import grown_hull
from ..rules import clip_polygon

INSIDE_TOLERANCE_M = 1e-9
"""A sample this close outside the clipped outline counts as inside, m (vertices, edges)."""


def render_outline(design: Design) -> np.ndarray:
    """The workspace outline over the coils (k, 2) m: clipped to the hull of the coils'
    top-face centres (the whole outline when they span no area)."""
    outline = design.workspace_region().outline
    tops = design.array.top_centres_m()[:, :2]
    if len(np.unique(np.round(tops, 12), axis=0)) < 3:
        return outline
    hull = grown_hull(tops, 0.0)
    clipped = np.round(clip_polygon(outline, hull), 12) + 0.0  # a grid's corners exactly
    return clipped if len(clipped) >= 3 else outline


def workspace_region(design: Design, *, heights_m: Sequence[float] | None = None,
                     n_xy: int = 3) -> np.ndarray:
    """Points of the rendering region, (n, 3) m: an n_xy x n_xy grid over the bounding box of
    :func:`render_outline` (for the 3 x 3 thesis array: +/- one pitch, the inner array), the
    points inside it, at ``heights_m`` (default: the lowest height the magnet reaches, at
    least workspace.z_min_m, and the design height)."""
    outline = render_outline(design)
    if heights_m is None:
        reach = rules.reachable_height_m(design)
        heights_m = (max(design.workspace.z_min_m, reach), design.optimize.height_m)
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    X, Y, Z = np.meshgrid(np.linspace(lo[0], hi[0], n_xy), np.linspace(lo[1], hi[1], n_xy),
                          np.asarray(heights_m, dtype=float), indexing="ij")
    pts = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    e = np.roll(outline, -1, axis=0) - outline
    cross = (e[None, :, 0] * (pts[:, None, 1] - outline[None, :, 1])
             - e[None, :, 1] * (pts[:, None, 0] - outline[None, :, 0]))
    inside = np.all(cross / np.linalg.norm(e, axis=1)[None, :] >= -INSIDE_TOLERANCE_M, axis=1)
    return pts[inside]


def fold_points(points_m: np.ndarray, tops_m: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """The distinct points under the mirror symmetries the array has (x -> -x, y -> -y,
    x <-> y, each applied to the coils' top centres (n, 3) m and axes (n, 3) together):
    symmetric points see the same forces, so each is solved once, m."""
    pts = np.array(points_m, dtype=float)
    poses = np.c_[np.asarray(tops_m, dtype=float), np.asarray(axes, dtype=float)]

    def key(a):
        return set(map(tuple, np.round(a, 12) + 0.0))  # + 0.0: -0.0 -> 0.0

    def same(mapped):
        return key(mapped) == key(poses)

    flip = {"x": [-1.0, 1.0, 1.0] * 2, "y": [1.0, -1.0, 1.0] * 2}
    if same(poses * flip["x"]):
        pts[:, 0] = np.abs(pts[:, 0])
    if same(poses * flip["y"]):
        pts[:, 1] = np.abs(pts[:, 1])
    if same(poses[:, [1, 0, 2, 4, 3, 5]]):
        pts[:, :2] = np.sort(pts[:, :2], axis=1)
    return np.unique(np.round(pts, 12), axis=0)
