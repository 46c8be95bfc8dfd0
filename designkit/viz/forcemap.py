"""Arrows of the force on the magnet over a square grid across the workspace's outline at the
design point's height, coloured by its magnitude (mN, log scale, the design's fixed range)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from ..support import validate as v
from .common import F_MN, F_N, MIN_ARROW, Quality, grid_resolution, import_pyvista
from .physics import (add_field_arrays, array_field, magnet_moment,
                      resolve_currents)
from .ranges import clip_note, colour_ranges
from .scene import scene_meshes
from .style import (add_axes, add_device, add_title, bar_args, currents_text, fit_camera,
                    in_mm, log_format, magnet_text, new_plotter)

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from ..design import Design


def force_map_data(design: "Design", currents: Sequence[float] | None = None, *,
                   moment=None, height_m: float | None = None, quality: Quality = "full"):
    """Force on the magnet at the nodes of a square grid (``quality``'s points per side of the
    workspace's bounding box) that lie in the workspace's outline, at ``height_m`` (default: the
    design point's height).

    Returns
    -------
    pyvista.PolyData
        Points (m) with ``"F (N)"``, ``"F magnitude (mN)"``, ``"Fz (mN)"``, ``"B (T)"``, ``"B magnitude (mT)"``.
    """
    pv = import_pyvista()
    res = grid_resolution(quality)
    cur = resolve_currents(design, currents)
    m = magnet_moment(design, moment)
    h = float(np.asarray(design.design_point_m)[2]) if height_m is None else v.positive("height_m",
                                                                              height_m)
    xy = design.workspace_region().grid_xy(map_spacing_m(design, quality))
    pts = np.c_[xy, np.full(len(xy), h)]
    cloud = pv.PolyData(pts)
    b, g = array_field(design, pts, cur, gradient=True)
    add_field_arrays(cloud, b, g, m)
    return cloud


def map_spacing_m(design: "Design", quality: Quality) -> float:
    """The force map's grid step, m: the workspace's bounding box's longer side over the
    quality's points per side less one."""
    lo, hi = design.workspace_region().bounds_m()
    return float(max(hi[:2] - lo[:2])) / (grid_resolution(quality)["map"] - 1)


DEVICE_DEPTH_M = 0.02
"""How far below the coil tops the force map draws the device, m."""


def _top_of(blocks, z_min_m: float):
    """The device's solids above z_min_m (m), cut flat there; other blocks unchanged."""
    out = blocks.copy()
    for key in ("windings", "cores"):
        if key in out.keys() and out[key].n_points:
            out[key] = out[key].clip(normal="z", origin=(0.0, 0.0, z_min_m), invert=False)
    return out


def plot_force_map(design: "Design", currents: Sequence[float] | None = None, *,
                   moment=None, height_m: float | None = None, quality: Quality = "full",
                   window_size=(1024, 768), data=None, blocks=None) -> "pyvista.Plotter":
    """Arrows of the force on the magnet over the workspace at one height, coloured by its
    magnitude (mN, log scale, the design's fixed range); arrow length grows as the square root
    of the magnitude, from :data:`MIN_ARROW` of the grid step to the whole step. The view holds
    the arrows' layer; the coils below are drawn see-through for context."""
    pv = import_pyvista()
    cur = resolve_currents(design, currents)
    h = float(np.asarray(design.design_point_m)[2]) if height_m is None else height_m
    cloud = (force_map_data(design, cur, moment=moment, height_m=h, quality=quality)
             if data is None else data)
    blocks = scene_meshes(design, cur) if blocks is None else blocks
    ranges = colour_ranges(design)
    p = new_plotter(pv, window_size)
    # see-through coils, cut DEVICE_DEPTH_M below their tops: the arrows are the subject, and the
    # whole length of the coils would shrink the workspace to a third of the picture
    add_device(p, design, _top_of(blocks, -DEVICE_DEPTH_M), opacity=0.25, magnet=False,
               workspace=True)
    f = np.asarray(cloud[F_N])
    fmag = np.linalg.norm(f, axis=1)
    fmax = float(fmag.max()) if fmag.size else 0.0
    lo, hi = ranges.f_mn
    colour = "no force: all coils at 0 A"
    spacing_mm = 1e3 * map_spacing_m(design, quality)
    mm = in_mm(cloud)
    if fmax > 0:
        # Length ~ sqrt(|F|): the force over a core is orders of magnitude above that at the
        # workspace's edge; a linear scale would show one arrow and dots.
        unit = f / np.where(fmag > 0, fmag, 1.0)[:, None]
        mm["arrow"] = unit * np.maximum(np.sqrt(fmag / fmax), MIN_ARROW)[:, None]
        glyphs = mm.glyph(orient="arrow", scale="arrow", factor=spacing_mm,
                          geom=pv.Arrow(tip_length=0.3, tip_radius=0.2, shaft_radius=0.08))
        colour = (f"colour: F (mN), log scale {lo:g}..{hi:g}, the design's fixed range"
                  + clip_note(fmag * 1e3, lo, hi, "mN"))
        p.add_mesh(glyphs, scalars=F_MN, cmap="plasma", log_scale=True, clim=(lo, hi),
                   name="force-arrows", scalar_bar_args=bar_args("F (mN)",
                                                                 fmt=log_format(lo, hi)))
    outline = design.workspace_region().outline * 1e3
    plane = pv.PolyData(np.c_[outline, np.full(len(outline), h * 1e3)],
                        faces=np.r_[len(outline), np.arange(len(outline))])
    p.add_mesh(plane, color="#dddddd", opacity=0.25)
    add_title(p, f"Force on the magnet ({magnet_text(design, moment)}) at z = {h * 1e3:.3g} mm "
                 f"(the design point's height)\nlargest: {fmax * 1e3:.4g} mN; "
                 f"{currents_text(cur)}; {colour}\narrow length ~ square root of the force (at "
                 f"least {MIN_ARROW:g} of the largest)", font_size=11)
    # the view holds the arrows' layer (the coils below are context, cut by the frame)
    lo_ws, hi_ws = design.workspace_region().bounds_m()
    reach = spacing_mm
    box = [lo_ws[0] * 1e3, hi_ws[0] * 1e3, lo_ws[1] * 1e3, hi_ws[1] * 1e3,
           h * 1e3 - reach, h * 1e3 + reach]
    # no z axis: the arrows' layer is one height (the title's), a z axis a spacing tall would
    # crowd its labels into one smudge
    fit_camera(p, add_axes(p, box, show_zaxis=False, show_zlabels=False), elevation_deg=50.0, margin=1.1,
               every_actor=False)
    return p
