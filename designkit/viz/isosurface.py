"""The surfaces Fz = +level (push) and Fz = -level (pull) of the force on the magnet above the
array; the level defaults to the human detection threshold ``render.threshold_n``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from ..support import validate as v
from .common import FZ_MN, REACH_M, Quality, image_grid, import_pyvista, grid_resolution
from .physics import (add_field_arrays, array_field, footprint_half_m, force_from_gradient,
                      magnet_moment, resolve_currents)
from .scene import scene_meshes
from .style import (add_device, add_axes, bar_args, currents_text, fit_camera, magnet_text, in_mm,
                    new_plotter, add_title)

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from ..design import Design


REACH_LIMIT_M = 0.5
"""Farthest point along a coil's axis where the reach of the level is looked for, m."""


def reach_height_m(design, cur, m, level_n) -> float:
    """Highest point (its z, m) on the energized coils' axes, from ``workspace.z_min_m`` above
    their tops out to :data:`REACH_LIMIT_M`, where |Fz| still reaches ``level_n``; the workspace's
    top when it reaches nowhere above it."""
    s = np.linspace(design.workspace.z_min_m, REACH_LIMIT_M, 120)
    tops, axes = design.array.top_centres_m(), design.array.axes()
    best = design.workspace.z_max_m
    for k in np.flatnonzero(cur):
        pts = tops[k] + s[:, None] * axes[k]
        _, g = array_field(design, pts, cur)
        above = np.flatnonzero(np.abs(force_from_gradient(g, m)[:, 2]) >= level_n)
        if above.size:
            best = max(best, float(pts[above[-1], 2]))
    return best


def force_isosurface_data(design: "Design", currents: Sequence[float] | None = None, *,
                          moment=None, level_n: float | None = None, quality: Quality = "full"):
    """Surfaces where the vertical force on the magnet equals +level and -level.

    The level defaults to the human detection threshold ``render.threshold_n`` (0.8 mN). The
    grid covers twice the array's footprint from ``workspace.z_min_m`` up to a quarter above
    where |Fz| on the axes of the energized coils falls below the level
    (:func:`reach_height_m`), at least the workspace top and at most four footprints: with the
    design's full current the threshold surface lies far above the workspace, and that reach
    is what the figure is for.

    Returns
    -------
    volume : pyvista.ImageData
        With ``"Fz (mN)"``, ``"F (N)"``, ``"F magnitude (mN)"``, ``"B (T)"``, ``"B magnitude (mT)"``.
    surface : pyvista.PolyData
        Contours at ``Fz = +level`` and ``-level`` with point data ``"Fz (mN)"`` (the level).
    level_n : float
        The level, N.
    """
    pv = import_pyvista()
    res = grid_resolution(quality)
    cur = resolve_currents(design, currents)
    m = magnet_moment(design, moment)
    level = design.render.threshold_n if level_n is None else v.positive("level_n", level_n, "N")
    reach = reach_height_m(design, cur, m, level)
    # a box sized to the array (twice its footprint, at most 4 footprints high), not to the
    # reach of the surfaces (up to 0.5 m): the array would be a speck; the plot states the cut
    foot = footprint_half_m(design)
    half = 2.0 * foot
    top = max(min(1.25 * reach, 4.0 * foot), design.workspace.z_max_m)
    vol = image_grid(pv, (-half, -half, design.workspace.z_min_m), (half, half, top), res["iso"])
    b, g = array_field(design, vol.points, cur, gradient=True)
    add_field_arrays(vol, b, g, m)
    vol.field_data[REACH_M] = [reach]
    surface = vol.contour([-level * 1e3, level * 1e3], scalars=FZ_MN)
    return vol, surface, level


def plot_force_isosurface(design: "Design", currents: Sequence[float] | None = None, *,
                          moment=None, level_n: float | None = None, quality: Quality = "full",
                          window_size=(1024, 768), data=None, blocks=None) -> "pyvista.Plotter":
    """Surfaces Fz = +level (push, red) and Fz = -level (pull, blue) above the array; level
    defaults to the human threshold 0.8 mN."""
    pv = import_pyvista()
    cur = resolve_currents(design, currents)
    vol, surface, level = (force_isosurface_data(design, cur, moment=moment, level_n=level_n,
                                                 quality=quality) if data is None else data)
    blocks = scene_meshes(design, cur) if blocks is None else blocks
    p = new_plotter(pv, window_size)
    add_device(p, design, blocks, opacity=1.0, magnet=True, workspace=True)
    lmn = level * 1e3
    if surface.n_points:
        p.add_mesh(in_mm(surface), scalars=FZ_MN, cmap=["#2166ac", "#b2182b"], clim=(-lmn, lmn),
                   opacity=0.5, smooth_shading=True, name="isosurface",
                   scalar_bar_args=bar_args("Fz (mN)", n_labels=2, fmt="%+.2g"))
    else:
        p.add_text(f"the vertical force stays below {lmn:g} mN everywhere in the box",
                   position="lower_left", color="black", font_size=11)
    p.add_mesh(in_mm(vol.outline()), color="grey", line_width=1)
    b = np.asarray(vol.bounds) * 1e3
    reach = ""
    if REACH_M in vol.field_data:
        z_reach = float(vol.field_data[REACH_M][0]) * 1e3
        where = ("" if z_reach <= b[5] + 1e-6 else
                 f", above the box: the surfaces close beyond its top")
        reach = (f"; on the energized coils' axes Fz reaches +-{lmn:g} mN up to z = "
                 f"{z_reach:.0f} mm{where}")
    add_title(p, f"Where the magnet ({magnet_text(design, moment)}) feels Fz = +{lmn:g} mN "
                 f"(red, push up) and -{lmn:g} mN (blue, pull down); {currents_text(cur)}\n"
                 f"the force is larger between the surfaces and the coils{reach}\n"
                 f"colour: the sign of Fz at the fixed level; surfaces cut flat by the grey box "
                 f"at z = {b[4]:.0f} mm (the workspace's floor), z = {b[5]:.0f} mm and x, y = "
                 f"+-{b[1]:.0f} mm", font_size=10)
    fit_camera(p, add_axes(p, b), elevation_deg=16.0, margin=1.12)
    return p
