"""Coil layouts of a design file: where each coil's top face sits and where its axis points.

A layout is a named generator (:class:`GridLayout`, :class:`HexLayout`, :class:`RingLayout`) or
the general form (:class:`FreeLayout`); each gives, in the array frame (m, z up, the coil tops
of an upright array at z = 0):

* ``top_centres_m()`` (n, 3): the centre of each coil's top face, in the layout's coil order;
* ``axes()`` (n, 3): each coil's unit axis, from its bottom face to its top face (the direction
  of its field at positive current, :class:`designkit.design.MagnetSpec`'s polarity);
* ``footprint_m()`` (k, 2): the convex outline in x, y the workspace covers by default
  (:class:`designkit.design.workspace.Workspace`);
* ``describe()``: one line for titles and reports ("3 x 3 grid, pitch 50 mm").

Everything downstream reads these poses, never rows and columns.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import BadInputError
from ..geometry.pose import Pose

UNIT_TOLERANCE = 1e-6
"""Largest | |axis| - 1 | a free layout's axis may have: an axis is a direction, written as a
unit vector; anything else is refused with the unit vector it may have meant."""


def pose_on_axis(position, axis) -> Pose:
    """The pose at ``position`` (m) whose local +z is the unit ``axis``: the identity rotation
    for an upright axis (+z), else :meth:`Pose.from_axis`."""
    a = np.asarray(axis, dtype=float)
    if np.allclose(a, (0.0, 0.0, 1.0), rtol=0.0, atol=1e-12):
        return Pose(tuple(float(c) for c in position))
    return Pose.from_axis(tuple(float(c) for c in position), a)


def grown_hull(points_xy: np.ndarray, margin_m: float) -> np.ndarray:
    """Convex hull of points (n, 2) m, each edge moved out by ``margin_m`` (mitred corners),
    counter-clockwise vertices (k, 2) m, rounded to 1e-12 m (so that a grid's outline is
    exactly rows x pitch wide). Fewer than three points off one line: their bounding box grown
    by the margin."""
    return np.round(_grown_hull(points_xy, margin_m), 12) + 0.0


def _grown_hull(points_xy: np.ndarray, margin_m: float) -> np.ndarray:
    p = np.unique(np.round(np.asarray(points_xy, dtype=float), 12), axis=0)
    hull = _hull(p) if len(p) >= 3 else p
    if len(hull) < 3:
        lo, hi = p.min(axis=0) - margin_m, p.max(axis=0) + margin_m
        return np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    if margin_m == 0.0:
        return hull
    edges = np.roll(hull, -1, axis=0) - hull
    normals = np.c_[edges[:, 1], -edges[:, 0]] / np.linalg.norm(edges, axis=1)[:, None]
    out = np.empty_like(hull)
    for k in range(len(hull)):
        # vertex k joins edge k - 1 and edge k: intersect the two moved edges
        n0, n1 = normals[k - 1], normals[k]
        a = np.array([n0, n1])
        b = np.array([n0 @ hull[k] + margin_m, n1 @ hull[k] + margin_m])
        out[k] = np.linalg.solve(a, b)
    return out


def _hull(p: np.ndarray) -> np.ndarray:
    """Andrew's monotone chain: convex hull of (n, 2) points, counter-clockwise, collinear
    points dropped."""
    pts = p[np.lexsort((p[:, 1], p[:, 0]))]

    def half(seq):
        out: list = []
        for q in seq:
            while len(out) >= 2 and _turn(out[-2], out[-1], q) <= 1e-15:
                out.pop()
            out.append(q)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _turn(a, b, c) -> float:
    """z of (b - a) x (c - a): > 0 when a, b, c turn counter-clockwise."""
    return float((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _upright(n: int) -> np.ndarray:
    return np.tile([0.0, 0.0, 1.0], (n, 1))


@dataclass(frozen=True)
class GridLayout:
    """Rows x columns of upright coils at one pitch, row-major from the top-left (+y) row."""

    kind: ClassVar[str] = "grid"
    rows: int = 3
    columns: int = 3
    pitch_m: float = 0.050
    """Centre-to-centre spacing, m (assumed from the thesis' 150 mm x 150 mm footprint)."""

    def top_centres_m(self) -> np.ndarray:
        j, i = np.meshgrid(np.arange(self.columns), np.arange(self.rows))
        x = (j.ravel() - (self.columns - 1) / 2) * self.pitch_m
        y = ((self.rows - 1) / 2 - i.ravel()) * self.pitch_m
        return np.c_[x, y, np.zeros(x.size)]

    def axes(self) -> np.ndarray:
        return _upright(self.rows * self.columns)

    def describe(self) -> str:
        return f"{self.rows} x {self.columns} grid, pitch {self.pitch_m * 1e3:.4g} mm"

    def footprint_m(self) -> np.ndarray:
        """The rectangle the grid's cells cover: half a pitch beyond the outer coil axes."""
        return grown_hull(self.top_centres_m()[:, :2], self.pitch_m / 2)


@dataclass(frozen=True)
class HexLayout:
    """Upright coils on a hexagonal lattice: one at the centre and ``rings`` rings around it
    (1 + 3 rings (rings + 1) coils); the centre first, then ring by ring, counter-clockwise
    from +x."""

    kind: ClassVar[str] = "hex"
    rings: int = 1
    pitch_m: float = 0.044
    """Centre-to-centre spacing of neighbouring coils, m."""

    def top_centres_m(self) -> np.ndarray:
        out = [(0.0, 0.0)]
        corners = [np.array([math.cos(a), math.sin(a)]) for a in np.arange(6) * math.pi / 3]
        for ring in range(1, self.rings + 1):
            for side in range(6):
                start, end = ring * corners[side], ring * corners[(side + 1) % 6]
                for step in range(ring):
                    out.append(tuple(start + (end - start) * step / ring))
        xy = np.array(out) * self.pitch_m
        return np.c_[xy, np.zeros(len(xy))]

    def axes(self) -> np.ndarray:
        return _upright(1 + 3 * self.rings * (self.rings + 1))

    def describe(self) -> str:
        return (f"hexagonal, {1 + 3 * self.rings * (self.rings + 1)} coils in {self.rings} "
                f"ring{'s' if self.rings != 1 else ''}, pitch {self.pitch_m * 1e3:.4g} mm")

    def footprint_m(self) -> np.ndarray:
        """The hexagon half a pitch beyond the outer ring."""
        return grown_hull(self.top_centres_m()[:, :2], self.pitch_m / 2)


@dataclass(frozen=True)
class RingLayout:
    """``count`` coils on a circle, the first on +x, counter-clockwise; each axis leans towards
    the array's axis (+z through the origin) by ``tilt_deg``, so the axes of a tilted ring meet
    above its centre, ``radius_m / tan(tilt)`` up (the layout of magnetic-navigation arrays)."""

    kind: ClassVar[str] = "ring"
    count: int = 6
    radius_m: float = 0.075
    """Radius of the circle of the coils' top-face centres, m."""
    tilt_deg: float = 0.0
    """Lean of each coil axis towards the array's axis, degrees in [0, 90)."""

    def _azimuths(self) -> np.ndarray:
        return 2 * math.pi * np.arange(self.count) / self.count

    def top_centres_m(self) -> np.ndarray:
        phi = self._azimuths()
        return np.c_[self.radius_m * np.cos(phi), self.radius_m * np.sin(phi),
                     np.zeros(self.count)]

    def axes(self) -> np.ndarray:
        phi, t = self._azimuths(), math.radians(self.tilt_deg)
        return np.c_[-math.sin(t) * np.cos(phi), -math.sin(t) * np.sin(phi),
                     np.full(self.count, math.cos(t))]

    def describe(self) -> str:
        tilt = f", axes tilted {self.tilt_deg:.4g} deg inwards" if self.tilt_deg else ""
        return f"ring of {self.count}, radius {self.radius_m * 1e3:.4g} mm{tilt}"

    def footprint_m(self) -> np.ndarray:
        """The polygon of the coils' top-face centres (the workspace lies inside the ring); a
        ring of one or two coils: their bounding box grown by the radius."""
        c = self.top_centres_m()[:, :2]
        return grown_hull(c, 0.0 if self.count >= 3 else self.radius_m)


@dataclass(frozen=True)
class FreeLayout:
    """Any coils: ``positions_m`` the top-face centres (n x 3, m) and ``axes`` their unit axes
    (n x 3; empty: every axis +z)."""

    kind: ClassVar[str] = "free"
    positions_m: tuple[tuple[float, float, float], ...] = ((0.0, 0.0, 0.0),)
    axis_vectors: tuple[tuple[float, float, float], ...] = ()
    footprint_margin_m: float = 0.025
    """How far the default workspace reaches beyond the hull of the coil axes, m."""

    def top_centres_m(self) -> np.ndarray:
        return np.array(self.positions_m, dtype=float).reshape(-1, 3)

    def axes(self) -> np.ndarray:
        if not self.axis_vectors:
            return _upright(len(self.positions_m))
        return np.array(self.axis_vectors, dtype=float).reshape(-1, 3)

    def describe(self) -> str:
        tilted = int(np.sum(np.abs(self.axes()[:, 2] - 1.0) > 1e-12))
        return (f"{len(self.positions_m)} coils in free poses"
                + (f", {tilted} tilted" if tilted else ""))

    def footprint_m(self) -> np.ndarray:
        return grown_hull(self.top_centres_m()[:, :2], self.footprint_margin_m)


Layout = GridLayout | HexLayout | RingLayout | FreeLayout
LAYOUTS: dict[str, type] = {c.kind: c for c in (GridLayout, HexLayout, RingLayout, FreeLayout)}
"""Layout name (``[array] layout = ...``) -> its class."""
LAYOUT_KEYS: dict[str, tuple[str, ...]] = {
    "grid": ("rows", "columns", "pitch_m"), "hex": ("rings", "pitch_m"),
    "ring": ("count", "radius_m", "tilt_deg"),
    "free": ("positions_m", "axes", "footprint_margin_m")}
"""The design-file keys of each layout (``axes`` is ``FreeLayout.axis_vectors``)."""


def check_layout(layout: Layout) -> None:
    """Range checks of a layout's own numbers; BadInputError naming ``array.<key>``."""
    def positive(name, value):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
                math.isfinite(value) and value > 0):
            raise BadInputError(f"array.{name}", "a finite number > 0", value)

    def count(name, value, least):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise BadInputError(f"array.{name}", f"a whole number >= {least}", value)

    if isinstance(layout, GridLayout):
        count("rows", layout.rows, 1)
        count("columns", layout.columns, 1)
        positive("pitch_m", layout.pitch_m)
    elif isinstance(layout, HexLayout):
        count("rings", layout.rings, 0)
        positive("pitch_m", layout.pitch_m)
    elif isinstance(layout, RingLayout):
        count("count", layout.count, 1)
        positive("radius_m", layout.radius_m)
        t = layout.tilt_deg
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not 0 <= t < 90:
            raise BadInputError("array.tilt_deg", "a number of degrees in [0, 90)", t)
    elif isinstance(layout, FreeLayout):
        _check_free(layout)
    else:
        raise BadInputError("array", f"a layout: one of {sorted(LAYOUTS)}", type(layout).__name__)


