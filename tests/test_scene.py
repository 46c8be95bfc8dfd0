"""Scenes: only what is asked, rigorous coil skipping, shared (rho, z) tables (air coils)."""

import numpy as np
import pytest

from designkit import Coil, default_design
from designkit.model.array import CoilArray, force_matrix
from designkit.errors import BadInputError
from designkit.model.skipping import SkippingEvaluator as Scene, bound_at, build_table, RZ_COMPONENTS

AIR = default_design().replace(core=None)
M = (0.0, 0.0, 0.909)


@pytest.fixture(scope="module")
def arr():
    return CoilArray.from_design(AIR)


@pytest.fixture(scope="module")
def pts():
    rng = np.random.default_rng(5)
    return np.c_[rng.uniform(-0.075, 0.075, (300, 2)), rng.uniform(0.01, 0.08, 300)]


@pytest.fixture(scope="module")
def direct(arr, pts):
    return arr.actuation_matrix(pts)


def test_direct_scene_matches_actuation_matrix(arr, pts, direct):
    r = Scene(arr, pts, ("B", "gradient", "force", "fz", "torque"), moment=M,
              tables="never", skip="never").evaluate()
    np.testing.assert_allclose(r.actuation(), direct, rtol=1e-11, atol=1e-15)
    f = np.einsum("rk,nkc->nrc", force_matrix(M), direct[:, 3:])
    np.testing.assert_allclose(r["force"], f, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(r["fz"], f[:, 2], rtol=1e-10, atol=1e-14)
    tq = np.cross(np.asarray(M)[None, :, None], direct[:, :3], axisa=1, axisb=1, axisc=1)
    np.testing.assert_allclose(r["torque"], tq, atol=1e-16)


@pytest.mark.parametrize("outputs", [("B", "gradient"), ("force",), ("fz",)])
def test_tables_meet_the_tolerance(arr, pts, direct, outputs):
    tol = 1e-5
    r = Scene(arr, pts, outputs, moment=M, tolerance=tol, tables="always",
              skip="never").evaluate()
    assert r.stats["table_pairs"] == 9 * len(pts)
    ref = Scene(arr, pts, outputs, moment=M, tables="never", skip="never").evaluate()
    for o in outputs:
        err = np.abs(r[o] - ref[o])
        scale = np.abs(ref[o]).max(axis=tuple(k for k in range(ref[o].ndim) if k != 1)
                                   if ref[o].ndim == 3 else None)
        assert np.all(err.max(axis=(0, 2) if err.ndim == 3 else None) <= tol * scale)


def test_fz_uses_only_dbz_dz(arr):
    sc = Scene(arr, [[0, 0, 0.03]], ("fz",), moment=M)
    assert sc._needs(arr.coils[0]) == (False, ("dbz_dz",))
    assert Scene(arr, [[0, 0, 0.03]], ("B",))._needs(arr.coils[0]) == (False, ("br", "bz"))


def test_skipping_is_rigorous_and_happens():
    c = Coil.from_design(AIR)
    far = CoilArray((c, c.moved((0.6, 0.0, -0.05)), c.moved((0.0, 0.6, -0.05))))
    rng = np.random.default_rng(0)
    p = np.c_[rng.uniform(-0.03, 0.03, (200, 2)), rng.uniform(0.01, 0.05, 200)]
    ref = Scene(far, p, ("B", "gradient"), tables="never", skip="never").evaluate()
    for cur in (None, (6.0, -6.0, 6.0)):
        r = Scene(far, p, ("B", "gradient"), tolerance=1e-2, tables="never", skip="bound",
                  currents=cur).evaluate()
        ref_o = ref.values if cur is None else {k: v @ np.asarray(cur) for k, v in
                                                ref.values.items()}
        assert r.stats["skipped"] == 2 * len(p)
        for o in ("B", "gradient"):
            err = np.abs(r[o] - ref_o[o]).max()
            assert 0 < err <= 1e-2 * np.abs(ref_o[o]).max()


def test_sphere_bound_holds_at_random_points():
    c = Coil.from_design(AIR)
    rng = np.random.default_rng(4)
    d = rng.normal(size=(400, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    p = d * rng.uniform(0.06, 0.5, (400, 1)) + c.pose.position
    eb, eg = bound_at(c, c.pose.to_local(p))
    b, g = c.field(p, 1.0, gradient=True)
    ok = np.isfinite(eb)
    assert ok.sum() > 200
    assert np.all(np.linalg.norm(b, axis=1)[ok] <= eb[ok])
    assert np.all(np.linalg.norm(g, axis=(1, 2))[ok] <= eg[ok])


def test_table_refuses_a_box_that_touches_the_sources():
    c = Coil.from_design(AIR, (0, 0, 0))
    assert build_table(c, (0.0, 0.1), (0.0, 0.1), RZ_COMPONENTS, 1e-4) is None


def test_bad_input(arr):
    with pytest.raises(BadInputError, match="along z"):
        Scene(arr, [[0, 0, 0.03]], ("fz",), moment=(0.1, 0, 1))
    with pytest.raises(BadInputError, match="outputs"):
        Scene(arr, [[0, 0, 0.03]], ("Bz",))
    with pytest.raises(BadInputError, match="moment"):
        Scene(arr, [[0, 0, 0.03]], ("force",))
    with pytest.raises(BadInputError, match="currents"):
        Scene(arr, [[0, 0, 0.03]], ("B",), currents=(1.0, 2.0))
