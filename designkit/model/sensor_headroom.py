"""Does the Hall-sensor array see the magnet? Range and resolution of the design's sensors.

The TLV493D-A1B6 sensors (``design.sensors``: ``range_t`` full scale per axis, ``lsb_t`` one
count) sit ``sensors.offset_m`` above the coil tops, one on each coil axis. The coil under a
sensor drives it hardest; the finger magnet is what the sensors are there to measure. This
module puts the two against the sensor's range and resolution: a coil field beyond ``range_t``
clips the reading, a magnet field of a few counts cannot be told from noise.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..field import dipole_field
from .coil import Coil


def sensor_headroom(design, current_a: float | None = None) -> dict:
    """Field at the upper sensor of one coil (on its axis, ``sensors.offset_m`` above the top).

    Parameters
    ----------
    design : Design
    current_a : float, optional
        Current of the coil under the sensor, A (default ``drive.max_current_a``).

    Returns
    -------
    dict (SI)
        ``sensor_point_m`` (3,), ``coil_field_t`` (3,) the coil's field there at the current,
        ``range_t``, ``lsb_t``, ``coil_field_fraction_of_range`` (largest component / range),
        ``clips`` (bool), ``magnet_field_t`` (3,) the finger magnet's dipole field there with
        the magnet at the design height above the coil, ``magnet_field_counts`` (largest
        component in counts of ``lsb_t``).
    """
    s = design.sensors
    current = design.drive.max_current_a if current_a is None else float(current_a)
    point = np.array([0.0, 0.0, s.offset_m])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the saturation warning is the report's, once
        b_coil = Coil.from_design(design).field(point, current)
    # the magnet as a point dipole at the design point
    b_mag = dipole_field(point - np.asarray(design.design_point_m),
                         design.magnet.moment_vector_a_m2)
    frac = float(np.abs(b_coil).max() / s.range_t)
    return {"sensor_point_m": point.tolist(), "coil_current_a": current,
            "coil_field_t": b_coil.tolist(), "range_t": s.range_t, "lsb_t": s.lsb_t,
            "coil_field_fraction_of_range": frac, "clips": frac > 1.0,
            "magnet_field_t": b_mag.tolist(),
            "magnet_field_counts": float(np.abs(b_mag).max() / s.lsb_t)}
