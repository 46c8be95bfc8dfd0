"""CoilArray: actuation matrix, F(m), Sk(m), symmetry, drive-limit metrics (air coils: the
core model is owned elsewhere and changing)."""

import numpy as np
import pytest

from designkit import Coil, Pose, default_design
from designkit.model.array import (ROWS, CoilArray, force_matrix, g5_from_gradient,
                                   gradient_from_g5, skew_matrix)
from designkit.model.metrics import condition_number, fz_per_amp, max_vertical_force
from designkit.errors import BadInputError, DesignRuleError
from designkit.field import dipole_field

AIR = default_design().replace(core=None)


@pytest.fixture(scope="module")
def arr():
    return CoilArray.from_design(AIR)


def test_default_layout():
    a = CoilArray.default()
    assert a.n_coils == 9 and ROWS[3] == "dBx/dx"
    pos = a.positions()
    # pitch 50 mm, row-major from +y, winding centres half a length below the tops at z = 0
    np.testing.assert_allclose(pos[0], [-0.05, 0.05, -0.05])
    np.testing.assert_allclose(pos[8], [0.05, -0.05, -0.05])
    assert all(c.core is not None for c in a.coils)
    assert len(a.coil_types()) == 1


def test_force_matrix_equals_grad_m_dot_b():
    # independent source: the closed-form dipole field and its gradient, and a
    # central difference of the energy m.B
    rng = np.random.default_rng(3)
    src = np.array([0.3, -0.2, 1.1])
    m = np.array([0.2, -0.5, 0.9])
    for p in rng.uniform(-0.05, 0.05, (5, 3)) + [0, 0, 0.1]:
        b, g = dipole_field(p, src, gradient=True)
        f_full = g.T @ m
        f5 = force_matrix(m) @ g5_from_gradient(g)
        np.testing.assert_allclose(f5, f_full, rtol=1e-12, atol=1e-18)
        h = 1e-6
        fd = [(m @ dipole_field(p + h * e, src) - m @ dipole_field(p - h * e, src)) / (2 * h)
              for e in np.eye(3)]
        np.testing.assert_allclose(f5, fd, rtol=1e-6)
        np.testing.assert_allclose(skew_matrix(m) @ b, np.cross(m, b), atol=1e-20)
        np.testing.assert_allclose(gradient_from_g5(g5_from_gradient(g)), g, atol=1e-15)


def test_superposition_against_direct_field_sums(arr):
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(-0.07, 0.07, (6, 2)), rng.uniform(0.01, 0.08, 6)]
    cur = rng.uniform(-6, 6, 9)
    b_sum = sum(c.field(pts, i) for c, i in zip(arr.coils, cur))
    g_sum = sum(c.field(pts, i, gradient=True)[1] for c, i in zip(arr.coils, cur))
    y = arr.actuation_matrix(pts) @ cur
    np.testing.assert_allclose(y[:, :3], b_sum, rtol=1e-12, atol=1e-16)
    np.testing.assert_allclose(y[:, 3:], g5_from_gradient(g_sum), rtol=1e-12, atol=1e-14)
    m = np.array([0, 0, AIR.magnet.moment_a_m2])
    np.testing.assert_allclose(arr.force(pts, m, cur), np.einsum("nji,j->ni", g_sum, m),
                               rtol=1e-11, atol=1e-15)
    np.testing.assert_allclose(arr.torque(pts, m, cur), np.cross(m, b_sum), atol=1e-15)


def _transform(a, r):
    """Actuation rows under the rotation/reflection r: B -> r B, G -> r G r^T."""
    b = np.einsum("ij,njc->nic", r, a[:, :3])
    g = gradient_from_g5(np.moveaxis(a[:, 3:], 1, -1))
    g = np.einsum("ia,ncab,jb->ncij", r, g, r)
    return np.concatenate([b, np.moveaxis(g5_from_gradient(g), -1, 1)], axis=1)


