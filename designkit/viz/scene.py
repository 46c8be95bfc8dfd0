"""The device scene: each coil's winding (coloured by its current) and core in its pose, the
magnet with its moment at the design point and the workspace's outline (solids in m; the figure
in mm)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from .common import CURRENT_A, MAGNET_RED, STEEL, import_pyvista
from .physics import magnet_moment, resolve_currents
from .ranges import colour_ranges
from .style import (add_axes, add_title, bar_args, currents_text, fit_camera, in_mm,
                    magnet_text, new_plotter, nice_bounds)

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from ..design import Design
    from ..geometry.pose import Pose


def pose_matrix(pose: "Pose") -> np.ndarray:
    """The 4 x 4 homogeneous transform of a pose (local -> array frame, m)."""
    t = np.eye(4)
    t[:3, :3] = pose.matrix
    t[:3, 3] = pose.position
    return t


def coil_solids(design: "Design", k: int, resolution: int = 64):
    """Coil k's winding (hollow cylinder) and core (cylinder, or None) in its pose, m."""
    pv = import_pyvista()
    c, core = design.coil_spec(k), design.core_spec(k)
    t = pose_matrix(design.coil_poses()[k])
    ring = pv.Disc(center=(0.0, 0.0, -c.length_m / 2), inner=c.inner_radius_m,
                   outer=c.outer_radius_m, c_res=resolution)
    # triangles: a plane cuts a triangulated cap into one closed line (a 64-gon into dashes)
    winding = ring.extrude((0.0, 0.0, c.length_m), capping=True).triangulate().transform(
        t, inplace=False)
    if core is None:
        return winding, None
    iron = pv.Cylinder(center=(0.0, 0.0, core.offset_m), direction=(0, 0, 1),
                       radius=core.radius_m, height=core.length_m, resolution=resolution)
    return winding, iron.triangulate().transform(t, inplace=False)


def workspace_outline(design: "Design") -> "pyvista.PolyData":
    """The edges of the workspace prism (its outline at z_min and z_max and the vertical edges
    joining them), m."""
    pv = import_pyvista()
    ws = design.workspace_region()
    o = ws.outline
    k = len(o)
    pts = np.vstack([np.c_[o, np.full(k, ws.z_min_m)], np.c_[o, np.full(k, ws.z_max_m)]])
    lines = []
    for i in range(k):
        j = (i + 1) % k
        lines += [[2, i, j], [2, k + i, k + j], [2, i, k + i]]
    return pv.PolyData(pts, lines=np.array(lines).ravel())


def scene_meshes(design: "Design", currents: Sequence[float] | None = None, *,
                 moment=None, resolution: int = 64) -> "pyvista.MultiBlock":
    """Solids of the device, m: windings (hollow cylinders in their poses, cell data
    ``"current (A)"``), cores, the finger magnet (a cylinder at the design point along its
    moment) and the workspace's outline."""
    pv = import_pyvista()
    cur = resolve_currents(design, currents)
    windings, cores = [], []
    for k, current in enumerate(cur):
        w, core = coil_solids(design, k, resolution)
        w.cell_data[CURRENT_A] = np.full(w.n_cells, float(current))
        windings.append(w)
        if core is not None:
            cores.append(core)
    m = magnet_moment(design, moment)
    mag = design.magnet
    axis = m / np.linalg.norm(m) if np.linalg.norm(m) > 0 else np.array([0.0, 0.0, 1.0])
    magnet = pv.Cylinder(center=np.asarray(design.design_point_m), direction=axis,
                         radius=mag.radius_m,
                         height=mag.length_m, resolution=resolution)
    blocks = pv.MultiBlock()
    blocks["windings"] = pv.merge(windings)
    if cores:
        blocks["cores"] = pv.merge(cores)
    blocks["magnet"] = magnet
    blocks["workspace"] = workspace_outline(design)
    return blocks


