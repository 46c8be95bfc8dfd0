"""Soft-iron cores: materials, the single-core panel model, the fast rod model, the coupled
array solve and the saturation correction.

- :mod:`.material`: the 1010 steel B-H curve (one table) and its interpolations;
- :mod:`.panel`: :class:`Core` and its surface-current (panel) and thesis-uniform models;
- :mod:`.solution`, :mod:`.quadrature`, :mod:`.discretization`: the solved currents, their
  field evaluation and the panels both solves share;
- :mod:`.rod`: the fast saturating rod model of the optimizer;
- :mod:`.core_model`, :mod:`.charges`, :mod:`.coupled`: all cores of an array solved together;
- :mod:`.saturation`: the saturation warning and the per-coil saturation table.

Models and measured accuracy: docs/core_model.md and docs/coupling.md.
"""

from .core_model import M_MAX, CoreModel, core_model
from .coupled import ArraySystem
from .material import (BH_CURVES, KNEE_T, STEEL1010_B, STEEL1010_H, steel1010_h,
                       steel1010_h_smooth, steel1010_mu_r)
from .nagaoka import demagnetizing_factor, nagaoka_self
from .panel import CORE_MODELS, Core
from .quadrature import EVAL_RTOL
from .rod import RodBatch, RodGeometry, RodSettings, RodSolution, solve_rod, solve_rods
from .saturation import SaturationWarning, saturation_table
from .solution import CoreSolution

__all__ = [
    "ArraySystem", "BH_CURVES", "CORE_MODELS", "Core", "CoreModel", "CoreSolution",
    "EVAL_RTOL", "KNEE_T", "M_MAX", "RodBatch", "RodGeometry", "RodSettings", "RodSolution", "STEEL1010_B", "STEEL1010_H",
    "SaturationWarning", "core_model", "demagnetizing_factor", "nagaoka_self",
    "saturation_table", "solve_rod", "solve_rods", "steel1010_h", "steel1010_h_smooth",
    "steel1010_mu_r",
]
