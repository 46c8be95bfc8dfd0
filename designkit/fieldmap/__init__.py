"""Map file v2: build it from a design, write it, load it (:class:`FieldMap`).

The format -- array names, shapes, validation, interpolation -- is defined once, in the
numpy-only reader :mod:`firmware_io.mapfile`; this package computes the arrays from a
:class:`~designkit.model.array.CoilArray`, writes them atomically, and :class:`FieldMap` wraps
:class:`firmware_io.mapfile.MapFile` with designkit's errors. All the physics the map samples
comes through one function, :func:`map_physics`.

* :mod:`.settings`: :class:`BuildSettings`, how densely a map samples;
* :mod:`.plan`: the box, the harmonic-cell layers, the fit lattices, the table grids;
* :mod:`.clearance`: how far the box is from the sources (the cells' scale);
* :mod:`.physics`: :class:`MapPhysics`, what the map samples;
* :mod:`.tables`: the per-core (rho, z) tables (magnet pull, sensor-field core modes);
* :mod:`.cells`: the least-squares fit of A's harmonic cells;
* :mod:`.builder`: :func:`build`, the build as named phases, checking itself;
* :mod:`.storage`: :func:`write` (atomic), :func:`load`, :class:`FieldMap`;
* :mod:`.symmetry`: the array's symmetries, one sample per orbit;
* :mod:`.region`: :func:`scene_region`, the box of a scene map.

Target: A within 1e-3 of each row's largest |A| over the box. The representation, its error
budget, the measured errors and costs, and the commands that measure them: docs/fieldmap.md.
"""

from .builder import FORMAT, FORMAT_VERSION, UNITS, build
from .settings import BuildSettings
from .cells import fit_layer, fit_layers
from .physics import MapPhysics, map_physics
from .plan import (box_axes, cell_layers, default_box, graded_axis, layer_nodes, rz_table_spec,
                   sources_top, table_specs, uniform_axis)
from .region import scene_band_m, scene_build_args, scene_region
from .storage import FieldMap, check_output, load, write
from .tables import (compute_magnet_table, compute_mode_tables, coupled_modes,
                     mode_table_entry)

__all__ = [
    "FORMAT", "FORMAT_VERSION", "UNITS", "BuildSettings", "build", "fit_layer", "fit_layers",
    "MapPhysics", "map_physics", "box_axes", "cell_layers", "default_box", "graded_axis",
    "layer_nodes", "rz_table_spec", "sources_top", "table_specs", "uniform_axis", "FieldMap",
    "check_output", "load", "write", "compute_magnet_table", "compute_mode_tables",
    "coupled_modes", "mode_table_entry", "scene_band_m", "scene_build_args",
    "scene_region",
]
