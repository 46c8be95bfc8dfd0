"""The modelled coil currents of the last control steps, for the sensor side.

A frame is a couple of sensor passes old when it is fitted: the fit needs the currents its
field was sampled at, not the command they lag nor today's. The control loop writes one row per
step; the sensor thread reads the row of a frame's time.
"""

from __future__ import annotations

import math

import numpy as np


class CurrentHistory:
    """Ring buffer of the modelled coil currents (A) at the start of each control step (s).

    A row's current is written before its time, so a reader never takes a half-written row
    unless the frame is older than the whole buffer (``length`` steps).
    """

    def __init__(self, n_coils: int, length: int):
        self.t_s = np.full(length, -math.inf)
        self.current_a = np.zeros((length, n_coils))
        self.k = 0

    def push(self, t_s: float, current_a: np.ndarray) -> None:
        """Record the currents (n,) A of the step starting at ``t_s`` (s)."""
        j = self.k % len(self.t_s)
        self.current_a[j] = current_a
        self.t_s[j] = t_s
        self.k += 1

    def at(self, t_s: float) -> np.ndarray:
        """Currents (n,) A of the newest step that started at or before ``t_s`` (the oldest
        kept when none did; zeros before the first step)."""
        t = self.t_s
        before = t <= t_s + 1e-12
        if not before.any():
            if self.k == 0:
                return np.zeros(self.current_a.shape[1])
            return self.current_a[int(np.argmin(t))].copy()
        return self.current_a[int(np.argmax(np.where(before, t, -math.inf)))].copy()
