"""The array model along a scripted path: where to sample it, how to read a step between
samples, and the magnet's loads for a moment of any direction.

The finger's path and tilt are scripted, so the simulated device evaluates the model in a few
batches before the loop (:func:`sample_steps`) and interpolates per step (:class:`Sampled`).
The cores are linear, so the field they take from the magnet is linear in its moment m and the
magnet's pull on them, F0 = grad(m . B_ind(m)), is a quadratic form in m: both follow from a
few fixed moments evaluated in batches (:func:`bias_force_any`, :func:`induced_field_any`).
The finger magnet is a finite cylinder, not a point: :func:`finite_size_bias` is what that
changes in F0 (up to 4-5 % 15-20 mm above a core), sampled more coarsely (it is small and
smooth). Positions m, moments A m^2, fields T, forces N.

The array is immutable and these loads are pure functions of it and of their arguments, so each
array keeps the loads of the last few paths it was asked for (:func:`memoized`): a path run
again -- another seed, another runner on the same trajectory -- is not evaluated again.
"""

from __future__ import annotations

import weakref
from collections import OrderedDict

import numpy as np

MEMO_PATHS = 16
"""Paths whose loads each array keeps (the oldest is dropped first)."""

_MEMO: "weakref.WeakKeyDictionary[object, OrderedDict]" = weakref.WeakKeyDictionary()

_BASIS = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [1.0, 1.0, 0], [1.0, 0, 1.0],
                   [0, 1.0, 1.0]])
_PAIRS = ((0, 1, 3), (0, 2, 4), (1, 2, 5))


def sample_steps(positions_m, directions, *, step_m: float, turn_rad: float,
                 max_stride: int | None = None) -> np.ndarray:
    """Indices of the steps to evaluate the model at: the first and the last, a step once the
    path moved ``step_m`` (m) or the moment turned ``turn_rad`` since the last sample, at least
    every ``max_stride`` steps, and both sides of a jump (> 1 mm between steps)."""
    p = np.asarray(positions_m, float)
    u = np.asarray(directions, float)
    cos_turn = np.cos(turn_rad)
    idx = [0]
    for k in range(1, len(p)):
        jump = np.linalg.norm(p[k] - p[k - 1]) > 1e-3
        if jump and idx[-1] != k - 1:
            idx.append(k - 1)
        last = idx[-1]
        if (jump or (max_stride is not None and k - last >= max_stride)
                or np.linalg.norm(p[k] - p[last]) >= step_m or u[k] @ u[last] < cos_turn):
            idx.append(k)
    if idx[-1] != len(p) - 1:
        idx.append(len(p) - 1)
    return np.asarray(idx)


class Sampled:
    """Values (s, ...) known at sampled steps ``idx`` (s,), linear in between (per step)."""

    def __init__(self, idx, values):
        self.idx = np.asarray(idx)
        self.values = np.asarray(values, float)

    def at(self, step: int) -> np.ndarray:
        j = int(np.searchsorted(self.idx, step, side="right")) - 1
        j = min(max(j, 0), len(self.idx) - 2) if len(self.idx) > 1 else 0
        if len(self.idx) == 1:
            return self.values[0]
        a, b = self.idx[j], self.idx[j + 1]
        w = min(max((step - a) / (b - a), 0.0), 1.0)
        return self.values[j] + w * (self.values[j + 1] - self.values[j])

    def all(self, steps) -> np.ndarray:
        """The values at every step of ``steps`` (k,), shape (k, ...)."""
        flat = self.values.reshape(len(self.idx), -1)
        out = np.empty((len(steps), flat.shape[1]))
        for j in range(flat.shape[1]):
            out[:, j] = np.interp(steps, self.idx, flat[:, j])
        return out.reshape((len(steps),) + self.values.shape[1:])


def _one_moment(moments) -> np.ndarray | None:
    """The moment (3,) when all rows of ``moments`` (k, 3) are equal, else None."""
    m = np.asarray(moments, float)
    return m[0] if np.all(m == m[0]) else None


def memoized(function, array, *args):
    """``function(array, *args)`` (numpy arrays or floats), kept for the array's core system
    (its coupled solve: what the loads depend on besides the arguments) while it lives; a copy
    is returned, so callers may change it. Arrays without coupled cores are not kept (their
    loads are zeros)."""
    system = array.coupled()
    if system is None:
        return function(array, *args)
    key = (function.__name__,) + tuple(
        (a.shape, a.tobytes()) for a in (np.ascontiguousarray(x, float) for x in args))
    memo = _MEMO.setdefault(system, OrderedDict())
    if key not in memo:
        memo[key] = function(array, *args)
        if len(memo) > MEMO_PATHS:
            memo.popitem(last=False)
    memo.move_to_end(key)
    return memo[key].copy()


def bias_force_any(array, points_m, moments_a_m2) -> np.ndarray:
    """F0 (k, 3) N at points (k, 3) m for a moment (k, 3) A m^2 each: one batch for a single
    moment, else the quadratic form from six fixed moments (``CoilArray.bias_force``, point
    dipole)."""
    p = np.asarray(points_m, float)
    m = np.asarray(moments_a_m2, float)
    one = _one_moment(m)
    if one is not None:
        return np.asarray(array.bias_force(p, one), float).reshape(-1, 3)
    f = [np.asarray(array.bias_force(p, b), float).reshape(-1, 3) for b in _BASIS]
    out = sum(m[:, i, None] ** 2 * f[i] for i in range(3))
    for i, j, ij in _PAIRS:
        out = out + (m[:, i] * m[:, j])[:, None] * (f[ij] - f[i] - f[j])
    return out


def induced_field_any(array, sensors_m, positions_m, moments_a_m2) -> np.ndarray:
    """The cores' field induced by the magnet at the sensors (n, 3) m, for magnet positions
    (k, 3) m and moments (k, 3) A m^2: (k, n, 3) T (``CoilArray.magnet_core_field``, linear in
    the moment: three fixed moments for a tilted one)."""
    p = np.asarray(positions_m, float)
    m = np.asarray(moments_a_m2, float)
    out = np.empty((len(p), len(sensors_m), 3))
    one = _one_moment(m)
    for k in range(len(p)):
        if one is not None:
            out[k] = array.magnet_core_field(sensors_m, p[k], one)
        else:
            out[k] = sum(m[k, i] * array.magnet_core_field(sensors_m, p[k], _BASIS[i])
                         for i in range(3))
    return out


def finite_size_bias(array, points_m, moments_a_m2, size_m) -> np.ndarray:
    """F0 of the magnet as the uniformly magnetized cylinder ``size_m`` = (radius, length) m,
    its axis along its moment, minus F0 of the point dipole: (k, 3) N at points (k, 3) m, a
    moment (k, 3) A m^2 each (``CoilArray.bias_force``; ~20 x a dipole's cost)."""
    p = np.asarray(points_m, float).reshape(-1, 3)
    m = np.asarray(moments_a_m2, float).reshape(-1, 3)
    one = _one_moment(m)
    if one is not None:
        cyl = np.asarray(array.bias_force(p, one, magnet_size_m=size_m), float).reshape(-1, 3)
    else:
        cyl = np.array([array.bias_force(q, mq, magnet_size_m=size_m) for q, mq in zip(p, m)])
    return cyl - bias_force_any(array, p, m)
