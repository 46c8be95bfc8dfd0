"""Small stand-ins for the runner's collaborators, so its loop and fault logic are tested alone."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from firmware_io.localization import Estimate


class TruthEstimator:
    """A pose estimator that returns the true position (read from a callable) and the given
    moment, trusted unless every sensor is NaN, with a zero protection level (the runner's own
    integrity logic is tested elsewhere)."""

    integrity_risk = 1e-4
    model_bias_m = 0.0

    def __init__(self, truth, moment=(0.0, 0.0, 0.909)):
        self.truth = truth
        self.moment = np.asarray(moment, float)
        self.resets = 0

    def reset(self):
        self.resets += 1

    def magnet_free(self, readings_t, currents_a=None):
        return False

    def estimate(self, readings_t, currents_a=None, *, usable=None, seed=None, time_s=None):
        ok = bool(np.isfinite(readings_t).any())
        return Estimate(np.asarray(self.truth(), float), self.moment.copy(), ok,
                        "" if ok else "no usable sensor", None, 0.0 if ok else math.inf)


class HoldTracker:
    """Holds the last estimate (zero velocity); every fix passes its gate."""

    r = 1e-6

    def __init__(self):
        self.reset()

    def reset(self):
        self.x = None
        self.t = None
        self.moment_a_m2 = None

    def update(self, position_m, time_s, ok=True, moment_a_m2=None, covariance=None):
        if ok:
            self.x = np.stack([np.asarray(position_m, float), np.zeros(3)])
            self.t = float(time_s)
            if moment_a_m2 is not None:
                self.moment_a_m2 = np.asarray(moment_a_m2, float)

    def predict(self, time_s):
        return self.x[0]

    def innovation(self, position_m, time_s):
        return np.zeros(3), 1.0

    def snapshot(self):
        return None


class ConstantMap:
    """A(p) fixed at one point's value (fault-logic tests do not need the field's shape), with
    a sensor section: positions (n_sensors, 3) m and the coils' field there (n_sensors, 3,
    n_coils) T/A (default: 18 sensors of the thesis' 3 x 3 board, no coil field)."""

    def __init__(self, a, bounds, moment, bias=None, sensors=None):
        self.a = np.asarray(a, float)
        self.bounds = bounds
        self.moment_a_m2 = np.asarray(moment, float)
        self._bias = bias
        if sensors is None:
            xy = np.array([[x, y] for y in (0.05, 0.0, -0.05) for x in (-0.05, 0.0, 0.05)])
            pts = np.r_[np.c_[xy, np.full(9, 0.014)], np.c_[xy, np.full(9, -0.114)]]
            sensors = (pts, np.zeros((18, 3, self.a.shape[1])))
        self.sensor_positions_m, self._sensor_field = (np.asarray(s, float) for s in sensors)

    def sensor_coil_field(self):
        return self._sensor_field.copy()

    def actuation(self, p, *, rows=None, coils=None):
        p = np.asarray(p, float)
        a = self.a if rows is None else self.a[list(rows)]
        a = a if coils is None else a[:, list(coils)]
        return a if p.ndim == 1 else np.broadcast_to(a, (len(p),) + a.shape)

    def bias_force(self, p):
        b = np.zeros(3) if self._bias is None else np.asarray(self._bias, float)
        p = np.asarray(p, float)
        return b if p.ndim == 1 else np.broadcast_to(b, (len(p), 3))


def device_map(a, bounds, device, bias=None):
    """A :class:`ConstantMap` with the simulated device's sensors (nominal positions and the
    coils' field there), flat in the device's order."""
    sim = device.sensor_sim
    return ConstantMap(a, bounds, device.moment, bias,
                       (sim.nominal_m.reshape(-1, 3),
                        sim.coil_field_t_per_a.reshape(-1, 3, a.shape[1])))


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


def md10c_drive(design, limit=4.8, total=20.0, **changes):
    """The design's drive record (designkit.sim.drive_data) at the MD10C's rated 30 V supply,
    with the runner tests' bounds (per coil ``limit``, sum ``total``, A) and the I^2 t guard at
    3 A, 300 s unless ``changes`` say otherwise."""
    from designkit.sim import drive_data

    rec = drive_data(design.replace(**{"drive.supply_voltage_v": 30.0}))
    return dataclasses.replace(rec, current_limit_a=limit, total_current_a=total,
                               **{"thermal_continuous_current_a": 3.0,
                                  "thermal_time_constant_s": 300.0, **changes})
