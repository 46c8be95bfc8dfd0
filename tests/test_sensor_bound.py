"""The Cramer-Rao bound of magnet poses (designkit.sensing.crb, .response) against independent
references: magpylib's cylinder for the field and its Jacobian, the public coupled-core model
for the cores' term, a least-squares fit's scatter on magpylib readings, closed forms for the
noise and the mean absolute error, and the issue's quoted numbers for the thesis layout."""

import math

import magpylib as magpy
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from designkit import default_design
from designkit.constants import MU0
from designkit.sensing.crb import BoundSettings, mean_norm, pose_bound
from designkit.sensing.response import (MagnetShape, cylinder_response, magnet_response,
                                        tangent_frame)

DESIGN = default_design()
SHAPE = MagnetShape.of(DESIGN.magnet)
SENSORS, FRAMES = DESIGN.sensor_poses()
MAGNET_ONLY = BoundSettings(cores="none")
QUOTED = BoundSettings(dof="position", background="none", cores="none", lsb_t=0.0)
"""What the issue's numbers assume: directions known, no background, no cores, no rounding."""


def magpylib_field(sites, centre, direction):
    """magpylib's uniformly magnetized cylinder (the thesis magnet) at the sites, T."""
    rot = Rotation.from_matrix(tangent_frame(direction))
    m = magpy.magnet.Cylinder(polarization=(0, 0, MU0 * SHAPE.magnetization_a_per_m),
                              dimension=(2 * SHAPE.radius_m, SHAPE.length_m),
                              position=centre, orientation=rot)
    return m.getB(sites)


@pytest.mark.parametrize("seed", range(3))
def test_field_and_jacobian_match_magpylib_central_differences(seed):
    # a tilted magnet anywhere above the board: each of the five columns against magpylib's
    # field moved (x, y, z) or turned (about e1, e2) by +-1 um / 1 urad
    rng = np.random.default_rng(seed)
    sites = rng.uniform([-0.07, -0.07, -0.12], [0.07, 0.07, 0.014], (12, 3))
    centre = rng.uniform([-0.05, -0.05, 0.03], [0.05, 0.05, 0.07])
    u = rng.normal(size=3)
    u[2] = -abs(u[2]) - 1.0
    u /= np.linalg.norm(u)
    b, jac = cylinder_response(sites, centre, u, SHAPE)
    np.testing.assert_allclose(b, magpylib_field(sites, centre, u), rtol=0,
                               atol=1e-12 * np.abs(b).max())
    fd = _magpylib_jacobian(sites, centre, u)
    for k in range(5):
        np.testing.assert_allclose(jac[:, :, k], fd[:, :, k], rtol=0,
                                   atol=1e-6 * np.abs(fd[:, :, k]).max())


def test_cores_term_matches_the_coupled_model_moved_and_turned(thesis_array):
    # the cores' field and its Jacobian against CoilArray.magnet_core_field (the public
    # coupled solve) moved by +-0.5 mm and its moment turned by +-1 mrad
    sites = np.r_[SENSORS[[4, 13, 0]], [[0.025, 0.0, 0.014]]]
    centre, u = np.array([0.01, -0.005, 0.035]), np.array([0.1, 0.2, -1.0])
    u /= np.linalg.norm(u)
    m = u * SHAPE.moment_a_m2
    with_cores = magnet_response(sites, centre[None], u, SHAPE, array=thesis_array)
    alone = magnet_response(sites, centre[None], u, SHAPE)
    b = with_cores.field_t[:, 0] - alone.field_t[:, 0]
    jac = with_cores.jacobian[:, 0] - alone.jacobian[:, 0]
    np.testing.assert_allclose(b, thesis_array.magnet_core_field(sites, centre, m), rtol=1e-9)
    h, e = 5e-4, tangent_frame(u)
    for k in range(5):
        if k < 3:
            step = h * np.eye(3)[k]
            fd = (thesis_array.magnet_core_field(sites, centre + step, m)
                  - thesis_array.magnet_core_field(sites, centre - step, m)) / (2 * h)
        else:
            rot = [Rotation.from_rotvec(s * 1e-3 * e[:, k - 3]).apply(m) for s in (1, -1)]
            fd = (thesis_array.magnet_core_field(sites, centre, rot[0])
                  - thesis_array.magnet_core_field(sites, centre, rot[1])) / 2e-3
        # central differences of step h: error ~ (h / d)^2, d ~ 15 mm
        np.testing.assert_allclose(jac[:, :, k], fd, rtol=0, atol=3e-3 * np.abs(fd).max())


