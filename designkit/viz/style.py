"""How every figure looks: the off-screen plotter, millimetre copies of the meshes, titles,
colour bars on round labels, axes on round ticks, the camera and the device drawn in context.

Figures are drawn in millimetres (the datasets stay in metres); tick and colour-bar labels are
1, 2 or 5 x 10^k values that VTK's own axis actor then labels as such.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np

from .common import COPPER, MAGNET_RED, STEEL, window_pixels
from .physics import magnet_moment


def new_plotter(pv, window_size, shape=(1, 1), col_weights=None):
    """An off-screen plotter on a white background; ``col_weights``: the panels' relative
    widths (default equal)."""
    p = pv.Plotter(off_screen=True, window_size=window_pixels(window_size), shape=shape,
                   col_weights=col_weights)
    p._col_fractions = (np.ones(shape[1]) if col_weights is None
                       else np.asarray(col_weights, float)) / (shape[1] if col_weights is None
                                                               else sum(col_weights))
    p.set_background("white")
    return p


def in_mm(mesh):
    """A copy of the mesh with its points in millimetres (data arrays untouched)."""
    out = mesh.cast_to_structured_grid() if hasattr(mesh, "spacing") else mesh.copy()
    out.points = np.asarray(out.points) * 1e3
    return out


def bar_args(title, **extra):
    args = dict(title=title, color="black", vertical=True, position_x=0.87, position_y=0.2,
                width=0.05, height=0.6, title_font_size=14, label_font_size=12, fmt="%.3g",
                n_labels=5)
    args.update(extra)
    return args


def add_title(p, text, font_size=12):
    """Title at the upper left, each line wrapped to the width of its (sub)plot."""
    fractions = getattr(p, "_col_fractions", np.ones(p.shape[1]) / p.shape[1])
    width = p.window_size[0] * fractions[p.renderers.index_to_loc(p.renderers.active_index)[1]
                                         if p.shape[1] > 1 else 0]
    # VTK's default font: a character is about 0.6 font sizes wide, in pixels
    chars = max(20, int(0.92 * width / (0.6 * font_size)))
    lines = [w for line in text.split("\n") for w in (textwrap.wrap(line, chars) or [""])]
    p.add_text("\n".join(lines), position="upper_left", font_size=font_size, color="black")
    # the band the title takes, px: fit_camera keeps the scene and its axis labels below it
    p._title_band_px = len(lines) * TITLE_LINE_PX_PER_PT * font_size + 6


TITLE_LINE_PX_PER_PT = 1.5
"""Height of a line of VTK's default font, pixels per point of font size (measured on the
rendered PNGs: 14-15 px a line at 10-11 pt)."""


def _vtk_tick_spacing(span: float) -> float:
    """The major tick spacing ``vtkCubeAxesActor`` picks for an axis of this span (it labels
    ``vmin + k * spacing`` whatever label count it is asked for, once that count reaches its
    own; pyvista's ``_axis_label_values`` mirrors the same rule)."""
    power = math.log10(span)
    if power != 0.0:
        power = math.copysign(abs(power) + 10.0e-10, power)
    if power < 0.0:
        power -= 1.0
    decade = 10.0 ** float(int(power))
    ticks = int(span / decade) + 1
    return decade / (5.0 if ticks <= 2 else 2.0 if ticks < 5 else 1.0)


def nice_ticks(lo: float, hi: float, target: int = 5) -> tuple[float, float, float]:
    """``(lo', hi', step)``: the range widened so that the axis VTK draws over it is labelled
    on round values: ``lo'`` a multiple of ``step``, ``step`` VTK's own tick spacing for the
    widened span (a 1, 2 or 5 x 10^k), 3 to 11 labels; of those, the least widening (then the
    label count nearest ``target`` + 1)."""
    span = hi - lo
    if not (span > 0 and math.isfinite(span)):
        return lo - 1.0, hi + 1.0, 1.0
    k = 10.0 ** math.floor(math.log10(span))
    best = None
    for base in (0.05, 0.1, 0.2, 0.25, 0.5, 1.0, 2.0, 2.5, 5.0):
        step = base * k
        a = math.floor(lo / step + 1e-9) * step
        b = math.ceil(hi / step - 1e-9) * step
        major = _vtk_tick_spacing(b - a)
        if abs(a / major - round(a / major)) > 1e-9:
            continue  # VTK would label a + j * major: not round
        a, b = round(a / major) * major, b  # exact multiples, no 1e-17 residues in the labels
        n = math.floor((b - a) / major + 1e-9)
        if 2 <= n <= 10:
            key = ((b - a) / span, abs(n - target))
            if best is None or key < best[0]:
                best = (key, (a, b, major))
    return best[1] if best else (lo, hi, span / target)


def nice_bounds(bounds) -> tuple[list[float], dict]:
    b = list(map(float, bounds))
    counts = {}
    for i, axis in enumerate("xyz"):
        lo, hi, step = nice_ticks(b[2 * i], b[2 * i + 1])
        b[2 * i], b[2 * i + 1] = lo, hi
        # at least VTK's own count: it then labels lo + k * step (see _vtk_tick_spacing)
        counts[f"n_{axis}labels"] = int(math.floor((hi - lo) / step + 1e-9)) + 1
    return b, counts


def axis_font_size(window_width_px: int) -> int:
    """Tick-label font size for a 3-D view this wide: 10 at 1024 px, smaller in proportion
    (at least 6), so that VTK's 8-10 labels per axis do not run into each other."""
    return int(max(6, min(10, round(10 * window_width_px / 1024))))


def add_axes(p, mesh_bounds=None, location="outer", **kw):
    """Axes in mm on round tick values (the bounds are widened to the nearest round ticks)."""
    b, counts = nice_bounds(p.bounds if mesh_bounds is None else mesh_bounds)
    p.show_bounds(bounds=b, xtitle="x (mm)", ytitle="y (mm)", ztitle="z (mm)",
                  color="black", font_size=axis_font_size(p.window_size[0] / p.shape[1]),
                  grid=False, location=location, ticks="outside", minor_ticks=False, fmt="%g",
                  **counts, **kw)
    # from the oblique views (azimuth -58 deg) the y axis starts at the corner where the x or
    # the z axis ends: its first label would touch theirs, so it is left blank
    cube = p.renderer.cube_axes_actor
    labels = cube.GetAxisLabels(1)
    if labels is not None and labels.GetNumberOfValues() > 2:
        labels.SetValue(0, "")
        cube.SetAxisLabels(1, labels)
        cube.Modified()
    return b


def fit_camera(p, bounds_mm, elevation_deg=25.0, azimuth_deg=-58.0, margin=1.22,
               every_actor=True):
    """Look at the box from (elevation, azimuth) from just far enough that its bounding sphere,
    widened by ``margin`` for the axis labels, fits the view: nothing is cut at the edges
    (``every_actor``: the box grown to hold every actor; else the box alone, the subject)."""
    b = np.asarray(bounds_mm, dtype=float)
    if every_actor:
        every = np.asarray(p.bounds, dtype=float)  # every actor, e.g. coils below the axes box
        b[0::2], b[1::2] = np.minimum(b[0::2], every[0::2]), np.maximum(b[1::2], every[1::2])
    centre = (b[0::2] + b[1::2]) / 2
    radius = 0.5 * float(np.linalg.norm(b[1::2] - b[0::2]))
    half_angle = math.radians(p.camera.view_angle / 2)
    # the title's band at the top: the margin leaves room for half of it; the view is fitted
    # in the rest and moved down by that much (the top axis labels stay clear of the title)
    band = 0.5 * min(getattr(p, "_title_band_px", 0.0) / (p.window_size[1] / p.shape[0]), 0.5)
    # a panel narrower than it is high fits the sphere in its width
    fractions = getattr(p, "_col_fractions", np.ones(p.shape[1]) / p.shape[1])
    col = p.renderers.index_to_loc(p.renderers.active_index)[1] if p.shape[1] > 1 else 0
    aspect = (p.window_size[0] * fractions[col]) / (p.window_size[1] / p.shape[0])
    fit_angle = min(half_angle, math.atan(math.tan(half_angle) * aspect))
    distance = margin * radius / math.sin(fit_angle) / (1.0 - band)
    _iso_camera(p, tuple(centre), distance, elevation_deg, azimuth_deg)
    if band > 0:
        pos, focus = (np.asarray(q, dtype=float) for q in p.camera_position[:2])
        view = (pos - focus) / np.linalg.norm(pos - focus)
        up = np.array([0.0, 0.0, 1.0]) - view[2] * view  # the screen's up direction
        shift = up / np.linalg.norm(up) * band * distance * math.tan(half_angle)
        p.camera_position = [tuple(pos + shift), tuple(focus + shift), (0.0, 0.0, 1.0)]


def add_device(p, design, blocks, *, opacity=1.0, magnet=True, workspace=True):
    p.add_mesh(in_mm(blocks["windings"]), color=COPPER, opacity=opacity, smooth_shading=True,
               name="windings")
    if "cores" in blocks.keys():
        p.add_mesh(in_mm(blocks["cores"]), color=STEEL, opacity=opacity, name="cores")
    if magnet:
        p.add_mesh(in_mm(blocks["magnet"]), color=MAGNET_RED, name="magnet")
    if workspace:
        p.add_mesh(in_mm(blocks["workspace"]), color="#1f4e9c", line_width=1.5, name="workspace")


def currents_text(cur) -> str:
    nz = [(i, c) for i, c in enumerate(cur) if c != 0.0]
    if not nz:
        return "all coils at 0 A"
    if len(nz) <= 3:
        return ", ".join(f"coil {i + 1} at {c:+.3g} A" for i, c in nz) + ", others 0 A" * (
            len(nz) < len(cur))
    return "I = [" + ", ".join(f"{c:+.2g}" for c in cur) + "] A"


def log_format(lo: float, hi: float) -> str:
    if lo >= 1.0:
        return "%.0f"
    return "%.2g" if hi < 100 else "%.3g"


def _iso_camera(p, focus_mm, distance_mm, elevation_deg=28.0, azimuth_deg=-58.0):
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    d = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    pos = np.asarray(focus_mm) + distance_mm * d
    p.camera_position = [tuple(pos), tuple(focus_mm), (0.0, 0.0, 1.0)]


def magnet_text(design, moment) -> str:
    m = magnet_moment(design, moment)
    direction = "+z" if np.allclose(m[:2], 0) and m[2] > 0 else (
        "-z" if np.allclose(m[:2], 0) else "(" + ", ".join(f"{x:.2g}" for x in m) + ")")
    return f"m = {np.linalg.norm(m):.3g} A m^2 along {direction}"


def bar_label_values(lo: float, hi: float, log: bool) -> list[float]:
    """Round label values for a colour bar over [lo, hi]: 1, 2, 5 x 10^k on a log bar (fewer
    per decade when the range spans many), the ticks of :func:`nice_ticks` inside the range on
    a linear one."""
    if not (hi > lo):
        return [lo]
    if log and lo > 0:
        for mants in ((1, 2, 5), (1, 3), (1,)):
            vals = [m * 10.0 ** e for e in range(math.floor(math.log10(lo)),
                                                math.ceil(math.log10(hi)) + 1) for m in mants]
            vals = [x for x in vals if lo * (1 - 1e-9) <= x <= hi * (1 + 1e-9)]  # lo > 0 here
            if vals and hi > vals[-1] * (1 + 1e-9) and _round_125(hi):
                vals.append(hi)  # a round top (round_range) is labelled
            if len(vals) <= 7:
                break
        return vals if len(vals) >= 2 else [lo, hi]
    a, b, step = nice_ticks(lo, hi)
    vals = [a + k * step for k in range(int(round((b - a) / step)) + 1)]
    return [x for x in vals if lo - 1e-9 * step <= x <= hi + 1e-9 * step]


def round_range(lo: float, hi: float, log: bool) -> tuple[float, float]:
    """A colour range widened to round ends (1, 2, 5 x 10^k on a log bar, :func:`nice_ticks`
    on a linear one), so that the bar has a labelled tick at its top and bottom."""
    if not (hi > lo):
        return lo, hi
    if log and lo > 0:
        steps = [m * 10.0 ** e for e in range(math.floor(math.log10(lo)) - 1,
                                             math.ceil(math.log10(hi)) + 2) for m in (1, 2, 5)]
        return (max(x for x in steps if x <= lo * (1 + 1e-9)),
                min(x for x in steps if x >= hi * (1 - 1e-9)))
    a, b, _ = nice_ticks(lo, hi)
    return a, b


def _round_125(x: float) -> bool:
    """True for 1, 2 or 5 x 10^k."""
    mant = x / 10.0 ** math.floor(math.log10(x) + 1e-12)
    return min(abs(mant - m) for m in (1, 2, 5, 10)) < 1e-9


def round_colour_bars(plotter) -> None:
    """Colour bars on round label values (:func:`bar_label_values`), their title lifted above
    the top label (VTK draws them overlapping)."""
    from vtkmodules.vtkCommonCore import vtkDoubleArray

    for bar in plotter.scalar_bars.values():
        size = bar.GetLabelTextProperty().GetFontSize()
        bar.SetVerticalTitleSeparation(max(int(size), 12))
        lut = bar.GetLookupTable()
        if lut is None or bar.GetNumberOfLabels() <= 2:
            continue  # two labels are the range's ends, e.g. -0.8 / +0.8 mN: round already
        lo, hi = lut.GetRange()
        labels = vtkDoubleArray()
        for x in bar_label_values(lo, hi, bool(lut.GetScale())):
            labels.InsertNextValue(x)
        bar.SetUseCustomLabels(True)
        bar.SetCustomLabels(labels)
        bar.SetLabelFormat("%g")
