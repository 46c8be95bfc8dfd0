"""Off-screen pyvista figures and ParaView (VTK) files of a design's coils, fields and forces.

Two layers:

* data builders (``scene_meshes``, ``field_line_data``, ``slice_data``, ``force_map_data``,
  ``force_isosurface_data``) evaluate the array's field on a grid and return pyvista datasets in
  the design frame (metres, coil top faces at z = 0, z up) carrying SI arrays
  (``"B (T)"``, ``"grad B (T/m)"``, ``"F (N)"``) and, for colouring, the same magnitudes in the
  units people read (``"B magnitude (mT)"``, ``"F magnitude (mN)"``, ``"Fz (mN)"``);
* ``plot_*`` functions turn them into a :class:`pyvista.Plotter` (``off_screen=True``, never
  shown) drawn in millimetres with titles and colour bars; :func:`save_png` writes it atomically
  and :func:`export_vtk` writes the datasets as ``.vtp`` / ``.vts`` files for ParaView.

The force on the finger magnet is ``F = (grad B)^T m`` (thesis eq. 2.5) with ``m`` the design's
magnet moment unless another is given. The design point
(:attr:`designkit.design.Design.design_point_m`): the magnet's centre at the design height above
the coil nearest the layout's centre (``Design.design_coil``), on its axis; the sections pass through it. Default currents (``currents=None``): the coil nearest
the design point at ``drive.max_current_a``, every other coil at 0 A (skipped when the field is
evaluated). Colour ranges are the design's (:func:`colour_ranges`), whatever the currents. pyvista is imported lazily: without it the figures raise
:class:`designkit.errors.MissingDependencyError` ("designkit.viz needs pyvista: pip install
pyvista"). Figure by figure: docs/figures.md.
"""

from __future__ import annotations

from .common import (B_MT, B_T, CURRENT_A, F_MN, F_N, FZ_MN, GRAD_T_M, IN_SOLID, KINDS,
                     MIN_ARROW, QUALITIES, REACH_M, Kind, Quality)
from .fieldlines import field_line_data, plot_field_lines
from .forcemap import force_map_data, plot_force_map
from .isosurface import force_isosurface_data, plot_force_isosurface
from .output import FigureSet, export_vtk, render, save_png, write_figures
from .physics import (array_field, force_from_gradient,
                      inside_solids, magnet_moment, nearest_coil, resolve_currents,
                      solid_distance_m)
from .ranges import ColourRanges, colour_ranges
from .scene import plot_array_scene, scene_meshes
from .slices import Section, plot_slices, section_plane, slice_data
from .style import bar_label_values, currents_text, nice_ticks

__all__ = ["B_MT", "B_T", "CURRENT_A", "F_MN", "F_N", "FZ_MN", "GRAD_T_M", "IN_SOLID", "KINDS",
           "MIN_ARROW", "QUALITIES", "REACH_M", "Kind", "Quality", "array_field",
           "bar_label_values", "export_vtk", "field_line_data", "force_from_gradient",
           "force_isosurface_data", "force_map_data", "inside_solids", "magnet_moment",
           "nice_ticks", "plot_array_scene", "plot_field_lines", "plot_force_isosurface",
           "plot_force_map", "plot_slices", "render", "resolve_currents", "save_png",
           "scene_meshes", "slice_data", "currents_text", "FigureSet", "write_figures",
           "nearest_coil", "solid_distance_m", "ColourRanges",
           "colour_ranges", "Section", "section_plane"]
