# SHIM: old path, removed at integration
"""Old path of :mod:`designkit.sim` (the simulated device); re-exports what callers use."""

from designkit.sim import run_simulation  # noqa: F401
