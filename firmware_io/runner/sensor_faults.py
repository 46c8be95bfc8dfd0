"""Sensor faults as the runner names them, and the latch for a sensor the estimator keeps
excluding.

A driver status other than 'ok' excludes a sensor from the fit and raises the fault of
:data:`SENSOR_FAULTS`. A sensor whose value contradicts the others while its status is ok is
excluded by the estimator's fault detection (RAIM FDE); when that happens in
:data:`FDE_LATCH_PASSES` passes in a row, :class:`ExclusionLatch` latches it out ('sensor_value'
fault): it is left out before the fit from then on, and the estimator can exclude another.
"""

from __future__ import annotations

import numpy as np

SENSOR_FAULTS = {"stale": "sensor_stuck", "recovered": "sensor_stuck", "hung": "sensor_stuck",
                 "saturated": "sensor_saturated", "nack": "sensor_dead", "failed": "sensor_dead",
                 "unconfigured": "sensor_dead", "not_ready": "sensor_dead",
                 "test_mode": "sensor_dead", "frozen": "sensor_value", "zero": "sensor_value"}
"""Per-sensor status (:data:`firmware_io.hw.tlv493d.SensorStatus`) -> the runner's fault
name; any status but 'ok' excludes the sensor from the fit."""

FDE_LATCH_PASSES = 10
"""Passes in a row (frames with a trusted estimate) a sensor must be excluded by the
estimator's fault detection before it is latched out: a lying sensor, not one noisy frame."""


class ExclusionLatch:
    """Per sensor, the trusted frames in a row the estimator excluded it; latched out at
    ``passes``.

    Parameters
    ----------
    n_sensors : int
    passes : int -- :data:`FDE_LATCH_PASSES`
    """

    def __init__(self, n_sensors: int, passes: int = FDE_LATCH_PASSES):
        self.count = np.zeros(n_sensors, dtype=int)
        self.latched = np.zeros(n_sensors, dtype=bool)
        self.passes = int(passes)

    def update(self, excluded, trusted: bool) -> list:
        """Count one frame's exclusions (indices); only a trusted frame counts (a frame the
        estimator refuses says nothing about one sensor). Returns the newly latched."""
        if not trusted:
            return []
        hit = np.zeros(len(self.count), dtype=bool)
        for k in excluded:
            if 0 <= int(k) < len(hit):
                hit[int(k)] = True
        self.count = np.where(hit, self.count + 1, 0)
        new = np.flatnonzero((self.count >= self.passes) & ~self.latched)
        self.latched[new] = True
        return [int(k) for k in new]
