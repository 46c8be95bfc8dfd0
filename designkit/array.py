"""The coil array under its first name: ``designkit.array.CoilArray`` is
:class:`designkit.model.array.CoilArray` (the package face keeps user imports working)."""

from .model.array import (ROWS, CoilArray, array_for_design, force_matrix, g5_from_gradient,
                          gradient_from_g5, skew_matrix)
from .model.metrics import condition_number, fz_per_amp, max_vertical_force, workspace_metrics

__all__ = ["ROWS", "CoilArray", "array_for_design", "condition_number", "force_matrix",
           "fz_per_amp", "g5_from_gradient", "gradient_from_g5", "max_vertical_force",
           "skew_matrix", "workspace_metrics"]
