"""Sensor headroom: which sensors the model expects beyond their linear range, and the
constraint that keeps chosen sensors within it.

A TLV493D-A1B6 reads linearly to +-130 mT per axis [DS]; the coils' field at a sensor is linear
in the currents (the map's sensor section, T/A), the magnet's is a dipole at the estimated pose,
the room's a uniform background. A sensor whose predicted field exceeds
:data:`EXPECTED_SATURATION` of the range on some axis is left out of the fit before it
saturates. A scene may ask the allocator to keep some sensors usable
(:class:`SensorHeadroom`): per axis, |C_s I + b_s| <= fraction x range, linear in the currents
I (C_s the coils' field per ampere at sensor s, b_s the rest), added to the bounded allocation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import BadInputError
from ..hw.tlv493d import TLV493D_LINEAR_RANGE_T
from ..localization import multipole_field

EXPECTED_SATURATION = 0.8
"""A sensor whose predicted field exceeds this fraction of the TLV493D's +-130 mT linear range
on some axis is left out of the fit (no fault): the margin covers the model's error at the
sensor (the cores' saturation and induced field, a few mT) and the field's change between
the frame and the currents that reach the coils."""


@dataclass(frozen=True)
class SensorLayout:
    """The sensors in the map's order: positions (n_sensors, 3) m and the coils' field there per
    ampere (n_sensors, 3, n_coils) T/A (None: unknown, no prediction)."""

    positions_m: np.ndarray
    coil_field_t_per_a: np.ndarray | None

    @classmethod
    def of_map(cls, fieldmap) -> "SensorLayout":
        """From a map file's sensor section (``sensor_positions_m``, ``sensor_coil_field()``),
        in its sensor order, whatever the board layout."""
        pts = np.asarray(fieldmap.sensor_positions_m, float).reshape(-1, 3)
        cf = np.asarray(fieldmap.sensor_coil_field(), float)
        return cls(pts, cf.reshape(len(pts), 3, -1))

    @property
    def n_sensors(self) -> int:
        return len(self.positions_m)

    def predicted_t(self, currents_a, position_m=None, moment_a_m2=None,
                    background_t=None) -> np.ndarray:
        """(n_sensors, 3) T: the coils' field at ``currents_a`` (n_coils,) A, plus the
        magnet's dipole at ``position_m`` (3,) m with ``moment_a_m2`` (3,) A m^2 when given,
        plus a uniform ``background_t`` (3,) T."""
        b = self.coil_field_t_per_a @ np.asarray(currents_a, float)
        if position_m is not None:
            b = b + multipole_field(self.positions_m, np.asarray(position_m, float),
                                    np.asarray(moment_a_m2, float))
        if background_t is not None:
            b = b + background_t
        return b


def expected_saturation(predicted_t: np.ndarray, fraction: float = EXPECTED_SATURATION):
    """(n_sensors,) bool: sensors whose predicted field (n_sensors, 3) T exceeds ``fraction``
    of the linear range on some axis."""
    return np.any(np.abs(predicted_t) > fraction * TLV493D_LINEAR_RANGE_T, axis=1)


@dataclass(frozen=True)
class SensorHeadroom:
    """A scene's request: keep ``sensors`` (indices in the map's order) within ``fraction`` of
    the linear range while rendering.

    Off by default (no scene asks). It costs force where a coil's field at a kept sensor
    binds (``designkit check`` lists the current that saturates each sensor).
    """

    sensors: tuple
    fraction: float = EXPECTED_SATURATION

    def __post_init__(self):
        s = tuple(int(k) for k in self.sensors)
        if not s or len(set(s)) != len(s) or min(s) < 0:
            raise BadInputError("sensors", "distinct sensor indices >= 0 (at least one)",
                                self.sensors)
        object.__setattr__(self, "sensors", s)
        if not (0.0 < self.fraction <= 1.0):
            raise BadInputError("fraction", "in (0, 1] of the linear range", self.fraction)

    @classmethod
    def from_meta(cls, meta: dict) -> "SensorHeadroom | None":
        """The request a compiled scene carries (``keep_sensors``: indices;
        ``keep_sensors_fraction``: default :data:`EXPECTED_SATURATION`), or None."""
        keep = meta.get("keep_sensors")
        if not keep:
            return None
        return cls(tuple(keep), float(meta.get("keep_sensors_fraction", EXPECTED_SATURATION)))

    def constraints(self, layout: SensorLayout, rest_t: np.ndarray, coils=None):
        """(G (r, c), h (r,), kept sensors): G I <= h holds the kept sensors' fields
        (C_s I + rest_s, per axis) within +-fraction x range, for the coils ``coils`` (index
        array, None: all). ``rest_t`` (n_sensors, 3) T is the field without the coils. A sensor
        the rest alone puts beyond the limit cannot be kept: it is left out (not in G)."""
        lim = self.fraction * TLV493D_LINEAR_RANGE_T
        idx = [s for s in self.sensors if s < layout.n_sensors
               and np.all(np.abs(rest_t[s]) < lim)]
        c = layout.coil_field_t_per_a[idx]
        if coils is not None:
            c = c[:, :, coils]
        c = c.reshape(3 * len(idx), -1)
        b = rest_t[idx].reshape(-1)
        return np.concatenate([c, -c]), np.concatenate([lim - b, lim + b]), tuple(idx)
