"""|B| and the force on the magnet on two sections through the design point: a vertical one
(along the design coil's lean, or x) and a horizontal one at the design point's height, with the
coils cut by the sections drawn exactly in their poses; points inside a core or a winding are
cut out of the picture along the solids' surfaces."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, Sequence

import numpy as np

from ..errors import BadInputError
from ..support import validate as v
from .common import B_MT, F_MN, IN_SOLID, Quality, grid_resolution, image_grid, import_pyvista
from .physics import (PICTURE_TOLERANCE, add_field_arrays, array_field,
                      footprint_half_m, magnet_moment, resolve_currents,
                      solid_distance_m)
from .ranges import clip_note, colour_ranges
from .scene import pose_matrix, scene_meshes
from .style import (add_title, bar_args, currents_text, in_mm, log_format, magnet_text,
                    new_plotter, nice_bounds)

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from ..design import Design

SOLID_DISTANCE_M = "distance to the nearest solid (m)"
"""Point data of the slices: :func:`designkit.viz.physics.solid_distance_m` (< 0 inside)."""
DRAWN_COIL_FRACTION = 0.25
"""How much of the design coil's length the vertical section shows below the coil tops."""


@dataclass(frozen=True)
class Section:
    """The vertical section plane: through ``point_m`` (the design point, m), spanned by z and
    the horizontal unit vector ``along`` (the design coil's lean, else +x); ``normal`` = z x
    ``along``. In-plane coordinate s = p . along, m."""

    point_m: np.ndarray
    along: np.ndarray
    normal: np.ndarray

    def to_plane(self) -> np.ndarray:
        """4 x 4 transform of the array frame onto the drawing frame: s along x, the plane at
        y = 0, z unchanged (a rotation about z and a shift along the normal)."""
        t = np.eye(4)
        t[0, :3], t[1, :3] = self.along, self.normal
        t[1, 3] = -float(self.normal @ self.point_m)
        return t

    def axis_title(self) -> str:
        a = self.along
        if np.allclose(a, (1.0, 0.0, 0.0)):
            return "x (mm)"
        if np.allclose(a, (0.0, 1.0, 0.0)):
            return "y (mm)"
        return f"s (mm) along ({a[0]:.2f}, {a[1]:.2f}, 0)"

    def describe(self) -> str:
        """'y = 25 mm' (a plane along x), 'x = 10 mm' or 'along (0.50, 0.87, 0)'."""
        if np.allclose(self.along, (1.0, 0.0, 0.0)):
            return f"y = {self.point_m[1] * 1e3:.4g} mm"
        if np.allclose(self.along, (0.0, 1.0, 0.0)):
            return f"x = {self.point_m[0] * 1e3:.4g} mm"
        return f"along ({self.along[0]:.2f}, {self.along[1]:.2f}, 0)"


def section_plane(design: "Design") -> Section:
    """The vertical section through the design point: it holds the design coil's axis (for a
    leaning coil, the plane of its lean; for an upright one, the plane along x)."""
    dp = np.asarray(design.design_point_m)
    axis = np.asarray(design.array.axes()[design.design_coil], dtype=float)
    lean = np.array([axis[0], axis[1], 0.0])
    if np.linalg.norm(lean) < 1e-9:
        along = np.array([1.0, 0.0, 0.0])
    else:
        along = lean / np.linalg.norm(lean)
        first = along[np.flatnonzero(np.abs(along) > 1e-12)[0]]
        along = along * np.sign(first)  # s increases to +x (or +y): the view is not mirrored
    along = np.where(np.abs(along) < 1e-15, 0.0, along)
    return Section(dp, along, np.array([-along[1], along[0], 0.0]))


