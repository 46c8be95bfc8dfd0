"""The device scene: windings coloured by current, cores, the magnet with its moment at the
design point and the workspace box (solids in m; the figure in mm)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from .common import MAGNET_RED, STEEL, CURRENT_A, import_pyvista
from .physics import magnet_moment, resolve_currents
from .style import add_axes, bar_args, currents_text, fit_camera, magnet_text, in_mm, new_plotter, add_title

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from ..design import Design


def scene_meshes(design: "Design", currents: Sequence[float] | None = None, *,
                 moment=None, resolution: int = 64) -> "pyvista.MultiBlock":
    """Solids of the device, m: windings (hollow cylinders, cell data ``"current (A)"``), cores,
    the finger magnet (cylinder at the design point) and the workspace box outline."""
    pv = import_pyvista()
    cur = resolve_currents(design, currents)
    c = design.coil
    windings, cores = [], []
    for (x, y, zc), current in zip(design.coil_centres_m(), cur):
        ring = pv.Disc(center=(x, y, zc - c.length_m / 2), inner=c.inner_radius_m,
                       outer=c.outer_radius_m, c_res=resolution)
        w = ring.extrude((0.0, 0.0, c.length_m), capping=True)
        w.cell_data[CURRENT_A] = np.full(w.n_cells, float(current))
        windings.append(w)
        if design.core is not None:
            core = pv.Cylinder(center=(x, y, zc + design.core.offset_m), direction=(0, 0, 1),
                               radius=design.core.radius_m, height=design.core.length_m,
                               resolution=resolution)
            cores.append(core)
    m = magnet_moment(design, moment)
    mag = design.magnet
    axis = m / np.linalg.norm(m) if np.linalg.norm(m) > 0 else np.array([0.0, 0.0, 1.0])
    magnet = pv.Cylinder(center=design.design_point_m, direction=axis, radius=mag.radius_m,
                         height=mag.length_m, resolution=resolution)
    ws = design.workspace
    box = pv.Box(bounds=(-ws.half_width_m, ws.half_width_m, -ws.half_width_m, ws.half_width_m,
                         ws.z_min_m, ws.z_max_m)).extract_all_edges()
    blocks = pv.MultiBlock()
    blocks["windings"] = pv.merge(windings)
    if cores:
        blocks["cores"] = pv.merge(cores)
    blocks["magnet"] = magnet
    blocks["workspace"] = box
    return blocks


def plot_array_scene(design: "Design", currents: Sequence[float] | None = None, *,
                     moment=None, window_size=(1024, 768), blocks=None) -> "pyvista.Plotter":
    """The coil array (windings coloured by current, cores), the magnet with its moment as an
    arrow at the design point, and the workspace box. Off-screen; never shown."""
    pv = import_pyvista()
    cur = resolve_currents(design, currents)
    blocks = scene_meshes(design, cur, moment=moment) if blocks is None else blocks
    m = magnet_moment(design, moment)
    p = new_plotter(pv, window_size)
    imax = float(np.max(np.abs(cur))) or 1.0
    p.add_mesh(in_mm(blocks["windings"]), scalars=CURRENT_A, cmap="coolwarm", clim=(-imax, imax),
               smooth_shading=True, name="windings",
               scalar_bar_args=bar_args("coil current (A)", fmt="%+.2g"))
    if "cores" in blocks.keys():
        p.add_mesh(in_mm(blocks["cores"]), color=STEEL, name="cores")
    p.add_mesh(in_mm(blocks["magnet"]), color=MAGNET_RED, name="magnet")
    p.add_mesh(in_mm(blocks["workspace"]), color="#1f4e9c", line_width=2, name="workspace")
    dp = np.asarray(design.design_point_m) * 1e3
    mdir = m / (np.linalg.norm(m) or 1.0)
    arrow = pv.Arrow(start=dp, direction=mdir, scale=30.0, tip_length=0.3, tip_radius=0.12,
                     shaft_radius=0.05)
    p.add_mesh(arrow, color="black", name="moment")
    p.add_point_labels([dp + mdir * 30.0 + np.array([8.0, 0.0, 0.0])], ["magnet moment m"],
                       font_size=12, text_color="black", shape=None, show_points=False,
                       always_visible=True)
    ws = design.workspace
    p.add_point_labels([(ws.half_width_m * 1e3, ws.half_width_m * 1e3, ws.z_max_m * 1e3)],
                       ["workspace"], font_size=12, text_color="#1f4e9c", shape=None,
                       show_points=False, always_visible=True)
    c = design.coil
    add_title(p, f"{design.name}: {design.array.describe()}; winding Ri/Ro/L = "
              f"{c.inner_radius_m * 1e3:.0f}/{c.outer_radius_m * 1e3:.0f}/"
              f"{c.length_m * 1e3:.0f} mm, {c.turns} turns\n"
              f"magnet ({magnet_text(design, moment)}) at the design point "
              f"z = {design.optimize.height_m * 1e3:.0f} mm; {currents_text(cur)}; windings "
              f"coloured by their current, linear scale {-imax:+.3g}..{imax:+.3g} A",
           font_size=10)
    fit_camera(p, add_axes(p), elevation_deg=22.0)
    return p
