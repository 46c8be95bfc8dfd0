"""The runner renders on the magnet that is there: the force rows and the reported torque use the
estimated moment, and the simulated plant pushes on the true (tilted) moment. References: the
force as the central difference of m . B over the array's field (no gradient rows, no force
law matrix), the torque m x B from the field itself, the tilted cylinder's field from
magpylib."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from designkit.model.array import CoilArray
from designkit.design import default_design
from designkit.sim import SimulatedDevice, tilted_direction
from firmware_io.allocation import allocate
from firmware_io.runner import Runner, RunnerConfig, RunnerIO, SensorFrame

from _runner_fakes import HoldTracker, PlaneScene, TruthEstimator, device_map, md10c_drive

BOX = (np.array([-0.075, -0.075, 0.010]), np.array([0.075, 0.075, 0.080]))
M = 0.909


def _force_by_differences(array, p, m, currents, h=1e-5):
    """grad(m . B) at p (N) from the array's field at p +- h e_k (central differences)."""
    pts = np.array([p + s * h * e for e in np.eye(3) for s in (1.0, -1.0)])
    b, _ = array.field(pts, currents)
    mb = b @ m
    return (mb[0::2] - mb[1::2]) / (2 * h)


class _Frames:
    """A sensor source handing one (unused) frame per step."""

    def __call__(self, t):
        return SensorFrame(np.zeros((18, 3)), ("ok",) * 18, t)


@pytest.fixture(scope="module")
def device(thesis_array):
    return SimulatedDevice(default_design(), thesis_array, seed=1,
                           drive=md10c_drive(default_design(), 6.0, 54.0))


