"""Smoke test of studies/map_cells.py and a closed-form check of its harmonic basis."""

import numpy as np

from conftest import load_study


def test_harmonic_basis_reproduces_a_known_potential():
    study = load_study("map_cells")
    e, ops = study.harmonic_rows(4)
    assert ops[0].shape[1] == 5 ** 2 - 1  # dim of harmonic polynomials of degree <= 4, minus 1
    rng = np.random.default_rng(3)
    s = rng.uniform(-1, 1, (50, 3))
    x, y, z = s.T
    # phi = x^3 - 3 x y^2 + z (x^2 + y^2) - 2 z^3 / 3 (harmonic); its 8 rows in closed form
    want = np.stack([3 * x**2 - 3 * y**2 + 2 * x * z, -6 * x * y + 2 * y * z,
                     x**2 + y**2 - 2 * z**2, 6 * x + 2 * z, -6 * y, 2 * x,
                     -6 * x + 2 * z, 2 * y], 1)
    m = study._monomials(e, s)
    g = np.stack([m @ op for op in ops], 1)  # (50, 8, K)
    coef = np.linalg.lstsq(g.reshape(-1, g.shape[2]), want.reshape(-1), rcond=None)[0]
    assert np.abs(g @ coef - want).max() < 1e-10


def test_map_cells_quick(tmp_path):
    res = load_study("map_cells").run(tmp_path, quick=True)
    assert (tmp_path / "map_cells.json").is_file()
    assert res["direct_us_per_point"] > 0 and len(res["configs"]) == 2
    assert all(0 < c["max_rel"] < 1 and c["bytes_per_cell"] > 0 for c in res["configs"])
    assert len(res["batch_cost"]) == 4 and all(b["loop_ms"] > 0 for b in res["batch_cost"])
    assert len(res["one_point"]) == 1 and res["one_point"][0]["one_point_us"] > 0
