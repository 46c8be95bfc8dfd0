"""The simulated device's loads along a path are kept per array (designkit.sim.samples.memoized):
a path asked for again gives the same values without evaluating the model, and what the caller
does with them does not reach the memo."""

from __future__ import annotations

import numpy as np

from designkit.sim import samples


def _counting(calls):
    def load(array, points_m, scale):
        calls.append(len(points_m))
        return np.asarray(points_m, float) * float(np.asarray(scale))
    return load


def test_a_path_asked_for_again_is_not_evaluated_again(thesis_array):
    calls = []
    load = _counting(calls)
    p = np.random.default_rng(0).uniform(-0.03, 0.03, (7, 3))
    a = samples.memoized(load, thesis_array, p, 2.0)
    b = samples.memoized(load, thesis_array, p.copy(), 2.0)
    assert calls == [7]
    np.testing.assert_array_equal(a, 2.0 * p)
    np.testing.assert_array_equal(b, a)
    a[:] = 0.0                                        # the caller's copy, not the memo
    np.testing.assert_array_equal(samples.memoized(load, thesis_array, p, 2.0), 2.0 * p)
    samples.memoized(load, thesis_array, p, 3.0)      # any argument changed: evaluated
    samples.memoized(load, thesis_array, p[:6], 2.0)
    assert calls == [7, 7, 6]


def test_the_memo_keeps_the_last_paths_only(thesis_array):
    calls = []
    load = _counting(calls)
    paths = [np.full((2, 3), float(k)) for k in range(samples.MEMO_PATHS + 1)]
    for p in paths:
        samples.memoized(load, thesis_array, p, 1.0)
    samples.memoized(load, thesis_array, paths[-1], 1.0)     # newest: kept
    samples.memoized(load, thesis_array, paths[0], 1.0)      # oldest: dropped, evaluated again
    assert len(calls) == samples.MEMO_PATHS + 2


def test_the_memoized_loads_are_the_models(thesis_array):
    """F0 of a tilted magnet along a path: the memo's values are the model's, bit for bit."""
    p = np.c_[np.linspace(-0.01, 0.01, 4), np.zeros(4), np.full(4, 0.035)]
    m = np.tile([0.2, 0.0, 0.9], (4, 1))
    want = samples.bias_force_any(thesis_array, p, m)
    np.testing.assert_array_equal(samples.memoized(samples.bias_force_any, thesis_array, p, m),
                                  want)
    np.testing.assert_array_equal(samples.memoized(samples.bias_force_any, thesis_array, p, m),
                                  want)