@pytest.mark.parametrize("tilt_deg, azimuth_deg", [(0.0, 0.0), (25.0, 40.0), (45.0, 200.0)])
def test_the_force_is_rendered_on_the_estimated_moment(device, thesis_array, tilt_deg,
                                                        azimuth_deg):
    """The estimator reports a magnet tilted by 0-45 degrees: the allocated currents give the
    scene's force on THAT moment (independent central differences of m . B, 0.1 %), the
    reported torque is m x B of those currents; the same currents on the map's (upright)
    moment miss it by far more when tilted (so a runner that ignored the estimate fails)."""
    p = np.array([0.012, -0.008, 0.035])
    m = M * tilted_direction([0.0, 0.0, 1.0], np.radians(tilt_deg), np.radians(azimuth_deg))[0]
    a = thesis_array.actuation_matrix(p)
    cfg = RunnerConfig(device.drive, force_axes="xyz")
    scene = PlaneScene(0.05, 6.0)                    # 6 N/m x 15 mm = 90 mN up
    r = Runner(device_map(a, BOX, device), scene, TruthEstimator(lambda: p, m),
               RunnerIO(device.coils, _Frames(), lambda line: None, lambda: 0.0), cfg,
               tracker=HoldTracker(), allocate=allocate)
    r.start()
    rec = r.step(0.0)
    assert rec.state == "running"
    want = scene.force(p, np.zeros(3))
    got = _force_by_differences(thesis_array, p, m, rec.command_a)
    assert np.linalg.norm(got - want) <= 1e-3 * np.linalg.norm(want)
    b, _ = thesis_array.field(p[None], rec.command_a)
    np.testing.assert_allclose(rec.torque_n_m, np.cross(m, b[0]), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(rec.moment_a_m2, m, rtol=0, atol=1e-15)
    upright = _force_by_differences(thesis_array, p, np.array([0.0, 0.0, M]), rec.command_a)
    if tilt_deg >= 25.0:
        assert np.linalg.norm(upright - want) > 0.05 * np.linalg.norm(want)


def test_the_plant_pushes_on_the_true_tilted_moment(device, thesis_array):
    """The simulated device's force and torque at a step come from the moment the trajectory
    gives that step: against central differences of m . B plus the cores' pull on that same
    moment (CoilArray.bias_force of the magnet's cylinder, its axis along m), and m x B."""
    steps = 40
    p = np.linspace([0.0, 0.0, 0.03], [0.004, 0.002, 0.032], steps)
    u = tilted_direction([0.0, 0.0, 1.0], np.radians(np.linspace(0.0, 40.0, steps)),
                         np.radians(np.linspace(10.0, 70.0, steps)))
    device.prepare(p, u)
    rng = np.random.default_rng(2)
    for k in (0, 17, 39):
        i = rng.uniform(-3.0, 3.0, 9)
        m = M * u[k]
        mg = default_design().magnet
        want = _force_by_differences(thesis_array, p[k], m, i) + thesis_array.bias_force(
            p[k][None], m, magnet_size_m=(mg.radius_m, mg.length_m))[0]
        # samples every 0.5 degrees or 0.25 mm: the interpolation leaves ~1e-4 of the force
        np.testing.assert_allclose(device.true_force_n(k, i), want, rtol=0,
                                   atol=2e-3 * np.linalg.norm(want))
        b, _ = thesis_array.field(p[k][None], i)
        np.testing.assert_allclose(device.true_torque_n_m(k, i), np.cross(m, b[0]), rtol=0,
                                   atol=2e-3 * np.linalg.norm(np.cross(m, b[0])))


def test_the_bias_force_of_any_moment_is_the_quadratic_form():
    """F0 for a tilted moment from six fixed moments equals CoilArray.bias_force called with
    that moment (the cores are linear: F0 is quadratic in m)."""
    from designkit.sim.samples import bias_force_any

    arr = CoilArray.from_design(default_design())
    p = np.array([[0.01, 0.0, 0.03], [-0.02, 0.01, 0.04]])
    m = M * tilted_direction([0.0, 0.0, 1.0], np.radians([30.0, 60.0]), np.radians([45.0, 190.0]))
    got = bias_force_any(arr, p, m)
    want = np.array([arr.bias_force(p[k][None], m[k])[0] for k in range(2)])
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    assert np.linalg.norm(want[0] - arr.bias_force(p[:1], [0.0, 0.0, M])[0]) > 1e-3


def test_the_sensors_see_the_tilted_cylinder_magpylib_computes():
    """An air-core device (no induced field), ideal sensors, no noise, no current: each sensor
    converts the field of the magnet tilted 30 degrees towards azimuth 60 degrees, as
    magpylib's uniformly magnetized cylinder of the design's size and polarization gives it."""
    import magpylib as magpy

    d0 = default_design()
    design = dataclasses.replace(d0, core=None)
    dev = SimulatedDevice(design, noise_t=0.0, sensor_errors="ideal")
    p = np.array([0.01, -0.005, 0.03])
    u = np.array([np.sin(np.pi / 6) * np.cos(np.pi / 3), np.sin(np.pi / 6) * np.sin(np.pi / 3),
                  np.cos(np.pi / 6)])
    np.testing.assert_allclose(
        tilted_direction([0.0, 0.0, 1.0], np.pi / 6, np.pi / 3)[0], u, atol=1e-15)
    dev.prepare(np.tile(p, (3, 1)), np.tile(u, (3, 1)))
    got = dev.sensor_readings_t(1, p, np.zeros(9))
    mg = d0.magnet
    j = 4e-7 * np.pi * mg.moment_a_m2 / (np.pi * mg.radius_m ** 2 * mg.length_m)   # T
    rot = Rotation.align_vectors([u], [[0.0, 0.0, 1.0]])[0]
    cyl = magpy.magnet.Cylinder(polarization=(0.0, 0.0, j),
                                dimension=(2 * mg.radius_m, mg.length_m), position=p,
                                orientation=rot)
    want = cyl.getB(dev.sensor_sim.true_m.reshape(-1, 3))
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9)
    assert np.abs(want).max() > 1e-3