def test_the_readout_rounding_adds_lsb_squared_over_12():
    resp = magnet_response(SENSORS, np.array([[0.02, 0.01, 0.045]]), DESIGN.magnet.direction,
                           SHAPE)
    with_lsb = pose_bound(resp, [[0]], np.arange(18), FRAMES, MAGNET_ONLY)
    without = pose_bound(resp, [[0]], np.arange(18), FRAMES,
                         BoundSettings(cores="none", lsb_t=0.0))
    ratio = math.sqrt(1 + 0.098e-3 ** 2 / 12 / 0.1e-3 ** 2)  # 1.0392
    np.testing.assert_allclose(with_lsb.position_rms_m / without.position_rms_m, ratio,
                               rtol=1e-9)
    np.testing.assert_allclose(with_lsb.orientation_rms_rad / without.orientation_rms_rad,
                               ratio, rtol=1e-9)
    # and the bound is linear in the noise
    doubled = pose_bound(resp, [[0]], np.arange(18), FRAMES,
                         BoundSettings(cores="none", lsb_t=0.0, noise_t=0.2e-3))
    np.testing.assert_allclose(doubled.position_rms_m, 2 * without.position_rms_m, rtol=1e-9)


def test_turning_a_chip_changes_nothing_until_it_decides_saturation():
    # isotropic noise: the bound ignores how a chip is turned; but a chip axis beyond 80 % of
    # the range takes the sensor out, and that depends on the chip's axes
    site = np.array([[0.0, 0.0, 0.014]])
    sites = np.r_[site, SENSORS[[0, 2, 6, 8, 1, 3, 5, 7]]]
    centre = np.array([[0.0, 0.0, 0.0245]])  # |B| ~ 150 mT along z at the first site
    resp = magnet_response(sites, centre, DESIGN.magnet.direction, SHAPE)
    bz = abs(resp.field_t[0, 0, 2])
    assert 0.8 * 0.130 < bz < math.sqrt(3) * 0.8 * 0.130
    aligned = np.tile(np.eye(3), (len(sites), 1, 1))
    diagonal = aligned.copy()
    diagonal[0] = Rotation.align_vectors([[1, 1, 1]], [[0, 0, 1]])[0].as_matrix().T
    b_aligned = pose_bound(resp, [[0]], np.arange(len(sites)), aligned, MAGNET_ONLY)
    b_turned = pose_bound(resp, [[0]], np.arange(len(sites)), diagonal, MAGNET_ONLY)
    b_without = pose_bound(resp, [[0]], np.arange(1, len(sites)), aligned[1:], MAGNET_ONLY)
    assert b_aligned.usable[0] == len(sites) - 1 and b_turned.usable[0] == len(sites)
    np.testing.assert_allclose(b_aligned.position_rms_m, b_without.position_rms_m, rtol=1e-12)
    assert b_turned.position_rms_m[0, 0] < 0.5 * b_aligned.position_rms_m[0, 0]
    # far away nothing saturates: any turn of any chip gives the same bound
    far = magnet_response(sites, np.array([[0.03, 0.0, 0.06]]), DESIGN.magnet.direction, SHAPE)
    rots = Rotation.random(len(sites), random_state=1).as_matrix()
    np.testing.assert_allclose(pose_bound(far, [[0]], np.arange(len(sites)), rots,
                                          MAGNET_ONLY).position_rms_m,
                               pose_bound(far, [[0]], np.arange(len(sites)), aligned,
                                          MAGNET_ONLY).position_rms_m, rtol=1e-9)