def pole_points_m(design: "Design", lift_m: float) -> np.ndarray:
    """(n, 3) m: a point on each coil's axis ``lift_m`` above its pole, its highest solid (the
    core's top face when the core stands above the winding, else the winding's)."""
    tops = np.asarray(design.array.top_centres_m(), dtype=float)
    axes = np.asarray(design.array.axes(), dtype=float)
    out = np.empty_like(tops)
    for k in range(len(tops)):
        c, core = design.coil_spec(k), design.core_spec(k)
        above = 0.0 if core is None else max(0.0, core.offset_m + core.length_m / 2
                                             - c.length_m / 2)
        out[k] = tops[k] + (above + lift_m) * axes[k]
    return out


def coil_top_discs(design: "Design", currents, resolution: int = 64) -> "pyvista.PolyData":
    """Each coil's top face (the winding's annulus, in its pose), m, cell data
    ``"current (A)"``: the top view of the scene."""
    pv = import_pyvista()
    discs = []
    for k, (pose, current) in enumerate(zip(design.coil_poses(), currents)):
        c = design.coil_spec(k)
        disc = pv.Disc(center=(0.0, 0.0, c.length_m / 2), inner=c.inner_radius_m,
                       outer=c.outer_radius_m, c_res=resolution).triangulate()
        disc = disc.transform(pose_matrix(pose), inplace=False)
        disc.cell_data[CURRENT_A] = np.full(disc.n_cells, float(current))
        discs.append(disc)
    return pv.merge(discs)


DESIGN_POINT_RING_MM = 8.0
"""Radius of the top view's ring about the design point, mm (a marker, clear of the number)."""
SCENE_PANELS = (3, 2)
"""Relative widths of the scene's two panels: the device in 3-D, its top view."""


def plot_array_scene(design: "Design", currents: Sequence[float] | None = None, *,
                     moment=None, window_size=(1280, 640), blocks=None) -> "pyvista.Plotter":
    """Left: the coil array in 3-D (windings coloured by current on the design's fixed
    -limit..+limit scale, cores), the magnet at the design point with its moment as an arrow,
    and the workspace's outline. Right: the top view, each coil's top face coloured by its
    current and numbered, the design point and the workspace. Off-screen; never shown."""
    pv = import_pyvista()
    cur = resolve_currents(design, currents)
    blocks = scene_meshes(design, cur, moment=moment) if blocks is None else blocks
    m = magnet_moment(design, moment)
    lo, hi = colour_ranges(design).current_a
    p = new_plotter(pv, window_size, shape=(1, 2), col_weights=SCENE_PANELS)
    p.subplot(0, 0)
    p.add_mesh(in_mm(blocks["windings"]), scalars=CURRENT_A, cmap="coolwarm", clim=(lo, hi),
               smooth_shading=True, name="windings", show_scalar_bar=False)
    if "cores" in blocks.keys():
        p.add_mesh(in_mm(blocks["cores"]), color=STEEL, name="cores")
    p.add_mesh(in_mm(blocks["magnet"]), color=MAGNET_RED, name="magnet")
    p.add_mesh(in_mm(blocks["workspace"]), color="#1f4e9c", line_width=2, name="workspace")
    dp = np.asarray(design.design_point_m) * 1e3
    mdir = m / (np.linalg.norm(m) or 1.0)
    # the arrow ends at the magnet, on the side its moment comes from: clear of the coils
    length = 25.0
    start = dp - mdir * (length + design.magnet.length_m * 1e3 / 2 + 2.0)
    p.add_mesh(pv.Arrow(start=start, direction=mdir, scale=length, tip_length=0.3,
                        tip_radius=0.12, shaft_radius=0.05), color="black", name="moment")
    k = design.design_coil
    c = design.coil_spec(k)
    add_title(p, f"{design.name}: {design.array.describe()}\n"
                 f"winding Ri/Ro/L = {c.inner_radius_m * 1e3:.3g}/{c.outer_radius_m * 1e3:.3g}/"
                 f"{c.length_m * 1e3:.3g} mm, {c.turns} turns"
                 + ("" if not design.groups else f" (coil {k + 1}; others: the design's groups)")
                 + f"\nmagnet ({magnet_text(design, moment)}) at the design point, "
                 f"{design.optimize.height_m * 1e3:.0f} mm above coil {k + 1} on its axis; "
                 "black arrow: its moment; blue: the workspace", font_size=10)
    fit_camera(p, add_axes(p), elevation_deg=22.0)
    p.subplot(0, 1)
    _top_view(p, pv, design, cur, (lo, hi))
    return p


