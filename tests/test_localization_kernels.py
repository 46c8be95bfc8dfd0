"""The pose fit's inner kernels against independent computations: the fit's Jacobian columns
(:func:`multipole_pose_columns`) against central differences of :func:`multipole_field`, the
cold search's per-candidate moments and its leave-one-out pass against a brute-force weighted
least squares (numpy's lstsq per candidate)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from firmware_io.localization.magnet import multipole_field, multipole_pose_columns
from firmware_io.localization.pose import rotated, tangent_axes
from firmware_io.localization.search import GridSearch, dipole_basis

M = 0.909                     # A m^2: the thesis' 10 x 10 mm N52 cylinder
OCTUPOLE = 0.005 ** 2 - 0.75 * 0.005 ** 2


@pytest.mark.parametrize("octupole", [0.0, OCTUPOLE])
def test_fit_columns_match_central_differences(octupole):
    """Columns 0-2 (dB/d position) and 3-4 (dB along the fit's two orientation steps, u moved
    by h along e1, e2 and renormalized: :func:`rotated`) and the returned field, at random
    points, poses and tilts: a sign, a dropped l = 3 term or a swapped column misses by far
    more than 1e-6 of the largest entry."""
    rng = np.random.default_rng(7)
    c, k = M / (4 * math.pi), 0.5 * M / (4 * math.pi) * octupole
    for _ in range(6):
        pts = rng.normal(scale=0.04, size=(18, 3))
        p = rng.normal(scale=0.01, size=3)
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        axes = tangent_axes(u)
        out = np.full((18, 3, 8), np.nan)
        b = multipole_pose_columns(pts - p, u, axes, c, k, out)
        assert np.allclose(b, multipole_field(pts, p, M * u, octupole), rtol=1e-12, atol=0)
        assert np.all(np.isnan(out[:, :, 5:]))           # nothing written beyond column 4
        h = 1e-7
        for j, e in enumerate(np.eye(3)):
            fd = (multipole_field(pts, p + h * e, M * u, octupole)
                  - multipole_field(pts, p - h * e, M * u, octupole)) / (2 * h)
            assert np.abs(out[:, :, j] - fd).max() < 1e-6 * np.abs(fd).max()
        for j in range(2):
            step = np.zeros(2)
            step[j] = h
            fd = (multipole_field(pts, p, M * rotated(u, axes, step), octupole)
                  - multipole_field(pts, p, M * rotated(u, axes, -step), octupole)) / (2 * h)
            assert np.abs(out[:, :, 3 + j] - fd).max() < 1e-6 * np.abs(fd).max()


def _search_case(seed):
    """Sensors on two boards, a dipole with a uniform background, weights with one sensor
    unusable; the search over a small box."""
    rng = np.random.default_rng(seed)
    xy = np.array([[x, y] for y in (0.05, 0.0, -0.05) for x in (-0.05, 0.0, 0.05)])
    pts = np.r_[np.c_[xy, np.full(9, 0.014)], np.c_[xy, np.full(9, -0.114)]]
    lo, hi = np.array([-0.06, -0.06, 0.02]), np.array([0.06, 0.06, 0.1])
    search = GridSearch(pts, None, lo, hi, M, np.eye(3))
    p_true = np.array([0.011, -0.007, 0.043])
    m_true = M * np.array([0.3, -0.2, 0.93]) / np.linalg.norm([0.3, -0.2, 0.93])
    data = dipole_basis(pts, p_true[None])[0] @ m_true + np.array([2e-5, -1e-5, 3e-5])
    data += rng.normal(scale=1e-4, size=data.shape)
    weights = np.full(18, 1e8) * rng.uniform(0.5, 2.0, 18)
    weights[seed % 18] = 0.0
    data[seed % 18] = 0.0
    return pts, search, data, weights


def _brute_force(pts, cands, data, weights):
    """Per candidate: the weighted least-squares (moment, background) and its cost, by lstsq."""
    d = dipole_basis(pts, cands)                                    # (C, n, 3, 3)
    sw = np.sqrt(weights)
    rhs = (data * sw[:, None]).reshape(-1)
    out_m, out_cost = [], []
    for dc in d:
        a = np.concatenate([dc, np.broadcast_to(np.eye(3), dc.shape)], axis=2)
        a = (a * sw[:, None, None]).reshape(-1, 6)
        x, *_ = np.linalg.lstsq(a, rhs, rcond=None)
        out_m.append(x[:3])
        out_cost.append(float(np.sum((a @ x - rhs) ** 2)))
    return np.array(out_m), np.array(out_cost)


@pytest.mark.parametrize("seed", [0, 5])
def test_search_starts_are_the_weighted_least_squares_minima(seed):
    """The search's best starts: their moments are the weighted least-squares moments at those
    candidates (the background eliminated), and no plausible candidate has a lower cost."""
    pts, search, data, weights = _search_case(seed)
    starts = search.starts(data, weights, True)
    m_all, cost_all = _brute_force(pts, search.candidates, data, weights)
    size = np.linalg.norm(m_all, axis=1) / M
    plausible = (size > 0.25) & (size < 4.0)
    best = np.argsort(np.where(plausible, cost_all, np.inf))[:3]
    for (p0, m0), j in zip(starts, best):
        assert np.array_equal(p0, search.candidates[j])
        assert np.allclose(m0, m_all[j], rtol=1e-6, atol=1e-9 * M)


def test_leave_one_out_names_the_sensor_whose_removal_fits_best():
    """A gross fault on one sensor: the leave-one-out pass names the block whose removal gives
    the lowest brute-force cost over the coarse candidates (the liar here)."""
    pts, search, data, weights = _search_case(3)
    liar = 1
    data[liar] += np.array([0.0, 0.0, 4e-3])
    coarse = search.candidates[search.coarse]
    best = []
    for b in range(18):
        if weights[b] == 0:
            best.append(np.inf)
            continue
        w = weights.copy()
        w[b] = 0.0
        m, cost = _brute_force(pts, coarse, np.where(w[:, None] > 0, data, 0.0), w)
        size = np.linalg.norm(m, axis=1) / M
        best.append(np.min(np.where((size > 0.25) & (size < 4.0), cost, np.inf)))
    assert int(np.argmin(best)) == liar
    assert search.leave_one_out(data, weights, True) == liar
