"""designkit.sim.readings: simulated Hall arrays, checked against magpylib, the TLV493D datasheet and
an independent 3-D solve."""

from __future__ import annotations

import math

import numpy as np
import pytest

from designkit.errors import BadInputError
from designkit.sim.readings import (TLV_LSB_T, SensorErrors, case_currents, magnet_field,
                                    random_positions, sensor_positions_m, tlv_readout)

import magpylib as magpy  # noqa: E402  (a test dependency: no skip)


def test_magnet_field_matches_magpylib_for_any_axis():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    for _ in range(5):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        c = rng.uniform(-0.02, 0.02, 3) + [0, 0, 0.04]
        m = 0.909 * axis
        pts = c + rng.normal(scale=0.03, size=(50, 3))
        pts = pts[np.linalg.norm(pts - c, axis=1) > 0.009]
        rot = Rotation.align_vectors([axis], [[0, 0, 1]])[0]
        j = 0.909 / (math.pi * 0.005**2 * 0.010) * magpy.mu_0
        ref = magpy.magnet.Cylinder(polarization=(0, 0, j), dimension=(0.010, 0.010),
                                    position=c, orientation=rot).getB(pts)
        got = magnet_field(pts, c, m, 0.005, 0.010)
        assert np.abs(got - ref).max() < 1e-8 * np.abs(ref).max() + 1e-15


def test_sensor_positions_follow_the_design_rule():
    from designkit.design import default_design

    d = default_design()
    sp = sensor_positions_m(d)
    assert sp.shape == (2, 9, 3)
    assert np.allclose(sp[0, :, 2], 0.014) and np.allclose(sp[1, :, 2], -0.114)
    assert np.allclose(sp[0, :, :2], np.array(d.coil_centres_m())[:, :2])


def test_readout_quantizes_saturates_and_flags():
    n = 9
    e = SensorErrors.ideal(n)
    rng = np.random.default_rng(1)
    b = rng.uniform(-0.1, 0.1, (20, 2, n, 3))
    r = tlv_readout(b, e, 0.0, rng)
    # noise-free: the reading is the nearest multiple of 0.098 mT
    assert np.allclose(r.codes * TLV_LSB_T, np.rint(b / TLV_LSB_T) * TLV_LSB_T)
    assert np.all(np.abs(r.top_t - b[:, 0]) <= TLV_LSB_T / 2 + 1e-15)
    # beyond +-130 mT: NaN and flagged; beyond the 12-bit range (+-200.7 mT) the codes clip
    b2 = np.zeros((1, 2, n, 3))
    b2[0, 0, 3, 2] = 0.150
    b2[0, 1, 5, 0] = -0.500
    r = tlv_readout(b2, e, 0.0, rng)
    assert r.saturated[0, 0, 3] and r.saturated[0, 1, 5] and r.saturated.sum() == 2
    assert np.all(np.isnan(r.top_t[0, 3])) and np.all(np.isnan(r.bottom_t[0, 5]))
    assert r.codes[0, 1, 5, 0] == -2048 and r.codes[0, 0, 3, 2] == round(0.150 / TLV_LSB_T)
    assert np.all(np.isfinite(r.top_t[0, :3]))


def test_readout_noise_matches_the_datasheet_figure():
    e = SensorErrors.ideal(9)
    rng = np.random.default_rng(2)
    r = tlv_readout(np.zeros((400, 2, 9, 3)), e, 0.1e-3, rng)
    x = np.concatenate([r.top_t.ravel(), r.bottom_t.ravel()])
    # 21600 samples: the rms (with quantization, +0.028 mT in quadrature) within 3 %
    assert abs(np.sqrt(np.mean(x**2)) - math.hypot(0.1e-3, TLV_LSB_T / math.sqrt(12))) < 3e-6


def test_sensor_errors_have_the_stated_size():
    rng = np.random.default_rng(3)
    e = SensorErrors.random(9, rng, mount_position_m=0.5e-3, mount_angle_deg=1.0,
                            dead=[(1, 4)])
    assert np.allclose(np.linalg.norm(e.position_errors_m, axis=-1), 0.5e-3)
    angles = np.degrees(np.arccos((np.trace(e.rotations, axis1=-2, axis2=-1) - 1) / 2))
    assert np.allclose(angles, 1.0)
    assert np.allclose(np.einsum("asji,asjk->asik", e.rotations, e.rotations), np.eye(3))
    assert e.dead[1, 4] and e.dead.sum() == 1
    r = tlv_readout(np.full((1, 2, 9, 3), 1e-3), e, 0.0, rng)
    assert np.all(np.isnan(r.bottom_t[0, 4])) and np.all(np.isfinite(r.top_t))
    with pytest.raises(BadInputError, match="dead"):
        SensorErrors.random(9, rng, dead=[(2, 0)])


def test_field_cases_are_the_thesis_cases():
    t = np.linspace(0, 20, 4001)
    assert np.all(case_currents("off", t, 9) == 0)
    assert np.all(case_currents("static", t, 9) == 0.65)
    s = case_currents("sinusoidal", t, 9)
    assert np.allclose(np.abs(s).max(axis=0), 0.65, rtol=1e-3)
    tv = case_currents("time-varying", t, 9, seed=1)
    assert np.abs(tv).max() <= 1.0 + 1e-12 and np.abs(tv).max() > 0.7
    rd = case_currents("rendering", t, 9, seed=1, max_current_a=6.0)
    assert np.abs(rd).max() <= 6.0 + 1e-12 and np.abs(rd).max() > 4.0
    with pytest.raises(BadInputError, match="case"):
        case_currents("pulsed", t, 9)


def test_random_positions_stay_in_the_box():
    p = random_positions(500, np.random.default_rng(4))
    assert np.all(np.abs(p[:, :2]) <= 0.025) and np.all((p[:, 2] >= 0.02) & (p[:, 2] <= 0.07))


@pytest.mark.slow
def test_induced_core_field_matches_the_independent_3d_solve():
    """Issue 14: an independent 3-D solve of the default array (linear mu_r
    1000) gives 4.0 mT at the upper and 0.74 mT at the lower centre sensor for the magnet 30 mm
    above the centre coil, where the magnet's own field at the lower sensor is 0.06 mT."""
    from designkit.sim.readings import SensorSimulator

    # the figures are for the moment along +z (the default design points it down)
    sim = SensorSimulator(errors="ideal", noise_t=0.0, moment_direction=(0.0, 0.0, 1.0))
    p = np.array([[0.0, 0.0, 0.030]])
    ind = sim.induced_part(p)[0]
    assert ind[0, 4, 2] == pytest.approx(4.0e-3, rel=0.05)
    assert ind[1, 4, 2] == pytest.approx(0.74e-3, rel=0.1)
    assert sim.magnet_part(p)[0, 1, 4, 2] == pytest.approx(0.06e-3, rel=0.1)
    # the one-core-at-a-time rod model (used where the coupled solve is too slow) is within 40 %
    rod = SensorSimulator(errors="ideal", noise_t=0.0, induced="rod",
                          moment_direction=(0.0, 0.0, 1.0)).induced_part(p)[0]
    assert rod[0, 4, 2] == pytest.approx(4.0e-3, rel=0.1)
    assert rod[1, 4, 2] == pytest.approx(0.74e-3, rel=0.4)
