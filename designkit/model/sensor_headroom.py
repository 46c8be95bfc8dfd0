"""Does the Hall-sensor array see the magnet? Range and resolution of the design's sensors.

The TLV493D-A1B6 sensors (``design.sensors``: ``range_t`` full scale per axis, ``lsb_t`` one
count) sit where the design's sensor layout puts them (:meth:`designkit.design.Design.
sensor_poses`: the default one on each coil's axis above its top and below its bottom; each
chip reads along its own axes). The coil nearest a sensor drives it hardest; the finger magnet
is what the sensors are there to measure. This module puts the two against the sensor's range
and resolution, for every sensor and every coil alone at the current (the coupled array: all
cores magnetized by that coil): a coil field beyond ``range_t`` on a chip axis clips the
reading, a magnet field of a few counts cannot be told from noise.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..field import dipole_field
from .array import array_for_design


def sensor_headroom(design, current_a: float | None = None, array=None) -> dict:
    """The design's sensors against the coils at ``current_a`` and the magnet.

    Parameters
    ----------
    design : Design
    current_a : float, optional
        Current of one coil, A (default ``drive.max_current_a``).
    array : CoilArray, optional
        The design's array when already built (default: :func:`array_for_design`).

    Returns
    -------
    dict (SI)
        The sensor a single coil drives hardest: ``sensor_index``, ``sensor_point_m`` (3,) array
        frame, ``coil_index`` the coil, ``coil_field_t`` (3,) its field there at the current
        (array frame), ``coil_field_fraction_of_range`` (largest chip-axis component / range),
        ``clips`` (bool); ``magnet_field_t`` (3,) the finger magnet's dipole field (the magnet at
        the design point) at the sensor that sees it most, ``magnet_field_counts`` (its largest
        chip-axis component in counts of ``lsb_t``); per sensor (n_sensors,):
        ``fraction_of_range_per_sensor`` and ``magnet_counts_per_sensor``; ``range_t``,
        ``lsb_t``, ``coil_current_a``.
    """
    s = design.sensors
    current = design.drive.max_current_a if current_a is None else float(current_a)
    arr = array_for_design(design) if array is None else array
    pos, frames = arr.sensor_poses()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the saturation warning is the report's, once
        b = arr.actuation_matrix(pos)[:, :3, :] * current  # (n_s, 3, n_coils) T, array frame
    chip = np.einsum("sai,sak->sik", frames, b)  # each chip's own axes
    frac = np.abs(chip).max(axis=1) / s.range_t  # (n_s, n_coils)
    i, k = np.unravel_index(int(np.argmax(frac)), frac.shape)
    # the magnet as a point dipole at the design point
    b_mag = dipole_field(pos - np.asarray(design.design_point_m), design.magnet.moment_vector_a_m2)
    counts = np.abs(np.einsum("sai,sa->si", frames, b_mag)).max(axis=1) / s.lsb_t
    j = int(np.argmax(counts))
    return {"sensor_index": int(i), "sensor_point_m": pos[i].tolist(), "coil_index": int(k),
            "coil_current_a": current, "coil_field_t": b[i, :, k].tolist(),
            "range_t": s.range_t, "lsb_t": s.lsb_t,
            "coil_field_fraction_of_range": float(frac[i, k]), "clips": bool(frac[i, k] > 1.0),
            "magnet_field_t": b_mag[j].tolist(), "magnet_field_counts": float(counts[j]),
            "fraction_of_range_per_sensor": frac.max(axis=1).tolist(),
            "magnet_counts_per_sensor": counts.tolist()}