def _top_view(p, pv, design, cur, clim) -> None:
    """The scene's right panel: coil tops from above, numbered, coloured by current."""
    lo, hi = clim
    p.add_mesh(in_mm(coil_top_discs(design, cur)), scalars=CURRENT_A, cmap="coolwarm",
               clim=(lo, hi), name="coil-tops", lighting=False,
               scalar_bar_args=bar_args("I (A)", fmt="%+.2g", position_x=0.86, width=0.05,
                                        n_labels=5))
    tops = np.asarray(design.array.top_centres_m(), dtype=float) * 1e3
    # the workspace's outline under the coils, and each bore's mouth white: where the outline
    # crosses a coil (a ring's outline runs through its coils' tops) the coil and its number
    # stay on top
    below = np.array([0.0, 0.0, min(0.0, float(tops[:, 2].min())) - COIL_LEAN_DEPTH_MM])
    p.add_mesh(in_mm(blocks_outline(design)).translate(below), color="#1f4e9c", line_width=2,
               name="outline")
    p.add_mesh(in_mm(bore_mouths(design)), color="white", lighting=False, name="bores")
    lift = np.array([0.0, 0.0, 1.0 + max(0.0, float(tops[:, 2].max()))])
    p.add_point_labels(tops + lift, [str(k + 1) for k in range(len(tops))], font_size=12,
                       text_color="black", shape=None, show_points=False, always_visible=True,
                       justification_horizontal="center", justification_vertical="center",
                       name="coil-numbers")
    # a ring about the design point, wide enough to leave the coil's number inside it readable
    dp = np.asarray(design.design_point_m) * 1e3
    ring = pv.Circle(radius=DESIGN_POINT_RING_MM, resolution=48).extract_feature_edges()
    p.add_mesh(ring.translate(dp + lift - (0.0, 0.0, dp[2])), color="cyan", line_width=3,
               name="design-point")  # cyan as the design point of the sections
    over = ("" if not np.any(np.abs(cur) > hi * (1 + 1e-9)) else
            f" (beyond: the end colours)")
    add_title(p, f"top view: coil numbers; colour: the coil's current, {lo:+.3g}..{hi:+.3g} A, "
                 f"the per-coil limit{over}; cyan ring: about the design point\n"
                 f"{currents_text(cur)}",
              font_size=10)
    p.view_xy()
    p.enable_parallel_projection()
    b = list(p.bounds)
    bounds, counts = nice_bounds(b)
    p.show_bounds(bounds=bounds, xtitle="x (mm)", ytitle="y (mm)", color="black", grid=False,
                  location="front", font_size=8, ticks="outside", show_zaxis=False, fmt="%g",
                  **counts)
    p.reset_camera(bounds=bounds)
    p.camera.zoom(0.8)


COIL_LEAN_DEPTH_MM = 30.0
"""How far below the coil tops' plane the top view draws the workspace's outline, mm: below
the lowest point of a leaning coil's top face."""


def bore_mouths(design: "Design", resolution: int = 48) -> "pyvista.PolyData":
    """Each coil's bore at its top face (a disc of the winding's inner radius in its pose), m."""
    pv = import_pyvista()
    discs = []
    for k, pose in enumerate(design.coil_poses()):
        c = design.coil_spec(k)
        disc = pv.Disc(center=(0.0, 0.0, c.length_m / 2), inner=0.0, outer=c.inner_radius_m,
                       c_res=resolution).triangulate()
        discs.append(disc.transform(pose_matrix(pose), inplace=False))
    return pv.merge(discs)


def blocks_outline(design: "Design") -> "pyvista.PolyData":
    """The workspace's outline at its floor (z_min), m: the top view's blue line."""
    pv = import_pyvista()
    o = design.workspace_region().outline
    k = len(o)
    lines = np.array([[2, i, (i + 1) % k] for i in range(k)]).ravel()
    return pv.PolyData(np.c_[o, np.zeros(k)], lines=lines)