def test_mirror_and_quarter_turn_symmetry(arr):
    # row-major index k = 3 i + j, x = (j - 1) pitch, y = (1 - i) pitch
    rng = np.random.default_rng(1)
    p = np.c_[rng.uniform(-0.07, 0.07, (4, 2)), rng.uniform(0.01, 0.08, 4)]
    a = arr.actuation_matrix(p)
    idx = np.arange(9).reshape(3, 3)
    # mirror x -> -x: B is a pseudovector (B' = det(r) r B) and mirroring also reverses each
    # coil's sense of circulation; the two signs cancel for the real (unmirrored) coils
    mir = np.diag([-1.0, 1.0, 1.0])
    perm = idx[:, ::-1].ravel()
    a_m = arr.actuation_matrix(p @ mir.T)
    np.testing.assert_allclose(a_m[:, :, perm], _transform(a, mir), rtol=1e-10, atol=1e-14)
    # 90 degrees about z: (x, y) -> (-y, x); coil (i, j) goes to (2 - j, i)
    rot = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    a_r = arr.actuation_matrix(p @ rot.T)
    target = _transform(a, rot)
    for k_old in range(9):
        i, j = divmod(k_old, 3)
        k_new = 3 * (2 - j) + i  # (x, y) = ((j-1)P, (1-i)P) -> ((i-1)P, (j-1)P)
        np.testing.assert_allclose(a_r[:, :, k_new], target[:, :, k_old], rtol=1e-10,
                                   atol=1e-14)


def test_overlap_names_coils():
    c = Coil.from_design(AIR)
    other = c.moved((0.03, 0.0, c.pose.position[2]))
    far = c.moved((0.2, 0.0, c.pose.position[2]))
    with pytest.raises(DesignRuleError, match="Coils 1 and 2 overlap"):
        CoilArray((far, c, other))
    tilted = Coil(c.inner_radius, c.outer_radius, c.length, c.turns,
                  pose=Pose.from_axis((0.0, 0.0, -0.05), (1.0, 0.0, 0.0)))
    with pytest.raises(DesignRuleError, match="Coils 0 and 1"):
        CoilArray((c, tilted))
    CoilArray((c, far))  # apart: fine
    with pytest.raises(BadInputError):
        CoilArray(())


def test_max_vertical_force_closed_form_matches_linprog():
    from scipy.optimize import linprog

    rng = np.random.default_rng(2)
    a = rng.normal(size=(20, 9))
    got = max_vertical_force(a, 6.0, 20.0)
    for k in range(20):
        res = linprog(-np.r_[a[k], -a[k]], A_ub=np.ones((1, 18)), b_ub=[20.0],
                      bounds=[(0, 6.0)] * 18, method="highs")
        assert got[k] == pytest.approx(-res.fun, rel=1e-9)
    # the budget never binds with 9 x 6 A <= 54 A: sum of |a| times 6 A
    np.testing.assert_allclose(max_vertical_force(a, 6.0, 54.0), 6 * np.abs(a).sum(1))


def test_metrics_on_the_array(arr):
    p = np.array([[0.0, 0.0, 0.03], [0.02, 0.01, 0.05]])
    a = arr.actuation_matrix(p)
    m = np.array([0.0, 0.0, AIR.magnet.moment_a_m2])
    fz = fz_per_amp(a, m)
    np.testing.assert_allclose(fz, m[2] * (-a[:, 3] - a[:, 6]), rtol=1e-12)
    free = max_vertical_force(fz, 6.0, 54.0)
    force3 = np.einsum("rk,nkc->nrc", force_matrix(m), a[:, 3:])
    pure = max_vertical_force(force3, 6.0, 54.0, lateral="zero")
    assert np.all(pure <= free * (1 + 1e-9)) and np.all(pure > 0)
    # reference: numpy's cond of the matrix scaled by hand (gradient rows x 30 mm)
    scaled = a.copy()
    scaled[:, 3:, :] *= 0.03
    np.testing.assert_allclose(condition_number(a), np.linalg.cond(scaled, 2), rtol=1e-10)
    unscaled = np.linalg.cond(a, 2)
    assert np.all(np.abs(condition_number(a) / unscaled - 1) > 0.1)  # the scaling is applied


def test_workspace_metrics_png(tmp_path, arr):
    from designkit.model.metrics import workspace_metrics

    png = tmp_path / "metrics.png"
    res = workspace_metrics(AIR, spacing=0.025, heights=(0.03,), out_png=png, array=arr)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # independent of the scene/table path: closed-form allocation on the direct A at (0, 0, 30 mm)
    k = int(np.argmin(np.abs(res["x_m"])))
    a = arr.actuation_matrix(np.array([[0.0, 0.0, 0.03]]))
    fz = fz_per_amp(a, [0, 0, AIR.magnet.moment_a_m2])
    want = 6.0 * np.abs(fz).sum()
    assert res["max_fz_n"][0][k, k] == pytest.approx(want, rel=1e-3)
    assert 0 <= res["fraction_above_threshold"][0] <= 1
