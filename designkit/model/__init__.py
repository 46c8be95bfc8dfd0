"""The device model: a coil (winding + core, :mod:`.coil`), its electrical and thermal model
(:mod:`.electrical`), the array of coils in poses with its actuation matrix, bias force and
sensor fields (:mod:`.array`), the bound-based evaluator that skips what a request does not need
(:mod:`.skipping`) and the Hall sensors' headroom (:mod:`.sensor_headroom`)."""

from .array import CoilArray
from .coil import Coil

__all__ = ["CoilArray", "Coil"]
