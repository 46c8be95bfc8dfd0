"""Streamlines of B from the array, seeded on rings just above the energized coils' top faces
(in their poses), coloured by |B| (mT, log scale, the design's fixed range) over the device."""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from .common import B_MT, B_T, Quality, image_grid, import_pyvista, grid_resolution
from .physics import (FIELDLINE_TOLERANCE, add_field_arrays, footprint_half_m, array_field,
                      resolve_currents)
from .ranges import clip_note, colour_ranges
from .scene import pole_points_m, scene_meshes
from .style import (add_axes, add_device, add_title, bar_args, currents_text, fit_camera,
                    in_mm, log_format, new_plotter)

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from ..design import Design


SEED_LIFT_M = 0.004
"""How far above a coil's pole (its highest solid: the core's top or the winding's), along its
axis, its field lines start, m: in air, not inside the iron."""


def field_line_data(design: "Design", currents: Sequence[float] | None = None, *,
                    quality: Quality = "full"):
    """Streamlines of B from the array.

    Returns
    -------
    volume : pyvista.ImageData
        Grid around the array (coils and workspace), with ``"B (T)"`` and ``"B magnitude (mT)"``.
    lines : pyvista.PolyData
        Streamlines seeded on rings just above the energized coils, with the same arrays.
    """
    pv = import_pyvista()
    res = grid_resolution(quality)
    cur = resolve_currents(design, currents)
    half = footprint_half_m(design) + 0.02
    zlo = -max(design.coil_spec(k).length_m for k in range(design.n_coils)) - 0.03
    zhi = design.workspace.z_max_m + 0.03
    vol = image_grid(pv, (-half, -half, zlo), (half, half, zhi), res["volume"])
    b = array_field(design, vol.points, cur, gradient=False, tolerance=FIELDLINE_TOLERANCE)
    add_field_arrays(vol, b)
    seeds = []
    nring = 16 if quality == "full" else 10
    phi = np.linspace(0, 2 * np.pi, nring, endpoint=False)
    poles = pole_points_m(design, SEED_LIFT_M)
    for k in np.flatnonzero(cur):
        frame = design.coil_poses()[k].matrix
        for radius in (0.3, 0.6, 0.9) if quality == "full" else (0.4, 0.8):
            r = radius * design.coil_spec(k).outer_radius_m
            ring = r * (np.cos(phi)[:, None] * frame[:, 0] + np.sin(phi)[:, None] * frame[:, 1])
            seeds.append(poles[k] + ring)
    if not seeds:
        return vol, pv.PolyData()
    source = pv.PolyData(np.vstack(seeds))
    lines = vol.streamlines_from_source(source, vectors=B_T, integration_direction="both",
                                        max_steps=4000, initial_step_length=0.2,
                                        terminal_speed=1e-9, compute_vorticity=False)
    return vol, lines


def plot_field_lines(design: "Design", currents: Sequence[float] | None = None, *,
                     quality: Quality = "full", window_size=(1024, 768), data=None,
                     blocks=None) -> "pyvista.Plotter":
    """Streamlines of B coloured by the magnitude of B (mT, log scale, the design's fixed range)
    over the coil array."""
    pv = import_pyvista()
    cur = resolve_currents(design, currents)
    vol, lines = field_line_data(design, cur, quality=quality) if data is None else data
    blocks = scene_meshes(design, cur) if blocks is None else blocks
    p = new_plotter(pv, window_size)
    add_device(p, design, blocks, opacity=0.3, magnet=True, workspace=True)
    lo, hi = colour_ranges(design).b_mt
    scale = ""
    if lines.n_points:
        bmt = np.asarray(lines[B_MT])
        scale = (f"; colour: B (mT), log scale {lo:g}..{hi:g}, the design's fixed range"
                 + clip_note(bmt, lo, hi, "mT"))
        p.add_mesh(in_mm(lines).tube(radius=0.7), scalars=B_MT, cmap="viridis", log_scale=True,
                   clim=(lo, hi), name="streamlines",
                   scalar_bar_args=bar_args("B (mT)", fmt=log_format(lo, hi)))
    else:
        p.add_text("no field: all coils at 0 A", position="lower_left", color="black")
    p.add_mesh(in_mm(vol.outline()), color="grey", line_width=1)
    add_title(p, f"Field lines of B, coloured by its magnitude (log scale)\n{currents_text(cur)}; "
              f"lines end at the edge of the computed box{scale}", font_size=11)
    fit_camera(p, add_axes(p), elevation_deg=12.0)
    return p
