"""firmware_io.localization: estimators checked against independent fields (magpylib), closed
forms and constructed data."""

from __future__ import annotations

import math

import numpy as np
import pytest

from firmware_io.errors import BadInputError
from firmware_io.localization import (ConstantVelocityKalman, LearnedInverse, Localizer,
                                      SensorModel, calibrate, multipole_field)

import magpylib as magpy  # noqa: E402  (a test dependency: no skip)

MOMENT = np.array([0.0, 0.0, 0.909])


def _positions():
    """The thesis geometry: 3 x 3 coils at 50 mm pitch, sensors 14 mm above the tops (z = 0)
    and 14 mm below the 100 mm coils' bottoms."""
    xy = np.array([[x, y] for y in (0.05, 0.0, -0.05) for x in (-0.05, 0.0, 0.05)])
    up = np.c_[xy, np.full(9, 0.014)]
    lo = np.c_[xy, np.full(9, -0.114)]
    return np.stack([up, lo])


def _model(rng, *, induced=None):
    sp = _positions()
    # a coil field per ampere with the array's mirror symmetry (Br odd about the mid-plane)
    up = rng.normal(scale=5e-3, size=(9, 3, 9))
    lo = up * np.array([-1.0, -1.0, 1.0])[None, :, None]
    return SensorModel(sp, np.stack([up, lo]), MOMENT, "a" * 64, 0.0, induced)


def _dipole_readings(model, p, currents):
    """Readings from magpylib's dipole (independent of the code under test) plus coils."""
    dip = magpy.misc.Dipole(moment=MOMENT, position=p)
    b = dip.getB(model.sensor_positions_m.reshape(-1, 3)).reshape(2, 9, 3)
    return b + np.einsum("asdc,c->asd", model.coil_field_t_per_a, currents)


def test_multipole_dipole_matches_magpylib_and_jacobian_matches_differences():
    rng = np.random.default_rng(0)
    pts = rng.normal(scale=0.03, size=(40, 3))
    c = np.array([0.003, -0.002, 0.04])
    m = rng.normal(size=3)
    ref = magpy.misc.Dipole(moment=m, position=c).getB(pts)
    got = multipole_field(pts, c, m)
    # magpylib uses the CODATA mu0 (5.5e-10 relative from 4 pi 1e-7)
    assert np.allclose(got, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())
    q = 1.5e-5
    _, jac = multipole_field(pts, c, m, q, jacobian=True)
    h = 1e-7
    fd = np.stack([(multipole_field(pts, c + h * e, m, q) - multipole_field(pts, c - h * e, m, q))
                   / (2 * h) for e in np.eye(3)], -1)
    assert np.abs(jac - fd).max() < 1e-6 * np.abs(fd).max()


def test_octupole_term_approaches_the_exact_cylinder():
    """10 x 10 mm cylinder, 20-60 mm away: the l = 3 term (h^2 - 3 a^2 / 4) cuts the dipole's
    worst error (3 %) > 4x, to < 1 % (what is left is the l = 5 term)."""
    cyl = magpy.magnet.Cylinder(polarization=(0, 0, 1.4551), dimension=(0.010, 0.010))
    moment = np.array([0, 0, 1.4551 / (4e-7 * math.pi) * math.pi * 0.005**2 * 0.010])
    rng = np.random.default_rng(1)
    d = rng.normal(size=(200, 3))
    pts = d / np.linalg.norm(d, axis=1)[:, None] * rng.uniform(0.02, 0.06, (200, 1))
    ref = cyl.getB(pts)
    e1 = np.linalg.norm(multipole_field(pts, np.zeros(3), moment) - ref, axis=1)
    e3 = np.linalg.norm(multipole_field(pts, np.zeros(3), moment, 0.005**2 * 0.25) - ref, axis=1)
    nrm = np.linalg.norm(ref, axis=1)
    assert np.max(e3 / nrm) < 0.25 * np.max(e1 / nrm)
    assert np.max(e3 / nrm) < 1e-2


@pytest.mark.parametrize("method", ["dipole", "model"])
def test_fit_recovers_a_noiseless_dipole(method):
    rng = np.random.default_rng(2)
    model = _model(rng)
    loc = Localizer(model, method, cores=False)
    for _ in range(8):
        p = np.r_[rng.uniform(-0.025, 0.025, 2), rng.uniform(0.02, 0.07)]
        i = rng.uniform(-1, 1, 9)
        top, bot = _dipole_readings(model, p, i)
        loc.reset()
        est = loc.locate(top, bot, i)
        assert est.ok, est.reason
        assert np.linalg.norm(est.position_m - p) < 1e-6
        # warm start from the last estimate, a nearby frame
        p2 = p + rng.normal(scale=1e-3, size=3)
        top, bot = _dipole_readings(model, p2, i)
        est = loc.locate(top, bot, i)
        assert est.ok and np.linalg.norm(est.position_m - p2) < 1e-6


