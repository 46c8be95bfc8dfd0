"""Checks of one frame's inputs for the estimators: the readings (n_sensors, 3) T, each in its
sensor's own frame (NaN = missing or unusable; Inf, fields beyond 1 T or not numbers are bad
input), the optional ``usable`` mask (n_sensors,) and the currents (n_coils,) A. Each check
returns float arrays or raises :class:`BadInputError` naming the input, the valid range and the
value; the estimators turn it into a not-ok estimate with that reason.
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


def check_readings(readings, n: int, usable=None) -> np.ndarray:
    """The readings as a float (n, 3) array, T, NaN where a sensor is missing or where
    ``usable`` (n,) is False."""
    arr = as_float_array("readings_t", readings, f"an array of shape ({n}, 3), T")
    if arr.shape != (n, 3):
        raise BadInputError("readings_t", f"an array of shape ({n}, 3), T", f"shape {arr.shape}")
    if not (np.abs(arr) <= 1.0).all():  # the usual frame passes one test (False with NaN)
        if np.any(np.isinf(arr)):
            raise BadInputError("readings_t", "finite values or NaN (missing/saturated), T",
                                f"Inf at {np.argwhere(np.isinf(arr))[0].tolist()}")
        if np.any(np.abs(arr) > 1.0):
            raise BadInputError("readings_t", "fields in tesla (|B| <= 1 T; a TLV493D reads "
                                "<= 0.2 T)", f"{np.nanmax(np.abs(arr))!r} -- millitesla passed "
                                "as tesla?")
    if usable is not None:
        mask = np.asarray(usable)
        if mask.shape != (n,) or mask.dtype != bool:
            raise BadInputError("usable", f"a bool array of shape ({n},)",
                                f"{mask.dtype} of shape {mask.shape}")
        if not mask.all():
            arr = np.where(mask[:, None], arr, np.nan)
    return arr


def check_currents(currents, n_coils: int) -> np.ndarray:
    """The currents as a finite float (n_coils,) array, A."""
    valid = f"{n_coils} finite values, A"
    if currents is None:
        raise BadInputError("currents_a", valid, None)
    i = as_float_array("currents_a", currents, valid)
    if i.shape != (n_coils,):
        raise BadInputError("currents_a", valid, f"shape {i.shape}")
    if not np.all(np.isfinite(i)):
        raise BadInputError("currents_a", valid, i.tolist())
    return i