def _check_free(layout: FreeLayout) -> None:
    pos = _vectors("array.positions_m", layout.positions_m, "[x, y, z] in m")
    if not pos:
        raise BadInputError("array.positions_m", "at least one [x, y, z] (m)", [])
    if layout.axis_vectors:
        axes = _vectors("array.axes", layout.axis_vectors, "[ax, ay, az], a unit vector")
        if len(axes) != len(pos):
            raise BadInputError("array.axes", f"one axis per coil ({len(pos)}) or none",
                                f"{len(axes)} axes")
        for k, a in enumerate(axes):
            n = math.sqrt(sum(c * c for c in a))
            if abs(n - 1.0) > UNIT_TOLERANCE:
                hint = (f"Did you mean {[round(c / n, 6) for c in a]}?" if n > 0 else
                        "An axis needs a direction.")
                raise BadInputError(f"array.axes[{k}]", "a unit vector (|axis| = 1)", list(a),
                                    hint)
    fm = layout.footprint_margin_m
    if isinstance(fm, bool) or not isinstance(fm, (int, float)) or not (
            math.isfinite(fm) and fm >= 0):
        raise BadInputError("array.footprint_margin_m", "a finite number >= 0 (m)", fm)


def _vectors(name: str, value, what: str) -> list:
    if not isinstance(value, (list, tuple)) or not all(
            isinstance(v, (list, tuple)) and len(v) == 3 and all(
                isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
                for c in v) for v in value):
        raise BadInputError(name, f"a list of {what}", value)
    return [tuple(float(c) for c in v) for v in value]


