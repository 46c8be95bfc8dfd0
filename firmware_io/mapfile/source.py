"""The actuation source: what the runner, the force constant and the localizer need from a map
file or a direct model of the array, as one named interface.

A(p) maps the coil currents I (A, one per coil in the design's coil order) to the field and its
gradient at a point p (m): [B; G5] = A(p) I, rows :data:`firmware_io.mapfile.format.ROWS`
(T/A and T/(m A), thesis eq. 2.13).
The force on the finger magnet is F(p, I) = F(m) G5(p) I + F0(p), with F0 the magnet's pull on
the iron at zero current; the coils' field at the Hall sensors tells the sensor side which
readings the currents will saturate. Implemented by ``firmware_io.mapfile.MapFile`` (the file
the device runs on), ``designkit.fieldmap.FieldMap`` and the direct coupled model of designkit
(``designkit.render.ArrayActuation``); each implements every member, so callers use them
without probing (no getattr / hasattr).
"""

from __future__ import annotations

from typing import Protocol, Sequence, runtime_checkable

import numpy as np

from ..errors import BadInputError


@runtime_checkable
class ActuationSource(Protocol):
    """A(p), F0(p) and the coils' field at the sensors of one design's array, with what
    identifies it.

    Attributes
    ----------
    n_coils : int
    bounds : (lower (3,), upper (3,)), m -- the box where ``actuation`` is valid
    moment_a_m2 : ndarray, shape (3,), A m^2 -- the finger magnet's moment F0 is computed for
    design_sha256 : str -- the design spec's hash (a scene or map of another design is refused)
    n_sensors : int -- the Hall sensors of the device (independent of n_coils)
    sensor_positions_m : ndarray, shape (n_sensors, 3), m -- the sensors' centres in the map's
        flat sensor order (the default layout: the upper array in coil order, then the lower)
    """

    n_coils: int
    bounds: tuple
    moment_a_m2: np.ndarray
    design_sha256: str
    n_sensors: int
    sensor_positions_m: np.ndarray

    def actuation(self, points, *, rows: Sequence[int] | None = None,
                  coils: Sequence[int] | None = None) -> np.ndarray:
        """A at points (3,) -> (r, c) or (n, 3) -> (n, r, c), with r = len(rows) (8 when None,
        in the order of ``ROWS``) and c = len(coils) (n_coils when None); SI units."""

    def bias_force(self, points) -> np.ndarray:
        """F0, the force on the magnet at zero current, N: (3,) -> (3,), (n, 3) -> (n, 3)."""

    def sensor_coil_field(self, currents=None) -> np.ndarray:
        """The coils' field at the sensors, array frame: per ampere (n_sensors, 3, n_coils)
        T/A, or with ``currents`` (n_coils,) A the field (n_sensors, 3) T."""


def selection(name: str, sel, n: int, error: type[ValueError] = BadInputError):
    """The ``rows=`` / ``coils=`` keyword of :meth:`ActuationSource.actuation` checked: None
    (all) or an index array (m,) of ints in 0..n-1, in the order given; ``error(name, valid,
    received)`` (a BadInputError of the caller's package) otherwise."""
    if sel is None:
        return None
    try:
        idx = np.asarray(sel)
        ok = idx.ndim == 1 and len(idx) > 0 and np.issubdtype(idx.dtype, np.integer)
    except (TypeError, ValueError):
        ok = False
    if not ok or np.any(idx < 0) or np.any(idx >= n):
        raise error(name, f"a non-empty sequence of indices 0..{n - 1}", sel)
    return idx.astype(np.intp)
