"""Checks of one frame's inputs for :class:`firmware_io.localization.Localizer`: the readings
(n, 3) T per array (NaN = missing or saturated; Inf, fields beyond 1 T or not numbers are bad
input) and the currents, as float arrays or :class:`BadInputError` naming the input, the valid
range and the value (``Localizer.fix`` turns it into a not-ok estimate with that reason).
"""

from __future__ import annotations

import numpy as np

from ..errors import BadInputError


def as_float_array(name: str, a, valid: str) -> np.ndarray:
    """``a`` as a float array, or BadInputError (not numbers, ragged) naming ``name``."""
    try:
        return np.asarray(a, dtype=float)
    except (TypeError, ValueError) as exc:
        raise BadInputError(name, valid, f"not an array of numbers ({exc})") from None


def check_frame(name: str, a, n: int) -> np.ndarray:
    """One array's readings ``a`` as a float (n, 3) array, T (NaN kept)."""
    arr = as_float_array(name, a, f"an array of shape ({n}, 3), T")
    if arr.shape != (n, 3):
        raise BadInputError(name, f"an array of shape ({n}, 3), T", f"shape {arr.shape}")
    if (np.abs(arr) <= 1.0).all():  # the usual frame: one test (False with NaN, Inf, > 1 T)
        return arr
    if np.any(np.isinf(arr)):  # NaN compares False
        raise BadInputError(name, "finite values or NaN (missing/saturated), T",
                            f"Inf at {np.argwhere(np.isinf(arr))[0].tolist()}")
    if np.any(np.abs(arr) > 1.0):
        raise BadInputError(name, "fields in tesla (|B| <= 1 T; a TLV493D reads <= 0.2 T)",
                            f"{np.nanmax(np.abs(arr))!r} -- millitesla passed as tesla?")
    return arr
