"""|B| and the force on the magnet on a vertical (y = 0) and a horizontal slice, with the
coils' outlines; points inside a core or a winding are left out of the picture."""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal, Sequence

import numpy as np

from ..errors import BadInputError
from ..support import validate as v
from .common import B_MT, F_MN, IN_SOLID, Quality, image_grid, import_pyvista, grid_resolution
from .physics import (PICTURE_TOLERANCE, add_field_arrays, footprint_half_m, array_field,
                      inside_solids, magnet_moment, resolve_currents)
from .scene import scene_meshes
from .style import (bar_args, currents_text, log_format, magnet_text, in_mm, nice_bounds, new_plotter,
                    add_title, round_range)

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from ..design import Design


def slice_data(design: "Design", currents: Sequence[float] | None = None, *,
               moment=None, height_m: float | None = None, quality: Quality = "full"):
    """|B| and the force on the magnet on a vertical (y = 0) and a horizontal slice.

    The vertical slice spans the array's footprint in x and z from 2 mm above the coil tops to
    the top of the workspace; the horizontal one is at ``height_m`` (default: the design height).

    Returns
    -------
    vertical, horizontal : pyvista.ImageData
        Flat grids with ``"B (T)"``, ``"B magnitude (mT)"``, ``"grad B (T/m)"``, ``"F (N)"``,
        ``"F magnitude (mN)"`` and ``"Fz (mN)"``.
    """
    pv = import_pyvista()
    res = grid_resolution(quality)
    cur = resolve_currents(design, currents)
    m = magnet_moment(design, moment)
    h = design.optimize.height_m if height_m is None else v.positive("height_m", height_m)
    half = footprint_half_m(design)
    nx, nz = res["slice"]
    vert = image_grid(pv, (-half, 0.0, 0.002), (half, 0.0, design.workspace.z_max_m), (nx, 1, nz))
    horiz = image_grid(pv, (-half, -half, h), (half, half, h), (nx, nx, 1))
    for mesh in (vert, horiz):
        b, g = array_field(design, mesh.points, cur, gradient=True,
                           tolerance=PICTURE_TOLERANCE)
        add_field_arrays(mesh, b, g, m)
        mesh.point_data[IN_SOLID] = inside_solids(design, mesh.points).astype(np.uint8)
    return vert, horiz


def _section_lines(pv, design, blocks, view: Literal["xz", "xy"], height_m, z_low_m):
    """Outlines of the coils in the slice views, mm."""
    if view == "xz":
        cut = blocks["windings"].slice(normal="y", origin=(0, 0, 0))
        if "cores" in blocks.keys():
            cut = cut.merge(blocks["cores"].slice(normal="y", origin=(0, 0, 0)))
        cut = cut.clip(normal=(0, 0, 1), origin=(0, 0, z_low_m), invert=False)
        return in_mm(cut)
    circles = []
    for x, y, _ in design.coil_centres_m():
        for r in (design.coil.inner_radius_m, design.coil.outer_radius_m):
            circles.append(pv.Circle(radius=r, resolution=72)
                           .translate((x, y, height_m + 1e-4)).extract_feature_edges())
    return in_mm(pv.merge(circles))


def _drop_solids(mesh):
    """The slice without the cells that touch a point inside a solid (a structured grid)."""
    solid = np.asarray(mesh[IN_SOLID], dtype=bool) if IN_SOLID in mesh.point_data.keys() \
        else np.zeros(mesh.n_points, dtype=bool)
    if not solid.any():
        return mesh
    return mesh.extract_points(~solid, adjacent_cells=False)


def _above(mesh, z_min_m: float):
    """The slice without the points below ``z_min_m``."""
    keep = np.asarray(mesh.points)[:, 2] >= z_min_m - 1e-12
    return mesh if keep.all() else mesh.extract_points(keep, adjacent_cells=False)


def _colour_range(values, unit: str) -> tuple[float, float, str]:
    """(lo, hi, note): the data range on round ends (a tick at the bar's top); a floor more
    than 4 decades below the top is clipped, and the note says so."""
    values = np.asarray(values, float)
    values = values[np.isfinite(values)]
    hi = float(values.max()) if values.size else 1.0
    hi = hi if hi > 0 else 1.0
    lo = max(float(values.min()), 1e-9) if values.size else hi * 1e-4
    note = ""
    if lo < hi * 1e-4:
        lo = hi * 1e-4
        note = f"; colours below {lo:.2g} {unit} clipped"
    lo, hi = round_range(lo, hi, log=True)
    return lo, hi, note