def layout_from_table(table: dict, source: str = "design") -> Layout:
    """The layout of an ``[array]`` table: ``layout`` names it (default 'grid'); every other
    key must be one of that layout's (:data:`LAYOUT_KEYS`)."""
    kind = table.get("layout", "grid")
    if kind not in LAYOUTS:
        raise BadInputError(f"{source}: array.layout", f"one of {sorted(LAYOUTS)}", kind)
    allowed = LAYOUT_KEYS[kind]
    for key in table:
        if key != "layout" and key not in allowed:
            owners = [k for k, keys in LAYOUT_KEYS.items() if key in keys]
            hint = (f"'{key}' belongs to layout {' / '.join(repr(o) for o in owners)}."
                    if owners else "")
            raise BadInputError(f"{source}: [array] key for layout '{kind}'",
                                f"one of {list(allowed)}", key, hint)
    values = {("axis_vectors" if k == "axes" else k): v for k, v in table.items()
              if k != "layout"}
    if kind == "free":
        for k in ("positions_m", "axis_vectors"):
            if k in values and isinstance(values[k], list):
                values[k] = tuple(tuple(v) if isinstance(v, list) else v for v in values[k])
    return LAYOUTS[kind](**values)


def layout_to_table(layout: Layout) -> dict:
    """The ``[array]`` table of a layout (inverse of :func:`layout_from_table`)."""
    out: dict = {"layout": layout.kind}
    for key in LAYOUT_KEYS[layout.kind]:
        value = getattr(layout, "axis_vectors" if key == "axes" else key)
        if key == "axes" and not value:
            continue
        out[key] = [list(v) for v in value] if isinstance(value, tuple) else value
    return out