@pytest.mark.parametrize("method", ["dipole", "model"])
def test_nan_sensor_is_excluded(method):
    rng = np.random.default_rng(3)
    model = _model(rng)
    loc = Localizer(model, method, cores=False)
    p = np.array([0.004, -0.006, 0.03])
    i = rng.uniform(-1, 1, 9)
    top, bot = _dipole_readings(model, p, i)
    top[4] = [np.nan, 0.0, 0.0]      # the strongest sensor saturated
    bot[0] = np.nan                  # a dead one in the lower array
    top[7] = 1e3 * 0 + 0.5 * np.nan  # NaN everywhere in one more
    est = loc.locate(top, bot, i)
    assert est.ok, est.reason
    assert np.linalg.norm(est.position_m - p) < 1e-6
    assert est.n_used == (6 if method == "dipole" else 15)


def test_too_few_sensors_and_garbage_give_ok_false():
    rng = np.random.default_rng(4)
    model = _model(rng)
    loc = Localizer(model, "model", cores=False)
    top = np.full((9, 3), np.nan)
    bot = np.full((9, 3), np.nan)
    top[:2] = 1e-3
    est = loc.locate(top, bot, np.zeros(9))
    assert not est.ok and "usable" in est.reason
    assert np.all(np.isfinite(est.position_m))
    # a field no dipole in the box can make: +50 mT along x at every sensor
    est = loc.locate(np.tile([0.05, 0, 0], (9, 1)), np.tile([0.05, 0, 0], (9, 1)), np.zeros(9))
    assert not est.ok
    assert np.all(np.isfinite(est.position_m)) and math.isfinite(est.residual)


def test_model_based_cancellation_uses_the_commanded_currents():
    """Large coil fields, a wrong current in the model -> detected (residual), right -> exact."""
    rng = np.random.default_rng(5)
    model = _model(rng)
    loc = Localizer(model, "model", cores=False, relative_error=0.0)
    p = np.array([-0.01, 0.012, 0.05])
    i = rng.uniform(-5, 5, 9)
    top, bot = _dipole_readings(model, p, i)
    assert np.linalg.norm(loc.locate(top, bot, i).position_m - p) < 1e-6
    loc.reset()
    wrong = i.copy()
    wrong[3] += 1.0
    assert not loc.locate(top, bot, wrong).ok


def test_induced_term_is_fitted():
    """A position-dependent extra field known to the model (the cores' stand-in) is fitted."""
    rng = np.random.default_rng(6)

    def induced(p):
        # a smooth field falling with height, as the magnet-magnetized cores make
        return np.broadcast_to(np.array([0.0, 0.0, 4e-3]) * (0.03 / p[2]) ** 3, (2, 9, 3)).copy()

    model = _model(rng, induced=induced)
    p = np.array([0.005, 0.002, 0.035])
    top, bot = _dipole_readings(model, p, np.zeros(9)) + induced(p)
    est = Localizer(model, "model").locate(top, bot, np.zeros(9))
    assert est.ok and np.linalg.norm(est.position_m - p) < 1e-5
    naive = Localizer(model, "model", cores=False, residual_limit=1e9).locate(top, bot, np.zeros(9))
    assert np.linalg.norm(naive.position_m - p) > 1e-4


def _inverse(rng):
    ws = ((rng.normal(size=(4, 8)), rng.normal(size=8)), (rng.normal(size=(8, 3)) * 3,
                                                            rng.normal(size=3)))
    return LearnedInverse(ws, np.zeros(4), np.ones(4), np.array([-0.025, -0.025, 0.006]),
                          np.array([0.025, 0.025, 0.056]), (-4.0, -1.0), "a" * 64)


