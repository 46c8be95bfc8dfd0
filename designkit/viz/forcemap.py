"""Arrows of the force on the magnet over a square grid across the workspace at one height,
coloured by its magnitude (mN, log scale)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

import numpy as np

from ..support import validate as v
from .common import F_MN, F_N, MIN_ARROW, Quality, import_pyvista, grid_resolution
from .physics import add_field_arrays, array_field, magnet_moment, resolve_currents
from .scene import scene_meshes
from .style import (add_device, add_axes, bar_args, currents_text, fit_camera, log_format,
                    magnet_text, in_mm, new_plotter, add_title, round_range)

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from ..design import Design


def force_map_data(design: "Design", currents: Sequence[float] | None = None, *,
                   moment=None, height_m: float | None = None, quality: Quality = "full"):
    """Force on the magnet at the nodes of a square grid over the workspace at one height.

    Returns
    -------
    pyvista.PolyData
        Points (m) with ``"F (N)"``, ``"F magnitude (mN)"``, ``"Fz (mN)"``, ``"B (T)"``, ``"B magnitude (mT)"``.
    """
    pv = import_pyvista()
    res = grid_resolution(quality)
    cur = resolve_currents(design, currents)
    m = magnet_moment(design, moment)
    h = design.optimize.height_m if height_m is None else v.positive("height_m", height_m)
    hw = design.workspace.half_width_m
    n = res["map"]
    xs = np.linspace(-hw, hw, n)
    xx, yy = np.meshgrid(xs, xs, indexing="ij")
    pts = np.c_[xx.ravel(), yy.ravel(), np.full(xx.size, h)]
    cloud = pv.PolyData(pts)
    b, g = array_field(design, pts, cur, gradient=True)
    add_field_arrays(cloud, b, g, m)
    return cloud


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
    """Arrows of the force on the magnet over a grid at one height, coloured by its magnitude
    (mN, log scale); arrow length grows as the square root of the magnitude."""
    pv = import_pyvista()
    cur = resolve_currents(design, currents)
    h = design.optimize.height_m if height_m is None else height_m
    cloud = (force_map_data(design, cur, moment=moment, height_m=h, quality=quality)
             if data is None else data)
    blocks = scene_meshes(design, cur) if blocks is None else blocks
    p = new_plotter(pv, window_size)
    # see-through coils, cut DEVICE_DEPTH_M below their tops: the arrows are the subject, and the
    # whole length of the coils would shrink the workspace to a third of the picture
    add_device(p, design, _top_of(blocks, -DEVICE_DEPTH_M), opacity=0.25, magnet=False,
                workspace=True)
    f = np.asarray(cloud[F_N])
    fmag = np.linalg.norm(f, axis=1)
    fmax = float(fmag.max()) if fmag.size else 0.0
    colour = "no force: all coils at 0 A"
    n = int(round(math.sqrt(cloud.n_points))) or 1
    spacing_mm = 2e3 * design.workspace.half_width_m / max(n - 1, 1)
    mm = in_mm(cloud)
    if fmax > 0:
        # Length ~ sqrt(|F|): the force over a core is orders of magnitude above that at the
        # workspace's edge; a linear scale would show one arrow and dots.
        unit = f / np.where(fmag > 0, fmag, 1.0)[:, None]
        # at least MIN_ARROW of the spacing, so that the weak-force arrows stay visible
        mm["arrow"] = unit * np.maximum(np.sqrt(fmag / fmax), MIN_ARROW)[:, None]
        glyphs = mm.glyph(orient="arrow", scale="arrow", factor=0.95 * spacing_mm,
                          geom=pv.Arrow(tip_length=0.35, tip_radius=0.15, shaft_radius=0.05))
        lo, hi = round_range(max(fmax * 1e-3, float(fmag.min()) * 1e3, 1e-9), fmax * 1e3,
                             log=True)  # round ends: a labelled tick at the bar's top
        colour = f"colour: F (mN), log scale {lo:g}..{hi:g}"
        p.add_mesh(glyphs, scalars=F_MN, cmap="plasma", log_scale=True,
                   clim=(lo, hi), name="force-arrows",
                   scalar_bar_args=bar_args("F (mN)", fmt=log_format(lo, hi)))
    plane = pv.Plane(center=(0, 0, h * 1e3), i_size=2e3 * design.workspace.half_width_m,
                     j_size=2e3 * design.workspace.half_width_m)
    p.add_mesh(plane, color="#dddddd", opacity=0.25)
    add_title(p, f"Force on the magnet ({magnet_text(design, moment)}) at z = {h * 1e3:.0f} mm\n"
              f"largest: {fmax * 1e3:.4g} mN; {currents_text(cur)}; {colour}\n"
              f"arrow length ~ square root of the force (at least {MIN_ARROW:g} of the "
              f"largest)", font_size=11)
    fit_camera(p, add_axes(p), elevation_deg=50.0)
    return p
