"""Physical constants of designkit, at the bottom of the import graph (the field kernels and the
design spec both read them; neither imports the other). Defined once, in firmware_io.constants,
so that the controller's models and designkit use the same numbers."""

from firmware_io.constants import MU0

__all__ = ["MU0"]
