"""firmware_io.mapfile: the one-point bias force (the runner's per-step kernel,
``modes.magnet_terms_one``) against the batch kernel (``modes.magnet_terms``: the same tables
through the general per-point bilinear lookup) and the trilinear residual -- at random points,
on the coils' axes (rho = 0), on the tables' cell edges in rho and z, at the box's faces and
outside the box (extrapolated)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from firmware_io.mapfile import MapFile
from firmware_io.mapfile.grid import trilinear, trilinear_one
from firmware_io.mapfile.modes import magnet_terms, magnet_terms_one


@pytest.fixture(scope="module")
def fmap(small_map):
    return MapFile.load(small_map)


def _edge_points(fmap) -> np.ndarray:
    """Points whose (v, u) table coordinates fall on cell edges for the first coil: rho on
    the table's v nodes, z on its u nodes, inside the box."""
    t = fmap.kernels["magnet"][0]
    lo, hi = fmap.bounds
    c = t["pos"][0]
    # v = rho / h / (1 + rho / scale) on integers -> rho = v h / (1 - v h / scale)
    h, scale = 1.0 / t["inv_h"], 1.0 / t["inv_scale"]
    rhos = [v * h / (1.0 - v * h / scale) for v in range(t["n_rho"]) if v * h < scale]
    rhos = [r for r in rhos if r <= 0.5 * float(np.min(hi[:2] - lo[:2]))]
    zs = [c[2] + t["z_ref"] + math.exp(t["u0"] + k / t["inv_du"]) for k in range(t["n_u"])]
    zs = [z for z in zs if lo[2] <= z <= hi[2]]
    pts = [(c[0] + r, c[1], z) for r in rhos[:12] for z in zs[::3]]
    pts += [(c[0], c[1], z) for z in zs]                          # on the axis: rho = 0
    return np.clip(np.array(pts, float), lo, hi)


def _reference(fmap, p: np.ndarray) -> np.ndarray:
    """The reference: the batch kernel of the cores' terms (one call over all points) plus
    the residual grid's one-point trilinear lookup (the residual is stored in float32: its
    batch and one-point lookups round differently, ~1e-8 of it; checked separately)."""
    k = fmap.kernels
    return magnet_terms(k["magnet"], p) + np.array([trilinear_one(k["magnet_f0"], q)
                                                    for q in p.tolist()])


def test_the_one_point_table_is_used(fmap):
    assert fmap.kernels["magnet_one"] is not None     # else the fast path is not under test


def test_one_point_bias_force_equals_the_batch_kernel(fmap):
    rng = np.random.default_rng(3)
    lo, hi = fmap.bounds
    span = hi - lo
    inside = rng.uniform(lo, hi, (400, 3))
    faces = rng.uniform(lo, hi, (60, 3))
    axis = rng.integers(0, 3, 60)
    faces[np.arange(60), axis] = np.where(rng.random(60) < 0.5, lo[axis], hi[axis])
    outside = rng.uniform(lo - 0.2 * span, hi + 0.2 * span, (200, 3))
    edges = _edge_points(fmap)
    assert len(edges) > 20
    for pts, extrapolate in ((inside, False), (faces, False), (edges, False), (outside, True)):
        ref = _reference(fmap, pts)
        one = np.array([fmap.bias_force(p, extrapolate=extrapolate) for p in pts])
        scale = np.abs(ref).max(axis=1)
        assert np.all(scale > 0)
        err = np.abs(one - ref).max(axis=1) / scale
        assert err.max() < 1e-12, (extrapolate, err.max(), pts[int(np.argmax(err))])
        # the public batch call agrees too, to the float32 residual's rounding
        res = np.abs(trilinear(fmap.kernels["magnet_f0"], pts)).max()
        assert np.allclose(fmap.bias_force(pts, extrapolate=extrapolate), ref, rtol=0,
                           atol=1e-12 * float(scale.max()) + 1e-6 * float(res))


def test_the_kernel_alone_equals_the_general_path(fmap):
    """Without the residual grid: ``magnet_terms_one`` through its table against itself
    without the table (the general path), at points on the coils' axes and cell edges."""
    k = fmap.kernels
    for p in _edge_points(fmap):
        q = p.tolist()
        fast = magnet_terms_one(k["magnet"], k["magnet_one"], q)
        slow = magnet_terms_one(k["magnet"], None, q)
        assert np.abs(fast - slow).max() <= 1e-12 * np.abs(slow).max()
