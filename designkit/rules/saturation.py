"""The coil currents that take each Hall sensor out of its linear range (reported by
``designkit check``, not a rule: the runner leaves a saturated sensor out)."""

from __future__ import annotations

from ..design import Design
from ..model.array import CoilArray
from ..sensing.sites import headroom


def sensor_saturation(design: Design, array=None) -> list[dict]:
    """The coil currents that take each Hall sensor out of its linear range (the coils' field
    alone; the magnet's adds near it, and the runner predicts both).

    The coils' field at a sensor is linear in the currents: B_s = C_s I, C_s (3, n_coils) T/A
    at ``CoilArray.sensor_poses()``, on the chip's own axes (the coupled cores included). Per
    sensor: the smallest current one coil alone needs to put some axis at ``sensors.range_t``,
    range / max_axis,k |C_s[axis, k]|, and which coil; and the current that does it with every
    coil at the same magnitude and the worst signs, range / max_axis sum_k |C_s[axis, k]|.

    Returns
    -------
    list of dict, one per sensor in the map's order: ``sensor``, ``position_m`` (3,),
    ``one_coil_a`` (A), ``coil`` (its index), ``all_coils_a`` (A).
    """
    if array is None:
        array = CoilArray.from_design(design)
    pts, frames = array.sensor_poses()
    room = headroom(array, pts, frames, design.sensors.range_t)
    return [{"sensor": s, "position_m": pos.tolist(), "one_coil_a": float(room.one_coil_a[s]),
             "coil": int(max(room.coil[s], 0)), "all_coils_a": float(room.worst_signs_a[s])}
            for s, pos in enumerate(pts)]
