"""The rule book: every buildability rule of a design, defined once, as functions of it.

Input: a :class:`designkit.design.Design` (SI, m), any layout. Output: :func:`rules` -> a list
of :class:`Rule` (value, limit, unit, which side is allowed, the design keys that fix it and a
sentence with the fix). The optimizer bounds its variables by :func:`pitch_clearance_m` and
:func:`max_core_protrusion_m` so its optima satisfy these rules; ``designkit check`` prints
them, ``report`` lists them with the device constraints, ``cad`` refuses a design that
violates one. :func:`assembly` is the printed assembly's derived geometry (coil types, seats,
frame plates, fixings, sensor holders), which cad/params.py converts to millimetres.

:mod:`.convex` (signed distance of convex solids), :mod:`.geometry` (the derived geometry),
:mod:`.clearance` (solid to solid, in their poses), :mod:`.reach` (how low the magnet goes),
:mod:`.driver` (the supply and the PWM within the driver's ratings), :mod:`.saturation` (the
coil currents that saturate each Hall sensor, reported by ``check``), :mod:`.book` (the rules in
report order). Conventions: coil top faces of an upright array at z = 0; "reach" is how far the
coil stack rises above a winding end plane. Rationale of each rule: docs/rules.md.
"""

from .geometry import (MAX_OVERHANG_DEG, Assembly, CoilType, Plate, Seat, assembly, board_top_m,
                       clip_polygon, coil_types, max_core_protrusion_m, pitch_clearance_m)
from .book import rules, violations
from .clearance import board_solids, coil_solid, lattice_gap_m, layout_keys
from .convex import Box, Cylinder, Prism, signed_distance
from .driver import driver_rules
from .reach import design_point_floor_m, reachable_height_m
from .rule import TOLERANCE_M, Rule
from .saturation import sensor_saturation

__all__ = ["MAX_OVERHANG_DEG", "Assembly", "CoilType", "Plate", "Seat", "assembly",
           "board_top_m", "clip_polygon", "coil_types", "max_core_protrusion_m", "pitch_clearance_m", "rules",
           "violations", "board_solids", "coil_solid", "lattice_gap_m", "layout_keys", "Box", "Cylinder", "Prism",
           "signed_distance", "driver_rules", "design_point_floor_m", "reachable_height_m", "TOLERANCE_M",
           "Rule", "sensor_saturation"]
