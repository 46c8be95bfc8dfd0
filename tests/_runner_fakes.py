"""Small stand-ins for the runner's collaborators, so its loop and fault logic are tested alone."""

from __future__ import annotations

import numpy as np

from firmware_io.localization import Estimate


class TruthLocalizer:
    """Returns the true position (read from a callable) unless every sensor is NaN, with a
    zero protection level (the runner's own integrity logic is tested elsewhere)."""

    def __init__(self, truth):
        self.truth = truth

    def estimate(self, readings_t, currents_a=None):
        ok = bool(np.isfinite(readings_t).any())
        return Estimate(np.asarray(self.truth(), float), np.array([0.0, 0.0, 1.0]), ok,
                        "" if ok else "no usable sensor", protection_level_m=0.0)


class HoldTracker:
    """Holds the last estimate (zero velocity)."""

    def __init__(self):
        self.x = None

    def update(self, position_m, time_s, ok=True):
        self.x = np.stack([np.asarray(position_m, float), np.zeros(3)])

    def predict(self, time_s):
        return self.x[0]


class ConstantMap:
    """A(p) fixed at one point's value (fault-logic tests do not need the field's shape)."""

    def __init__(self, a, bounds, moment, bias=None):
        self.a = np.asarray(a, float)
        self.bounds = bounds
        self.moment_a_m2 = np.asarray(moment, float)
        self._bias = bias

    def actuation(self, p, *, rows=None, coils=None):
        p = np.asarray(p, float)
        a = self.a if rows is None else self.a[list(rows)]
        a = a if coils is None else a[:, list(coils)]
        return a if p.ndim == 1 else np.broadcast_to(a, (len(p),) + a.shape)

    def bias_force(self, p):
        b = np.zeros(3) if self._bias is None else np.asarray(self._bias, float)
        p = np.asarray(p, float)
        return b if p.ndim == 1 else np.broadcast_to(b, (len(p), 3))


class PlaneScene:
    """Flat surface at ``height_m``: f = (0, 0, stiffness * max(0, height - z))."""

    def __init__(self, height_m=0.05, stiffness_n_per_m=6.0):
        self.h, self.k = height_m, stiffness_n_per_m

    def force(self, p, v):
        return np.array([0.0, 0.0, self.k * max(0.0, self.h - float(p[2]))])


def clipped_lstsq(fm, target, limit, total, unipolar=False):
    """Least-norm solution clipped into the bounds (a stand-in, not the exact allocator)."""
    i = np.linalg.lstsq(fm, target, rcond=None)[0]
    lo = 0.0 if unipolar else -np.asarray(limit)
    i = np.clip(i, lo, limit)
    s = np.abs(i).sum()
    if s > total:
        i *= total / s
    return i, float(np.sum((fm @ i - target) ** 2))