def plot_slices(design: "Design", currents: Sequence[float] | None = None, *,
                quantity: Literal["B", "F"] = "B", moment=None, height_m: float | None = None,
                quality: Quality = "full", window_size=(1500, 640), data=None,
                blocks=None) -> "pyvista.Plotter":
    """Magnitude of B (mT) or of the force on the magnet (mN) on the vertical slice y = 0 (left)
    and on a horizontal slice at the design height (right); one log colour scale shared by both
    (each title says so), the coils' outlines and, for the force, the contour of the human
    threshold (0.8 mN); the force only where the magnet's centre can be (z >= workspace z_min)."""
    pv = import_pyvista()
    if quantity not in ("B", "F"):
        raise BadInputError("quantity", "'B' or 'F'", quantity)
    cur = resolve_currents(design, currents)
    h = design.optimize.height_m if height_m is None else height_m
    vert, horiz = (slice_data(design, cur, moment=moment, height_m=h, quality=quality)
                   if data is None else data)
    blocks = scene_meshes(design, cur) if blocks is None else blocks
    name = B_MT if quantity == "B" else F_MN
    # points inside a core or a winding are not in air: they are left out of the picture
    vert, horiz = (_drop_solids(mesh) for mesh in (vert, horiz))
    floor_note = ""
    if quantity == "F":  # the force only where the magnet's centre can be
        vert = _above(vert, design.workspace.z_min_m)
        floor_note = (f"; blank below z = {design.workspace.z_min_m * 1e3:g} mm, where the "
                      "magnet's centre cannot be")
    lo, hi, clip_note = _colour_range(np.r_[np.asarray(vert[name]), np.asarray(horiz[name])],
                                      "mT" if quantity == "B" else "mN")
    label = "B (mT)" if quantity == "B" else "F (mN)"
    threshold_mn = design.render.threshold_n * 1e3
    z_low_m = -0.25 * design.coil.length_m  # show the top quarter of the coils
    head = ("Magnitude of B" if quantity == "B"
            else f"Magnitude of the force on the magnet ({magnet_text(design, moment)})")
    p = new_plotter(pv, window_size, shape=(1, 2))
    for col, (mesh, view) in enumerate(((vert, "xz"), (horiz, "xy"))):
        p.subplot(0, col)
        mm = in_mm(mesh)
        p.add_mesh(mm, scalars=name, cmap="inferno", log_scale=True, clim=(lo, hi),
                   name=f"slice-{view}", show_scalar_bar=(col == 1),
                   scalar_bar_args=bar_args(label, fmt=log_format(lo, hi), position_x=0.88,
                                        width=0.045))
        notes = [currents_text(cur), "cyan dot: design point" + clip_note]
        scale = (f"colour: {label}, log scale {lo:g}..{hi:g}, one bar (right) for both "
                 "panels")
        if quantity == "F" and lo < threshold_mn < hi:
            iso = mm.contour([threshold_mn], scalars=name)
            if iso.n_points:
                p.add_mesh(iso, color="cyan", line_width=3, name=f"threshold-{view}")
                notes.append(f"cyan line: {threshold_mn:g} mN")
        p.add_mesh(_section_lines(pv, design, blocks, view, h, z_low_m), color="black",
                   line_width=2)
        dp = np.asarray(design.design_point_m) * 1e3
        dot = dp + ((0.0, -1.0, 0.0) if view == "xz" else (0.0, 0.0, 0.5))
        p.add_mesh(pv.PolyData(dot[None, :]), color="cyan", point_size=12,
                   render_points_as_spheres=True)
        bounds = list(mm.bounds)
        if view == "xz":
            where = ("vertical slice y = 0 (coils in outline below; blank: inside iron"
                     f"{floor_note})")
            bounds[4] = z_low_m * 1e3
            p.view_xz()
        else:
            where = f"horizontal slice z = {h * 1e3:.0f} mm"
            p.view_xy()
        add_title(p, f"{head}\n{where}\n{scale}\n" + "; ".join(notes), font_size=10)
        bounds, counts = nice_bounds(bounds)
        p.show_bounds(bounds=bounds, xtitle="x (mm)", ytitle="y (mm)", ztitle="z (mm)",
                      color="black", grid=False, location="front",
                      font_size=max(6, min(9, round(9 * p.window_size[0] / 1500))),
                      ticks="outside", show_yaxis=(view == "xy"), show_zaxis=(view == "xz"),
                      fmt="%g", **counts)
        p.enable_parallel_projection()
        p.reset_camera(bounds=bounds)
        p.camera.zoom(0.95 if view == "xz" else 0.9)  # room for the axis titles
        if view == "xy":
            # leave room for the colour bar on the right
            p.camera.position = tuple(np.asarray(p.camera.position) + (12.0, 0.0, 0.0))
            p.camera.focal_point = tuple(np.asarray(p.camera.focal_point) + (12.0, 0.0, 0.0))
    return p
