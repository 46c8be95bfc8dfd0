"""Sensor calibration at start-up, through the firmware's own drive and read path.

With the finger magnet away from the board, the coils are driven with known current patterns
(A) and every sensor read (T, one flat list in the map's order);
:func:`firmware_io.localization.calibrate` then fits each sensor's gain, mounting rotation and
offset. Output: the pose estimator's ``calibration``.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..errors import BadInputError, FirmwareIOError
from ..localization import CALIBRATED_RELATIVE_ERROR, calibrate

CALIBRATION_CURRENT_A = 2.0
"""Largest calibration current per coil, A: the iron cores stay near their linear range and the
sensors above them below the TLV493D's linear range, while every sensor sees a coil field many
times its noise along three independent directions."""


def calibration_currents(n_coils: int, amplitude_a: float = CALIBRATION_CURRENT_A,
                         frames: int = 40, seed: int = 0) -> np.ndarray:
    """Current patterns for :func:`record_calibration`, (frames, n_coils) A: a zero frame (the
    offsets) then uniform random patterns in [-amplitude, amplitude] (with nine coils every
    sensor sees coil fields along three independent directions; fixed seed: repeatable)."""
    if not (0 < amplitude_a <= 13.0):
        raise BadInputError("amplitude_a", "in (0, 13] A", amplitude_a)
    if frames < 8:
        raise BadInputError("frames", ">= 8 (4 unknowns per sensor axis, with margin)", frames)
    rng = np.random.default_rng(seed)
    out = rng.uniform(-amplitude_a, amplitude_a, (frames, n_coils))
    out[0] = 0.0
    return out


def record_calibration(coils, arrays, currents_a: np.ndarray, *, settle_s: float,
                       sleep: Callable[[float], None] = time.sleep):
    """Initialise the PWM boards, drive each current pattern, wait ``settle_s`` (several L/R),
    read the arrays twice (a
    master-controlled TLV493D returns the conversion the previous read triggered) and keep the
    second frame; all coils off at the end, also on an error.

    The finger magnet must be away from the board (its field would be taken for an offset).

    Returns
    -------
    readings_t : ndarray, shape (k, n_sensors, 3), T (NaN where a sensor was not 'ok')
    applied_a : ndarray, shape (k, n_coils), A -- the steady-state currents of the duties
        written (quantized, clamped by the drive)
    """
    i = np.asarray(currents_a, float)
    frames, applied = [], []
    coils.initialize()
    try:
        for row in i:
            res = coils.command(row)
            sleep(settle_s)
            arrays.read()
            r = arrays.read()
            bad = np.array([s != "ok" for s in r.status])
            frames.append(np.where(bad[:, None], np.nan, r.field_t))
            applied.append(np.asarray(res.current_a, float))
    finally:
        coils.all_off()
    return np.array(frames), np.array(applied)


def calibrate_sensors(model, readings_t, applied_a):
    """Per-sensor calibration (gain, mounting rotation, offset) from coil-only frames
    ``readings_t`` (k, n_sensors, 3) T, each in its sensor's frame:
    :func:`firmware_io.localization.calibrate`, checked to be finite. Returns what it returns,
    for the estimator's ``calibration``."""
    r = np.asarray(readings_t, float)
    try:
        cal = calibrate(r, applied_a, model)
    except (np.linalg.LinAlgError, ValueError):
        cal = (np.full(1, np.nan),)
    # (gain_inverse, offsets) or the localizer's calibration object with those attributes
    parts = cal if isinstance(cal, tuple) else [
        getattr(cal, a) for a in ("gain_inverse", "offsets_t", "shift_m", "coil_field_t_per_a")
        if getattr(cal, a, None) is not None]
    if not all(np.all(np.isfinite(c)) for c in parts):
        raise FirmwareIOError("sensor calibration failed (a sensor saw too few usable frames); "
                              "check the sensors and that the magnet is away from the board")
    return cal
