"""Sensor faults as the runner names them, and the latch for a sensor the estimator keeps
excluding.

A driver status other than 'ok' excludes a sensor from the fit and raises the fault of
:data:`SENSOR_FAULTS`. A sensor whose value contradicts the others while its status is ok is
excluded by the estimator's fault detection (RAIM FDE); when that happens in
:data:`FDE_LATCH_PASSES` passes whose fit the others agree with, with no trusted fix using it
in between, :class:`ExclusionLatch` latches it out ('sensor_value' fault): it is left out
before the fit from then on, and the estimator can exclude another.
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
"""Passes (frames whose fit passed its residual test) a sensor must be excluded by the
estimator's fault detection, with no trusted fix using it in between, before it is latched
out: a lying sensor, not one noisy frame."""


class ExclusionLatch:
    """Per sensor, the passes in a row the estimator excluded it; latched out at ``passes``.

    Parameters
    ----------
    n_sensors : int
    passes : int -- :data:`FDE_LATCH_PASSES`
    """

    def __init__(self, n_sensors: int, passes: int = FDE_LATCH_PASSES):
        self.count = np.zeros(n_sensors, dtype=int)
        self.latched = np.zeros(n_sensors, dtype=bool)
        self.passes = int(passes)

    def update(self, excluded, consistent: bool, vouched=()) -> list:
        """Count one frame: the sensors the estimator excluded (indices) from a fix that passed
        its residual test (``consistent``: the others agree) count one more; the sensors a
        trusted fix used (``vouched``) restart at zero; the rest keep their count (a refused
        frame, or a sensor left out, says nothing about one sensor). Returns the newly
        latched."""
        for k in vouched:
            if 0 <= int(k) < len(self.count):
                self.count[int(k)] = 0
        if consistent:
            for k in excluded:
                if 0 <= int(k) < len(self.count):
                    self.count[int(k)] += 1
        new = np.flatnonzero((self.count >= self.passes) & ~self.latched)
        self.latched[new] = True
        return [int(k) for k in new]
