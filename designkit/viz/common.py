"""What every figure of :mod:`designkit.viz` shares: the lazy pyvista import, the figure kinds
and grid qualities, the names of the data arrays and the checks of the plot options.

Array names carry their unit: SI arrays (``"B (T)"``, ``"grad B (T/m)"``, ``"F (N)"``) and,
for colouring, magnitudes in the units people read (``"B magnitude (mT)"``, ``"F magnitude
(mN)"``, ``"Fz (mN)"``). pyvista is imported only in :func:`import_pyvista`: without it the figures raise
:class:`designkit.errors.MissingDependencyError` with the fix; without a display (no
``DISPLAY``) VTK is pointed at its EGL render window, which renders off-screen.
"""

from __future__ import annotations

import os
from typing import Literal

from ..errors import BadInputError, MissingDependencyError

Quality = Literal["quick", "full"]
Kind = Literal["scene", "fieldlines", "slice-B", "slice-F", "forcemap", "isosurface"]
KINDS: tuple[str, ...] = ("scene", "fieldlines", "slice-B", "slice-F", "forcemap", "isosurface")
QUALITIES: tuple[str, ...] = ("quick", "full")

# Grid points per axis. "quick" is for tests and `designkit report --quick`; "full" is the
# report's (what it costs: docs/figures.md).
GRID_POINTS = {
    "quick": {"volume": (17, 17, 19), "slice": (33, 21), "plane": (35, 35), "map": 9,
              "iso": (19, 19, 17)},
    "full": {"volume": (33, 33, 41), "slice": (81, 51), "plane": (81, 81), "map": 11,
             "iso": (37, 37, 31)},
}

B_T, B_MT = "B (T)", "B magnitude (mT)"
GRAD_T_M, F_N, F_MN, FZ_MN = "grad B (T/m)", "F (N)", "F magnitude (mN)", "Fz (mN)"
CURRENT_A = "current (A)"
IN_SOLID = "inside a core or winding"
REACH_M = "height where |Fz| on the coil axes falls below the level (m)"

COPPER, STEEL, MAGNET_RED = "#c87533", "#8c8c8c", "#b22222"
MIN_ARROW = 0.45
"""Shortest force arrow in the force map, as a fraction of the longest."""


def import_pyvista():
    """Import pyvista for off-screen use, or raise MissingDependencyError with the fix."""
    if not os.environ.get("DISPLAY"):
        # VTK otherwise tries X first and logs "bad X server connection" before falling back.
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import pyvista
    except ImportError as exc:
        raise MissingDependencyError("pyvista", "pyvista", "designkit.viz") from exc
    return pyvista


def grid_resolution(quality: str) -> dict:
    if quality not in QUALITIES:
        raise BadInputError("quality", f"one of {QUALITIES}", quality)
    return GRID_POINTS[quality]


def window_pixels(window_size) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in window_size)
    except (TypeError, ValueError):
        raise BadInputError("window_size", "two whole numbers (width, height) in pixels",
                            window_size) from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise BadInputError("window_size", "(width, height) each in [16, 8192] px", window_size)
    return w, h


def image_grid(pv, lo, hi, dims):
    dims = tuple(int(d) for d in dims)
    spacing = tuple((h - l) / (d - 1) if d > 1 else 1.0 for l, h, d in zip(lo, hi, dims))
    return pv.ImageData(dimensions=dims, spacing=spacing, origin=tuple(lo))
