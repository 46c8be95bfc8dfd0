"""The device model: a coil (winding + core, :mod:`.coil`), its electrical and thermal model
(:mod:`.electrical`), the array of coils in poses with its actuation matrix, bias force and
sensor fields (:mod:`.array`), where the coils' solids meet (:mod:`.overlap`), the workspace
metrics (:mod:`.metrics`), the bound-based evaluator that skips what a request does not need
(:mod:`.skipping`) and the Hall sensors' headroom (:mod:`.sensor_headroom`)."""

from .array import CoilArray
from .coil import Coil

__all__ = ["CoilArray", "Coil"]