def test_mean_absolute_error_of_a_gaussian_matches_closed_forms():
    # round: E|e| = 2 sqrt(2 / pi) sigma; needle: E|z| = sqrt(2 / pi); flat disc: sqrt(pi / 2)
    np.testing.assert_allclose(mean_norm(4.0 * np.eye(3)), 2 * 2 * math.sqrt(2 / math.pi),
                               rtol=1e-9)
    np.testing.assert_allclose(mean_norm(np.diag([1.0, 0, 0])), math.sqrt(2 / math.pi),
                               rtol=1e-4)
    np.testing.assert_allclose(mean_norm(np.diag([1.0, 1.0, 0])), math.sqrt(math.pi / 2),
                               rtol=1e-4)


def test_the_issue_numbers_for_the_thesis_layout():
    # one magnet over the centre coil: 0.04 / 0.50 / 2.2 mm at 30 / 45 / 60 mm, and two magnets
    # 20-30 mm apart there: 1.4-2.4 / 2.1-3.1 / 4.5-6.5 mm, quoted for 0.1 mT with the
    # position alone; the rounding term (x 1.039) is left out as the quote did
    heights = np.array([0.03, 0.045, 0.06])
    pts = np.concatenate([[[0, 0, z], [-0.01, 0, z], [0.01, 0, z], [-0.015, 0, z],
                           [0.015, 0, z]] for z in heights])
    resp = magnet_response(SENSORS, pts, DESIGN.magnet.direction, SHAPE)
    one = pose_bound(resp, [[5 * k] for k in range(3)], np.arange(18), FRAMES, QUOTED)
    np.testing.assert_allclose(one.position_rms_m[:, 0] * 1e3, [0.0353, 0.493, 2.19],
                               rtol=5e-3)
    assert np.all(np.abs(one.position_rms_m[:, 0] * 1e3 - [0.04, 0.50, 2.2])
                  <= [0.005, 0.01, 0.05])
    two = pose_bound(resp, [[5 * k + a, 5 * k + a + 1] for k in range(3) for a in (1, 3)],
                     np.arange(18), FRAMES, QUOTED)
    worst = two.position_rms_m.max(axis=1).reshape(3, 2) * 1e3  # (height, 20 / 30 mm apart)
    quoted = np.array([[2.4, 1.4], [3.1, 2.1], [6.5, 4.5]])
    assert np.all(np.abs(worst / quoted - 1) < 0.05), worst
    # the pose (5 unknowns a magnet) and the background the estimator fits cost more
    full = pose_bound(resp, [[5 * k] for k in range(3)], np.arange(18), FRAMES, MAGNET_ONLY)
    assert np.all(full.position_rms_m > 2 * one.position_rms_m)


def _magpylib_jacobian(sites, centre, u, h=1e-6):
    """(n, 3, 5) by central differences of magpylib's field (moved, then turned)."""
    e = tangent_frame(u)
    cols = []
    for k in range(5):
        if k < 3:
            step = h * np.eye(3)[k]
            cols.append((magpylib_field(sites, centre + step, u)
                         - magpylib_field(sites, centre - step, u)) / (2 * h))
        else:
            turn = [Rotation.from_rotvec(s * h * e[:, k - 3]).apply(u) for s in (1, -1)]
            cols.append((magpylib_field(sites, centre, turn[0])
                         - magpylib_field(sites, centre, turn[1])) / (2 * h))
    return np.stack(cols, axis=-1)