def slice_data(design: "Design", currents: Sequence[float] | None = None, *,
               moment=None, height_m: float | None = None, quality: Quality = "full"):
    """|B| and the force on the magnet on the vertical section through the design point
    (:func:`section_plane`) and on a horizontal section.

    The vertical section spans the array's footprint along the plane and, in z, from
    :data:`DRAWN_COIL_FRACTION` of the design coil's length below the coil tops to the top of the
    workspace; the horizontal one spans the footprint at ``height_m`` (default: the design
    point's height). Both carry :data:`SOLID_DISTANCE_M` and ``IN_SOLID`` (1 inside a winding or
    a core).

    Returns
    -------
    vertical : pyvista.StructuredGrid
    horizontal : pyvista.ImageData
        Flat grids with ``"B (T)"``, ``"B magnitude (mT)"``, ``"grad B (T/m)"``, ``"F (N)"``,
        ``"F magnitude (mN)"`` and ``"Fz (mN)"``.
    """
    pv = import_pyvista()
    res = grid_resolution(quality)
    cur = resolve_currents(design, currents)
    m = magnet_moment(design, moment)
    sec = section_plane(design)
    h = float(sec.point_m[2]) if height_m is None else v.positive("height_m", height_m)
    half = footprint_half_m(design)
    nx, nz = res["slice"]
    s = np.linspace(-half, half, nx)
    z = np.linspace(_z_low(design), design.workspace.z_max_m, nz)
    foot = sec.point_m - (sec.point_m @ sec.along) * sec.along  # s = 0 on the plane, z = 0
    ss, zz = np.meshgrid(s, z, indexing="ij")
    xyz = (foot[None, None, :] + ss[..., None] * sec.along[None, None, :])
    vert = pv.StructuredGrid(xyz[..., 0][:, None, :], xyz[..., 1][:, None, :],
                             zz[:, None, :])
    horiz = image_grid(pv, (-half, -half, h), (half, half, h), (nx, nx, 1))
    for mesh in (vert, horiz):
        b, g = array_field(design, mesh.points, cur, gradient=True,
                           tolerance=PICTURE_TOLERANCE)
        add_field_arrays(mesh, b, g, m)
        dist = solid_distance_m(design, mesh.points)
        mesh.point_data[SOLID_DISTANCE_M] = dist
        mesh.point_data[IN_SOLID] = (dist <= 0.0).astype(np.uint8)
        mesh.field_data[MOMENT_A_M2] = m  # what F was computed for (the figure's title)
    return vert, horiz


MOMENT_A_M2 = "moment (A m^2)"
"""The field-data entry of :func:`slice_data`'s sections: the magnet moment of their force."""


def _z_low(design: "Design") -> float:
    """Bottom of the vertical section, m: a quarter of the design coil's length below the tops."""
    return -DRAWN_COIL_FRACTION * design.coil_spec(design.design_coil).length_m


def _air(mesh):
    """The slice cut along the solids' surfaces (the zero of the signed distance): air only."""
    if SOLID_DISTANCE_M not in mesh.point_data.keys():
        return mesh
    if np.asarray(mesh[SOLID_DISTANCE_M]).min() > 0.0:
        return mesh
    return mesh.clip_scalar(scalars=SOLID_DISTANCE_M, value=0.0, invert=False)


def _section_lines(pv, design, blocks, sec: Section, view: Literal["xz", "xy"], height_m,
                   z_low_m):
    """The coils in the section views, m (drawing frame): the solids cut by the vertical plane,
    or the rims of the coils' top faces (winding and core) seen from above, laid on the
    horizontal section."""
    solids = [blocks[key] for key in ("windings", "cores") if key in blocks.keys()]
    if view == "xz":
        cut = pv.merge([s.slice(normal=sec.normal, origin=sec.point_m) for s in solids])
        if cut.n_points:
            cut = cut.clip(normal=(0, 0, 1), origin=(0, 0, z_low_m), invert=False)
        return cut.transform(sec.to_plane(), inplace=False) if cut.n_points else cut
    rims = []
    for k, pose in enumerate(design.coil_poses()):
        c, core = design.coil_spec(k), design.core_spec(k)
        circles = [(r, c.length_m / 2) for r in (c.inner_radius_m, c.outer_radius_m)]
        if core is not None:
            circles.append((core.radius_m, core.offset_m + core.length_m / 2))
        for radius, z_local in circles:
            rim = pv.Circle(radius=radius, resolution=72).translate((0.0, 0.0, z_local))
            rims.append(rim.extract_feature_edges().transform(pose_matrix(pose),
                                                              inplace=False))
    top = pv.merge(rims)
    top.points[:, 2] = height_m + 1e-4
    return top


