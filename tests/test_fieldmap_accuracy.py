"""The map's interpolation error against direct evaluation of the coupled model
(CoilArray.actuation_matrix) at 1e4 random points -- half uniform in the box, half in its
lowest 10 mm where the fields vary fastest -- for seeded random array geometries (1 x 2, 2 x 2,
3 x 3; pitch, core radius and length, box drawn at random, its floor 18-24 mm above the coil
tops around the default 20 mm). Target: every row within 1e-3 of that row's largest |A| over
the sample. Slow: each case builds a map (tens of seconds) and evaluates the coupled model
directly at 1e4 points."""

import numpy as np
import pytest

from designkit import default_design, fieldmap
from designkit.model.array import ROWS, CoilArray


def _geometry(shape, seed):
    rng = np.random.default_rng(seed)
    rows, cols = shape
    pitch = rng.uniform(0.042, 0.060)
    half = pitch * (max(rows, cols) - 1) / 2 + rng.uniform(0.008, 0.02)
    z_min = rng.uniform(0.018, 0.024)
    return default_design().replace(**{
        "array.rows": rows, "array.columns": cols, "array.pitch_m": pitch,
        "core.radius_m": rng.uniform(0.008, 0.012), "core.length_m": rng.uniform(0.100, 0.115),
        "workspace.shape": "box", "workspace.half_width_m": half, "workspace.z_min_m": z_min,
        "workspace.z_max_m": z_min + rng.uniform(0.02, 0.04)})


def _points(lo, hi, n, seed):
    rng = np.random.default_rng(seed)
    p = rng.uniform(lo, hi, (n, 3))
    p[n // 2:, 2] = rng.uniform(lo[2], lo[2] + 0.010, n - n // 2)
    return p


@pytest.mark.slow
@pytest.mark.parametrize("shape,seed", [((1, 2), 1), ((2, 2), 2), ((3, 3), 3)])
def test_map_within_1e3_of_the_direct_coupled_model(tmp_path, shape, seed):
    design = _geometry(shape, seed)
    path = fieldmap.write(tmp_path / "m.npz", fieldmap.build(design, n_check=10, progress=False))
    fm = fieldmap.load(path, design)
    lo, hi = fm.bounds
    p = _points(lo, hi, 10000, seed)
    direct = CoilArray.from_design(design).actuation_matrix(p)
    got = fm.actuation(p)
    err = np.abs(got - direct).max(axis=(0, 2)) / np.abs(direct).max(axis=(0, 2))
    print(shape, seed, f"max {err.max():.2e}", dict(zip(ROWS, err.round(6).tolist())))
    assert np.all(err <= 1e-3), dict(zip(ROWS, err.round(6).tolist()))
    # the runner's subsets are the same entries
    r, c = [3, 6], list(range(0, fm.n_coils, 2))
    np.testing.assert_allclose(fm.actuation(p[:500], rows=r, coils=c), got[:500][:, r][:, :, c],
                               rtol=1e-5, atol=1e-6 * np.abs(got).max())  # float32 products