def test_learned_inverse_never_leaves_its_box_unflagged():
    rng = np.random.default_rng(7)
    inv = _inverse(rng)
    model = _model(rng)
    loc = Localizer(model, "learned", learned=inv)
    n_flagged = 0
    for _ in range(300):
        b = rng.normal(size=3) * 10 ** rng.uniform(-5, -0.5)
        rel, inside = inv(b)
        raw = inv.raw(b[None])[0]
        out_of_box = np.any(raw < inv.box_lower_m) or np.any(raw > inv.box_upper_m)
        assert np.all(rel >= inv.box_lower_m) and np.all(rel <= inv.box_upper_m)
        if out_of_box:
            assert not inside
            n_flagged += 1
        top = np.zeros((9, 3))
        top[int(rng.integers(9))] = b
        est = loc.locate(top, np.zeros((9, 3)))
        k = int(np.argmax(np.linalg.norm(top, axis=1)))
        if out_of_box or not inside:
            assert not est.ok
        assert np.all(est.position_m - model.sensor_positions_m[0, k] >= inv.box_lower_m - 1e-12)
    assert n_flagged > 10  # the random network does leave its box: the check is exercised


def test_learned_weights_round_trip_and_design_check(tmp_path):
    rng = np.random.default_rng(8)
    inv = _inverse(rng)
    inv.save(tmp_path / "w.npz")
    back = LearnedInverse.load(tmp_path / "w.npz")
    b = rng.normal(size=(5, 3)) * 1e-3
    assert np.array_equal(back.raw(b), inv.raw(b))
    other = _model(rng)
    other.design_sha256 = "b" * 64
    with pytest.raises(BadInputError, match="weights"):
        Localizer(other, "learned", learned=back)
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(BadInputError, match="weights"):
        LearnedInverse.load(tmp_path / "junk.npz")


def test_bad_inputs_name_the_parameter(tmp_path):
    rng = np.random.default_rng(9)
    model = _model(rng)
    loc = Localizer(model, "model", cores=False)
    ok = np.zeros((9, 3))
    with pytest.raises(BadInputError, match="top.*shape"):
        loc.locate(np.zeros((8, 3)), ok, np.zeros(9))
    with pytest.raises(BadInputError, match="bottom.*Inf"):
        bad = ok.copy()
        bad[2, 1] = np.inf
        loc.locate(ok, bad, np.zeros(9))
    with pytest.raises(BadInputError, match="millitesla"):
        loc.locate(ok + 50.0, ok, np.zeros(9))
    with pytest.raises(BadInputError, match="currents"):
        loc.locate(ok, ok, np.zeros(8))
    with pytest.raises(BadInputError, match="currents"):
        loc.locate(ok, ok, np.r_[np.zeros(8), np.nan])
    with pytest.raises(BadInputError, match="currents"):
        loc.locate(ok, ok)
    with pytest.raises(BadInputError, match="method"):
        Localizer(model, "neural")
    with pytest.raises(BadInputError, match="sensor_positions_m"):
        SensorModel(np.zeros((9, 3)), model.coil_field_t_per_a, MOMENT, "x")
    with pytest.raises(BadInputError, match="map file"):
        (tmp_path / "m.npz").write_bytes(b"junk")
        Localizer.from_map(tmp_path / "m.npz")


def test_kalman_tracks_constant_velocity_exactly():
    kf = ConstantVelocityKalman(accel_rms_m_s2=1e-6, meas_rms_m=1e-4)
    v = np.array([0.02, -0.01, 0.005])
    p0 = np.array([0.0, 0.01, 0.04])
    for k in range(300):
        t = k * 0.01
        pos, vel = kf.update(p0 + v * t, t)
    assert np.allclose(vel, v, atol=1e-5)
    assert np.allclose(kf.predict(3.5), p0 + v * 3.5, atol=1e-5)
    # a rejected estimate leaves the track alone
    pos, _ = kf.update(np.array([1.0, 1.0, 1.0]), 3.0, ok=False)
    assert np.allclose(pos, p0 + v * 3.0, atol=1e-5)


def test_calibration_recovers_gain_rotation_offset():
    rng = np.random.default_rng(10)
    model = _model(rng)
    g_true = np.eye(3) + rng.normal(scale=0.02, size=(2, 9, 3, 3))
    o_true = rng.normal(scale=1e-4, size=(2, 9, 3))
    i = rng.uniform(-2, 2, (40, 9))
    b = np.einsum("asdc,kc->kasd", model.coil_field_t_per_a, i)
    meas = np.einsum("asij,kasj->kasi", g_true, b) + o_true
    gi, off = calibrate(meas[:, 0], meas[:, 1], i, model)
    assert np.allclose(gi, np.linalg.inv(g_true), atol=1e-9)
    assert np.allclose(off, o_true, atol=1e-12)


def test_localization_imports_numpy_only():
    import subprocess
    import sys
    from pathlib import Path

    code = ("import sys, firmware_io.localization; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('designkit', 'smbus2', 'scipy')]; "
            "assert not bad, bad")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=str(Path(__file__).parents[1]))
