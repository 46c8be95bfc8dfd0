"""``python -m firmware_io.mapfile MAP.npz``: load a map on the target host and evaluate it."""

from .reader import _self_check

_self_check()