def plot_slices(design: "Design", currents: Sequence[float] | None = None, *,
                quantity: Literal["B", "F"] = "B", quality: Quality = "full",
                window_size=(1500, 640), data=None, blocks=None) -> "pyvista.Plotter":
    """Magnitude of B (mT) or of the force on the magnet (mN) on the vertical section through
    the design point (left) and on a horizontal section at its height (right); one log colour
    scale, the design's fixed one (:func:`designkit.viz.ranges.colour_ranges`), shared by both;
    the coils cut by the sections and, for the force, the contour of the human threshold; the
    force only where the magnet's centre can be (z >= workspace z_min). ``data``: the two
    sections of :func:`slice_data` (None: made here, at the design point's height, for the
    design's magnet; another height or moment: make them with :func:`slice_data`)."""
    pv = import_pyvista()
    if quantity not in ("B", "F"):
        raise BadInputError("quantity", "'B' or 'F'", quantity)
    cur = resolve_currents(design, currents)
    sec = section_plane(design)
    vert, horiz = (slice_data(design, cur, height_m=float(sec.point_m[2]), quality=quality)
                   if data is None else data)
    h = float(horiz.points[0, 2])
    moment = np.asarray(horiz.field_data[MOMENT_A_M2], dtype=float)
    blocks = scene_meshes(design, cur) if blocks is None else blocks
    ranges = colour_ranges(design)
    name = B_MT if quantity == "B" else F_MN
    unit = "mT" if quantity == "B" else "mN"
    # points inside a core or a winding are not in air: cut out along the solids' surfaces
    vert, horiz = (_air(mesh) for mesh in (vert, horiz))
    if quantity == "F":  # the force only where the magnet's centre can be
        vert = vert.clip(normal=(0, 0, 1), origin=(0, 0, design.workspace.z_min_m),
                         invert=False)
    lo, hi = ranges.b_mt if quantity == "B" else ranges.f_mn
    clipped = clip_note(np.r_[np.asarray(vert[name]), np.asarray(horiz[name])], lo, hi, unit)
    label = f"{'B' if quantity == 'B' else 'F'} ({unit})"
    threshold_mn = design.render.threshold_n * 1e3
    z_low_m = _z_low(design)
    head = ("Magnitude of B (mT)" if quantity == "B"
            else f"Force on the magnet ({magnet_text(design, moment)}), magnitude in mN")
    scale = (f"colour: log scale {lo:g}..{hi:g} {unit}, the design's fixed range; one bar "
             f"(right) for both panels{clipped}")
    dp = sec.point_m
    p = new_plotter(pv, window_size, shape=(1, 2))
    for col, (mesh, view) in enumerate(((vert, "xz"), (horiz, "xy"))):
        p.subplot(0, col)
        mm = in_mm(mesh.transform(sec.to_plane(), inplace=False) if view == "xz" else mesh)
        p.add_mesh(mm, scalars=name, cmap="inferno", log_scale=True, clim=(lo, hi),
                   name=f"slice-{view}", show_scalar_bar=(col == 1),
                   scalar_bar_args=bar_args(label, fmt=log_format(lo, hi), position_x=0.88,
                                            width=0.045))
        notes = []
        if quantity == "F" and lo < threshold_mn < hi and mm.n_points:
            iso = mm.contour([threshold_mn], scalars=name)
            if iso.n_points:
                p.add_mesh(iso, color="cyan", line_width=3, name=f"threshold-{view}")
                notes.append(f"cyan line: {threshold_mn:g} mN")
        lines = _section_lines(pv, design, blocks, sec, view, h, z_low_m)
        if lines.n_points:
            p.add_mesh(in_mm(lines), color="black", line_width=2, name=f"coils-{view}")
        if view == "xz":
            dot = (sec.to_plane() @ np.r_[dp, 1.0])[:3] * 1e3 + (0.0, -1.0, 0.0)
        else:
            dot = dp * 1e3 + (0.0, 0.0, 0.5)
        p.add_mesh(pv.PolyData(dot[None, :]), color="cyan", point_size=12,
                   render_points_as_spheres=True)
        bounds = list(mm.bounds) if mm.n_points else list(np.r_[-1, 1, -1, 1, -1, 1] * 1e2)
        if view == "xz":
            blank = ("inside the coils" if quantity == "B" else "inside the coils and below "
                     f"z = {design.workspace.z_min_m * 1e3:g} mm (the magnet's centre cannot "
                     "be there)")
            text = [f"{head}: vertical section {sec.describe()} through the design point (cyan "
                    "dot)", f"coils cut by it in black; blank: {blank}",
                    "; ".join([currents_text(cur)] + notes)]
            bounds[4] = min(bounds[4], z_low_m * 1e3)
            p.view_xz()
        else:
            text = [f"{head}: horizontal section z = {h * 1e3:.3g} mm through the design point",
                    "; ".join(["black: the coil tops seen from above"] + notes), scale]
            p.view_xy()
        add_title(p, "\n".join(text), font_size=10)
        bounds, counts = nice_bounds(bounds)
        p.show_bounds(bounds=bounds, xtitle=sec.axis_title() if view == "xz" else "x (mm)",
                      ytitle="y (mm)", ztitle="z (mm)", color="black", grid=False,
                      location="front",
                      font_size=max(6, min(9, round(9 * p.window_size[0] / 1500))),
                      ticks="outside", show_yaxis=(view == "xy"), show_zaxis=(view == "xz"),
                      fmt="%g", **counts)
        p.enable_parallel_projection()
        p.reset_camera(bounds=bounds)
        p.camera.zoom(0.95 if view == "xz" else 0.9)  # room for the axis titles
        # room for the colour bar on the right of the right panel, for the z axis's title on the
        # left of the left one
        shift = np.array([12.0 if view == "xy" else -0.04 * (bounds[1] - bounds[0]), 0.0, 0.0])
        p.camera.position = tuple(np.asarray(p.camera.position) + shift)
        p.camera.focal_point = tuple(np.asarray(p.camera.focal_point) + shift)
    return p