def test_two_magnets_jointly_match_a_fisher_matrix_built_from_magpylib():
    # two tilted magnets 30 mm apart plus the background, 13 unknowns: the joint covariance
    # from magpylib's Jacobians, assembled and inverted here, per magnet
    pts = np.array([[-0.01, 0.005, 0.04], [0.02, 0.005, 0.045]])
    dirs = np.array([[0.2, 0.0, -1.0], [-0.1, 0.3, -1.0]])
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    resp = magnet_response(SENSORS, pts, dirs, SHAPE)
    b = pose_bound(resp, [[0, 1]], np.arange(18), FRAMES, MAGNET_ONLY)
    jac = np.concatenate([_magpylib_jacobian(SENSORS, p, u) for p, u in zip(pts, dirs)]
                         + [np.broadcast_to(np.eye(3), (18, 3, 3))], axis=-1).reshape(-1, 13)
    cov = np.linalg.inv(jac.T @ jac / MAGNET_ONLY.variance_t2)
    for k in range(2):
        np.testing.assert_allclose(b.position_rms_m[0, k],
                                   math.sqrt(np.trace(cov[5 * k:5 * k + 3, 5 * k:5 * k + 3])),
                                   rtol=1e-5)
        np.testing.assert_allclose(b.orientation_rms_rad[0, k],
                                   math.sqrt(cov[5 * k + 3, 5 * k + 3] + cov[5 * k + 4,
                                                                             5 * k + 4]),
                                   rtol=1e-5)
    single = pose_bound(resp, [[0]], np.arange(18), FRAMES, MAGNET_ONLY)
    assert b.position_rms_m[0, 0] > 1.5 * single.position_rms_m[0, 0]
    # two sensors (6 readings) cannot hold 8 unknowns: singular, reported as such, finite
    few = pose_bound(resp, [[0]], [4, 13], FRAMES[[4, 13]], MAGNET_ONLY)
    assert not few.observable[0] and few.position_rms_m[0, 0] == 1.0
    assert np.all(np.isfinite(few.condition)) and np.all(np.isfinite(few.position_mae_m))


def _fit_scatter(centre, u, trials, seed):
    """rms position error and rms direction error of least-squares fits (5 unknowns + the
    background) to magpylib readings with 0.1 mT noise rounded to 0.098 mT counts."""
    from scipy.optimize import least_squares

    from firmware_io.localization.magnet import cylinder_field

    rng = np.random.default_rng(seed)
    truth = magpylib_field(SENSORS, centre, u)
    e = tangent_frame(u)

    def model(x):
        uu = Rotation.from_rotvec(x[3] * e[:, 0] + x[4] * e[:, 1]).apply(u)
        return (cylinder_field(SENSORS, x[:3], uu * SHAPE.moment_a_m2, SHAPE.radius_m,
                               SHAPE.length_m) + x[5:]).ravel()

    pos, ang = [], []
    for _ in range(trials):
        y = np.round((truth + rng.normal(0, 1e-4, truth.shape)) / 0.098e-3) * 0.098e-3
        r = least_squares(lambda x: (model(x) - y.ravel()) / 1e-4, np.r_[centre, np.zeros(5)],
                          x_scale=np.r_[[1e-3] * 3, 0.05, 0.05, [1e-4] * 3], xtol=1e-12)
        pos.append(r.x[:3] - centre)
        ang.append(r.x[3:5])
    return (math.sqrt(np.mean(np.sum(np.square(pos), 1))),
            math.sqrt(np.mean(np.sum(np.square(ang), 1))))


@pytest.mark.parametrize("centre", [pytest.param([0.0, 0.0, 0.03]),
                                    pytest.param([0.025, 0.0, 0.035], marks=pytest.mark.slow),
                                    pytest.param([0.03, -0.02, 0.03], marks=pytest.mark.slow)])
def test_least_squares_scatter_on_magpylib_readings_meets_the_bound(centre):
    # the fit is efficient where the errors are small: its scatter equals the bound within
    # the sampling error of an rms over n trials (~0.71 / sqrt(n) relative, 3 sigma)
    centre = np.array(centre)
    u = np.array([0.2, 0.1, -1.0]) / np.linalg.norm([0.2, 0.1, -1.0])
    trials = 150
    rms, ang = _fit_scatter(centre, u, trials, seed=7)
    resp = magnet_response(SENSORS, centre[None], u, SHAPE)
    b = pose_bound(resp, [[0]], np.arange(18), FRAMES, MAGNET_ONLY)
    tol = 3 * 0.71 / math.sqrt(trials)
    assert abs(rms / b.position_rms_m[0, 0] - 1) < tol, (rms, b.position_rms_m)
    assert abs(ang / b.orientation_rms_rad[0, 0] - 1) < tol, (ang, b.orientation_rms_rad)
