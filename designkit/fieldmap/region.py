"""The region of a scene map: the part of the workspace box where a scene's objects can push.

The scene's force laws (:mod:`firmware_io.scene`) are non-zero only where an object's signed
distance g(p) is at most the law's contact band (inside the object, or within the band outside
it). The region is the bounding box of those points of the design's box, sampled on a grid of
``spacing_m`` and widened by one grid step (so no such point is missed between nodes) plus
``margin_m``, clipped to the box. Outside it the runner, which refuses positions outside its
map's box, fails safe (coils off). Lengths in m.
"""

from __future__ import annotations

import numpy as np

from ..errors import BadInputError
from .plan import default_box, lattice_nodes, uniform_axis
from .settings import N_CHECK

SPACING_M = 0.002
"""Grid step (m) on which the objects' signed distances are sampled."""
MARGIN_M = 0.005
"""Default margin (m) around the objects' reach: the finger's approach and the localizer's
first fixes before contact."""
MIN_CHECK = 100
"""Fewest random check points of a scene map (its build's self-check, meta 'errors')."""


def scene_region(objects, band_m: float, lower, upper, margin_m: float = MARGIN_M,
                 spacing_m: float = SPACING_M) -> tuple[np.ndarray, np.ndarray]:
    """(lower (3,), upper (3,)) m: the box around the points of [lower, upper] where some
    object's signed distance is <= ``band_m`` (objects with ``signed_distance(points)``),
    widened by ``spacing_m`` + ``margin_m`` and clipped to [lower, upper].

    BadInputError when no object reaches into the box."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    pts = lattice_nodes([uniform_axis(lower[i], upper[i], spacing_m) for i in range(3)])
    near = within_reach(objects, pts, band_m)
    if not near.any():
        raise BadInputError("scene", "objects that reach into the map's box "
                            f"{np.round(lower * 1e3, 1).tolist()} .. "
                            f"{np.round(upper * 1e3, 1).tolist()} mm", "none does")
    grow = spacing_m + margin_m
    lo = np.maximum(pts[near].min(axis=0) - grow, lower)
    hi = np.minimum(pts[near].max(axis=0) + grow, upper)
    return lo, hi


def within_reach(objects, points, reach_m: float) -> np.ndarray:
    """(n,) bool: the points (n, 3) m where some object's signed distance is <= ``reach_m``."""
    near = np.zeros(len(points), bool)
    for obj in objects:
        near |= np.asarray(obj.signed_distance(points)) <= reach_m
    return near


def scene_band_m(scene) -> float:
    """The contact band (m) of a loaded scene's law (0 for the penetration law)."""
    law = scene.meta.get("law", {})
    return float(law.get("contact_band_m", 0.0)) if law.get("name") == "constraint" else 0.0


def scene_build_args(design, objects, band_m: float, margin_m: float = MARGIN_M,
                     region: dict | None = None) -> dict:
    """The keyword arguments of :func:`designkit.fieldmap.build` for the scene map of
    ``objects`` on ``design``: its box (:func:`scene_region` in the design's box), meta
    'region' (``region`` plus the margin) and its check points (:func:`scene_check_points`).
    Every other setting is the full map's: the sensor field's mode tables on the same steps
    give the same error in the region (docs/fieldmap.md, "Scene maps")."""
    full = default_box(design)
    box = scene_region(objects, band_m, *full, margin_m=margin_m)
    return {"box": box, "region": {**(region or {}), "margin_m": float(margin_m)},
            "n_check": scene_check_points(box, full)}


def scene_check_points(box, full_box) -> int:
    """The check points of a map over ``box`` (lower, upper) m: the full map's
    :data:`~designkit.fieldmap.settings.N_CHECK` over ``full_box`` at the same density, at least
    :data:`MIN_CHECK`."""
    vol = float(np.prod(np.subtract(box[1], box[0])))
    full = float(np.prod(np.subtract(full_box[1], full_box[0])))
    return int(min(N_CHECK, max(MIN_CHECK, np.ceil(N_CHECK * vol / full))))
