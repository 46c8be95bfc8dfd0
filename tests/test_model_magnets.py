"""Several magnets over one array (designkit.model.magnets): each magnet's F0 and the cross terms
(the cores one magnet magnetizes pulling on another) and the cores' field, against the cached
3-D GetDP FEM of two 10 x 10 mm magnets over the thesis array (tests/data/magnets_fem_refs.*,
make_magnets_fem_refs.py), reciprocity of linear cores, and the refusal of overlapping magnets."""

import json
from pathlib import Path

import numpy as np
import pytest

from designkit.design import default_design
from designkit.errors import BadInputError
from designkit.model.array import CoilArray

DATA = Path(__file__).parent / "data"
REFS = dict(np.load(DATA / "magnets_fem_refs.npz"))
REFS_META = json.loads((DATA / "magnets_fem_refs.json").read_text())
CASES = ("side", "apart", "tilted")
MAGNET = default_design().magnet
SIZE = (MAGNET.radius_m, MAGNET.length_m)

FEM_LOW = (1.03, 1.09)
"""Model / FEM of every entry's magnitude at level -1 (measured 1.053-1.075): the FEM at level
-1 is low by a common factor (the cores' magnetization under-resolved: one core's pull is
2.6-3.4 % low at level -1 and 5-7 % at level -2, test_coupling_fem_cache.py)."""
RATIO_SPREAD = 0.015
"""Largest spread of those ratios within a case (measured 0.6 / 0.8 / 0.6 %): the cross terms
2 % off against the F0s, a dropped or sign-flipped term, fail it."""


@pytest.fixture(scope="module")
def arr():
    return CoilArray.default()


def _ratios(model, fem):
    return np.linalg.norm(model, axis=-1) / np.linalg.norm(fem, axis=-1)


@pytest.mark.parametrize("case", CASES)
def test_f0_and_cross_terms_against_the_3d_fem(arr, case):
    assert f"{case}_L-1" in REFS_META
    p, m = REFS[f"{case}_positions_m"], REFS[f"{case}_moments_a_m2"]
    f, t = arr.bias_force_matrix(p, m, magnet_sizes_m=SIZE)
    fe, te = REFS[f"{case}_L-1_force_n"], REFS[f"{case}_L-1_torque_n_m"]
    r = _ratios(f, fe)
    assert FEM_LOW[0] < r.min() and r.max() < FEM_LOW[1], r
    assert r.max() / r.min() - 1 < RATIO_SPREAD, r
    # the same directions (measured within 0.45 degrees)
    cos = (f * fe).sum(-1) / np.linalg.norm(f, axis=-1) / np.linalg.norm(fe, axis=-1)
    assert cos.min() > np.cos(np.radians(1.0)), np.degrees(np.arccos(cos))
    # torques about each centre, against the case's largest (measured 5.4 / 6.7 / 6.0 %)
    et = np.linalg.norm(t - te, axis=-1).max() / np.linalg.norm(te, axis=-1).max()
    assert et < FEM_LOW[1] - 1, et
    # the cross terms are not small: without them the sum is far off
    no_cross = np.linalg.norm(np.diagonal(f, axis1=0, axis2=1).T - fe.sum(axis=1), axis=-1)
    assert np.all(no_cross > 0.12 * np.linalg.norm(fe.sum(axis=1), axis=-1))
    fs, ts = arr.bias_forces(p, m, magnet_sizes_m=SIZE)
    np.testing.assert_allclose(fs, f.sum(axis=1), rtol=0, atol=1e-15)
    np.testing.assert_allclose(ts, t.sum(axis=1), rtol=0, atol=1e-18)


@pytest.mark.parametrize("case", CASES)
def test_cores_field_against_the_3d_fem(arr, case):
    p, m = REFS[f"{case}_positions_m"], REFS[f"{case}_moments_a_m2"]
    pts, be = REFS[f"{case}_points_m"], REFS[f"{case}_L-1_b_t"]
    each = np.stack([arr.magnets_core_field(pts, p[k:k + 1], m[k:k + 1], magnet_sizes_m=SIZE)
                     for k in range(len(p))])
    r = _ratios(each, be)  # measured 1.043-1.069
    assert FEM_LOW[0] < r.min() and r.max() < FEM_LOW[1], r
    both = arr.magnets_core_field(pts, p, m, magnet_sizes_m=SIZE)
    np.testing.assert_allclose(both, each.sum(axis=0), rtol=1e-12, atol=1e-18)


def test_diagonal_is_each_magnets_own_f0_and_cores_are_reciprocal(arr):
    p = np.array([[-0.02, 0.01, 0.03], [0.025, -0.005, 0.045], [0.0, 0.03, 0.06]])
    m = MAGNET.moment_a_m2 * np.array([[0.3, 0.0, -1.0], [0.0, -0.4, -1.0], [0.5, 0.5, 0.7]])
    m /= np.linalg.norm(m, axis=1)[:, None] / MAGNET.moment_a_m2
    for size in (None, SIZE):
        f, t = arr.bias_force_matrix(p, m, magnet_sizes_m=size)
        for i in range(3):
            kw = {} if size is None else {"magnet_size_m": size}
            np.testing.assert_allclose(f[i, i], arr.bias_force(p[i], m[i], **kw), rtol=1e-10,
                                       atol=1e-16)
    # linear cores: m_i . B_k(p_i) = m_k . B_i(p_k) (B_k: the cores magnetized by dipole k);
    # the model's source projection keeps it to 4.5e-4 (the azimuthal sampling of the drive)
    b = np.stack([arr.magnets_core_field(p, p[k:k + 1], m[k:k + 1]) for k in range(3)])
    u = np.einsum("kic,ic->ik", b, m)  # u[i, k] = m_i . B_k(p_i)
    np.testing.assert_allclose(u, u.T, rtol=2e-3)
    # the gradient of the cores' field of all three, against central differences
    q, e = np.array([[0.01, 0.01, 0.05]]), 1e-6
    b, g = arr.magnets_core_field(q, p, m, gradient=True)
    np.testing.assert_allclose(b, arr.magnets_core_field(q, p, m), rtol=0, atol=0)
    fd = np.stack([(arr.magnets_core_field(q + e * d, p, m) - arr.magnets_core_field(
        q - e * d, p, m))[0] / (2 * e) for d in np.eye(3)], axis=-1)
    np.testing.assert_allclose(g[0], fd, rtol=0, atol=1e-6 * np.abs(fd).max())


def test_overlapping_magnets_are_refused(arr):
    p = np.array([[0.0, 0.0, 0.03], [0.008, 0.0, 0.03]])
    m = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    with pytest.raises(BadInputError, match="overlap"):
        arr.bias_force_matrix(p, m, magnet_sizes_m=SIZE)
    with pytest.raises(BadInputError, match="moments_a_m2"):
        arr.bias_forces(p, m[:1])
    with pytest.raises(BadInputError, match="magnet_sizes_m"):
        arr.bias_forces(p, m, magnet_sizes_m=(-0.005, 0.01))
