"""The runner's sensor side and control-step pieces, each against an independent reference: a
textbook 6-state Kalman filter, the force on a dipole from its field-gradient tensor, a
brute-force search, direct evaluation of the bounded field, the simulator's true sensor errors."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from firmware_io.errors import BadInputError
from firmware_io.localization import Estimate
from firmware_io.mapfile.drive import DriveRecord
from firmware_io.runner.pipeline import Acquisition
from firmware_io.runner import (CoilSkipBound, CurrentHistory, Fix, PoseTracker, RunnerConfig,
                                SensorFrame, SensorLayout, SensorPipeline, force_law_rows)


# ---------------------------------------------------------------------------------------------
# the tracker on the control thread vs a textbook Kalman filter


def _textbook(zs, ts, q, r, t_query):
    """Full 6-state constant-velocity filter (x, y, z, vx, vy, vz) with dense matrices."""
    x = np.r_[zs[0], np.zeros(3)]
    p = np.diag([r] * 3 + [1.0] * 3)
    t = ts[0]
    h = np.c_[np.eye(3), np.zeros((3, 3))]
    for z, tk in zip(zs[1:], ts[1:]):
        dt = tk - t
        f = np.eye(6)
        f[:3, 3:] = dt * np.eye(3)
        qm = q * np.block([[dt ** 4 / 4 * np.eye(3), dt ** 3 / 2 * np.eye(3)],
                           [dt ** 3 / 2 * np.eye(3), dt ** 2 * np.eye(3)]])
        x = f @ x
        p = f @ p @ f.T + qm
        s = h @ p @ h.T + r * np.eye(3)
        k = p @ h.T @ np.linalg.inv(s)
        x = x + k @ (z - h @ x)
        p = (np.eye(6) - k @ h) @ p
        t = tk
    return x[:3] + (t_query - t) * x[3:], x[3:]


def test_tracker_matches_a_textbook_kalman_filter():
    rng = np.random.default_rng(3)
    for _ in range(20):
        a, m = rng.uniform(0.1, 20), rng.uniform(1e-4, 5e-3)
        n = rng.integers(2, 40)
        ts = np.cumsum(rng.uniform(1e-3, 2e-2, n))
        zs = np.cumsum(rng.normal(0, 1e-3, (n, 3)), axis=0) + [0.0, 0.0, 0.04]
        kf = PoseTracker(a, m)
        for z, t in zip(zs, ts):
            kf.update(z, t, True)
        tq = ts[-1] + rng.uniform(0, 0.02)
        ref_p, ref_v = _textbook(zs, ts, a * a, m * m, tq)
        assert np.allclose(kf.predict(tq), ref_p, rtol=0, atol=1e-12)
        assert np.allclose(kf.x[1], ref_v, rtol=1e-9, atol=1e-12)


def test_tracker_skips_flagged_estimates_and_refuses_bad_tuning():
    kf = PoseTracker()
    kf.update([0.0, 0.0, 0.03], 0.0)
    kf.update([0.0, 0.0, 0.03], 0.01)
    before = kf.predict(0.02).copy()
    kf.update([0.05, 0.05, 0.05], 0.02, ok=False)     # a lost fit: prediction only
    assert np.allclose(kf.predict(0.02), before)
    with pytest.raises(BadInputError, match="meas_rms_m"):
        PoseTracker(2.0, -1.0)


# ---------------------------------------------------------------------------------------------
# what the force law needs of A(p)


def _gradient_rows(g):
    """A's rows 3..7 (dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz) of a gradient tensor."""
    return np.array([g[0, 0], g[0, 1], g[0, 2], g[1, 1], g[1, 2]])


def test_force_law_rows_give_the_force_of_the_gradient_tensor():
    rng = np.random.default_rng(5)
    for k in range(50):
        m = rng.normal(size=3) if k % 2 else np.array([0.0, 0.0, rng.normal()])
        s = rng.normal(size=(3, 3))
        g = s + s.T
        g -= np.trace(g) / 3 * np.eye(3)           # curl- and divergence-free field gradient
        a = np.zeros(8)
        a[:3] = rng.normal(size=3)                  # B itself: no force on a dipole
        a[3:] = _gradient_rows(g)
        f = g @ m                                   # F = grad(m . B) = G m (G symmetric)
        rows, mat = force_law_rows(m, "xyz")
        assert np.allclose(mat @ a[rows], f, rtol=1e-12, atol=1e-12)
        rz, mz = force_law_rows(m, "z")
        assert np.allclose(mz @ a[rz], f[2:], rtol=1e-12, atol=1e-12)
        if k % 2 == 0:                             # a z-dipole: 4 rows for 3-D, 2 for Fz
            assert rows.tolist() == [3, 5, 6, 7] and rz.tolist() == [3, 6]


class _BumpMap:
    """A(p) of smooth bumps around each coil decaying like a coil's gradient (r^-5), a stand-in
    field whose value is known anywhere."""

    def __init__(self, centres, width_m=0.02):
        self.c = np.asarray(centres, float)
        self.w = width_m
        self.bounds = (np.array([-0.075, -0.075, 0.01]), np.array([0.075, 0.075, 0.08]))

    def actuation(self, p):
        p = np.atleast_2d(p)
        d2 = ((p[:, None, :] - self.c[None]) ** 2).sum(-1) / self.w ** 2     # (N, n)
        e = (1.0 + d2) ** -2.5
        a = np.zeros((len(p), 8, len(self.c)))
        a[:, 3] = 0.1 * e
        a[:, 6] = -0.05 * e * (1 + 0.3 * np.sin(40 * p[:, :1]))
        a[:, 5] = 0.02 * e
        a[:, 7] = 0.03 * e
        return a


def _unit_vectors(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_coil_skip_bound_holds_at_random_points_for_any_moment():
    """|F_k| = |G_k m| <= bound_k |m| for random points and random moment directions (the
    force from the law's rows, an independent path), and the bound is tight to a factor ~3
    for the worst direction (the largest eigenvalue of G_k) where the force matters: the
    Frobenius norm and the cell margin cost a factor ~2 (median)."""
    xs = np.array([-0.03, 0.0, 0.03])
    centres = np.array([[x, y, 0.0] for y in xs for x in xs])
    fmap = _BumpMap(centres)
    bound = CoilSkipBound(fmap, spacing_m=5e-3)
    rng = np.random.default_rng(7)
    lo, hi = fmap.bounds
    pts = rng.uniform(lo, hi, (3000, 3))
    moments = 0.909 * _unit_vectors(rng, 3000)
    a = fmap.actuation(pts)
    exact = np.array([np.linalg.norm(mat @ a[k, rows], axis=0) for k, (rows, mat) in
                      enumerate(force_law_rows(m, "xyz") for m in moments)])
    b = np.array([bound.at(p) for p in pts]) * 0.909
    assert np.all(exact <= b)
    # not vacuous: the worst direction's force (largest |eigenvalue| of G_k) is within ~3x
    g = np.zeros((len(pts), 9, 3, 3))
    g[..., 0, 0], g[..., 0, 1], g[..., 0, 2] = a[:, 3], a[:, 4], a[:, 5]
    g[..., 1, 1], g[..., 1, 2] = a[:, 6], a[:, 7]
    g[..., 2, 2] = -a[:, 3] - a[:, 6]
    g = np.triu(g) + np.swapaxes(np.triu(g, 1), -1, -2)
    worst = 0.909 * np.abs(np.linalg.eigvalsh(g)).max(axis=-1)
    big = worst > 1e-2 * worst.max(axis=1, keepdims=True)
    assert np.all(worst <= b + 1e-15) and np.median(b[big] / worst[big]) < 3
    keep = bound.keep(np.array([-0.06, -0.06, 0.012]), np.full(9, 1.0), 1e-3, 0.909)
    assert 0 < len(keep) < 9 and 0 in keep


def test_runner_config_refuses_a_negative_skip_force():
    with pytest.raises(BadInputError, match="skip_force_n"):
        RunnerConfig(DriveRecord((2.0,) * 9, (0.03,) * 9, 30.0, 4.8, 20.0), skip_force_n=-1.0)


# ---------------------------------------------------------------------------------------------
# the sensor side


def test_current_history_returns_the_newest_step_at_or_before_the_frame():
    rng = np.random.default_rng(2)
    h = CurrentHistory(3, 16)
    kept = []
    for k in range(40):
        i = rng.normal(size=3)
        h.push(k * 1e-3, i)
        kept = (kept + [(k * 1e-3, i)])[-16:]
    for t in rng.uniform(0.024, 0.045, 50):
        want = max((e for e in kept if e[0] <= t + 1e-12), key=lambda e: e[0])[1]
        assert np.array_equal(h.at(t), want)
    assert np.array_equal(h.at(0.0), kept[0][1])           # older than kept: the oldest


class _RecordingEstimator:
    def __init__(self):
        self.calls = []

    def reset(self):
        pass

    def estimate(self, readings_t, currents_a=None, *, usable=None, seed=None, time_s=None):
        self.calls.append((readings_t.copy(), np.array(currents_a)))
        return Estimate(np.array([0.0, 0.0, 0.03]), np.array([0.0, 0.0, 0.6]), True)


def _layout(n=18, n_coils=9):
    return SensorLayout(np.zeros((n, 3)) + [0.0, 0.0, -0.2], np.zeros((n, 3, n_coils)))


def test_pipeline_excludes_unhealthy_sensors_and_fits_with_the_frame_time_currents():
    loc = _RecordingEstimator()
    h = CurrentHistory(9, 32)
    for k in range(20):
        h.push(k * 1e-3, np.full(9, float(k)))
    pipe = SensorPipeline(loc, _layout(), h.at, np.array([0.0, 0.0, 0.6]))
    status = ["ok"] * 18
    status[4] = "nack"
    frame = SensorFrame(np.full((18, 3), 1e-3), tuple(status), 0.0125)
    fix = pipe.process(frame)
    assert isinstance(fix, Fix) and fix.ok and fix.frame_t_s == 0.0125
    readings, cur = loc.calls[0]
    assert np.all(np.isnan(readings[4])) and np.isfinite(np.delete(readings, 4, 0)).all()
    assert np.array_equal(cur, np.full(9, 12.0))             # the step started at 12 ms
    assert fix.problems[0][0] == "sensor_dead" and fix.excluded[4]
    # still excluded next frame, but no new fault
    assert pipe.process(frame).problems == ()


class _FakeArrays:
    def __init__(self):
        self.sensors = [None] * 18
        self.n = 0

    def read(self):
        from firmware_io.hw.sensors import ArraysReading

        self.n += 1
        time.sleep(2e-3)
        return ArraysReading(np.zeros((18, 3)), ("ok",) * 18, np.ones(18, dtype=bool))


def test_threaded_source_runs_the_pipeline_and_stamps_the_previous_pass():
    from firmware_io.run import ThreadedSensorSource

    clock_lock = threading.Lock()
    ticks = {"t": 0.0}

    def clock():
        with clock_lock:
            ticks["t"] += 1.0
            return ticks["t"]

    loc = _RecordingEstimator()
    src = ThreadedSensorSource(_FakeArrays(), clock=clock)
    pipe = SensorPipeline(loc, _layout(), lambda t: np.zeros(9), np.array([0.0, 0.0, 0.6]))
    src.attach(pipe)
    src.start()
    try:
        deadline = time.monotonic() + 5.0
        got = None
        while got is None and time.monotonic() < deadline:
            got = src(0.0)
            time.sleep(1e-3)
    finally:
        src.stop()
    assert isinstance(got, Fix) and got.ok
    # each pass reads the clock once at its start: a frame holds the previous pass's field
    assert got.frame_t_s < ticks["t"] and float(got.frame_t_s).is_integer()
    again = src(0.0)                       # handed over once: None or a newer result
    assert again is None or (isinstance(again, Fix) and again.frame_t_s > got.frame_t_s)


class _ScriptedEstimator:
    """Names sensor 3 in the first frame (a pass whose reads straddle a move), then finds the
    magnet consistent with every sensor (fault-free PL 3.5 mm) but never trusts it alone (no
    prior); solved without sensor 3 its fault-free PL is 15 mm: what the runner_stale study
    showed after the finger's return."""

    class settings:
        alert_limit_m = 0.010
        orientation_alert_limit_rad = 0.2

    def __init__(self):
        self.calls = 0

    def reset(self):
        pass

    def magnet_free(self, readings, currents):
        return False

    def estimate(self, readings, currents, usable=None, seed=None, time_s=None):
        self.calls += 1
        p = np.array([-0.020, 0.0, 0.030])
        without_3 = usable is not None and not usable[3]
        named = (3,) if self.calls == 1 else ()
        return Estimate(p, np.array([0.0, 0.0, 0.6]), False, "protection level above the limit",
                        protection_level_m=0.04, excluded_sensors=named, consistent=True,
                        fault_free_protection_level_m=0.015 if without_3 or named else 0.0035)


def test_a_transient_naming_clears_after_agreeing_frames_and_the_finger_is_acquired():
    est = _ScriptedEstimator()
    pipe = SensorPipeline(est, _layout(), lambda t: np.zeros(9), np.array([0.0, 0.0, 0.6]),
                          acquisition=Acquisition(clear_passes=5))
    fixes = [pipe.process(SensorFrame(np.full((18, 3), 1e-3), ("ok",) * 18, 0.01 + 0.003 * k))
             for k in range(8)]
    assert not fixes[0].ok and fixes[0].fault_excluded == (3,)
    # frames 1-4 agree with sensor 3 but it stays suspect: each is solved without it and not
    # acquired (fault-free PL 15 mm > 10 mm); the 5th agreeing frame ends the suspicion
    assert [f.ok for f in fixes[1:5]] == [False] * 4
    assert all(f.ok and f.acquired for f in fixes[5:])
    assert not pipe.suspect.any()
    # a sensor named again restarts its count: never cleared while it keeps being named
    est2 = _ScriptedEstimator()
    est2.estimate = lambda r, c, usable=None, seed=None, time_s=None: Estimate(
        np.array([-0.02, 0.0, 0.03]), np.array([0.0, 0.0, 0.6]), False, "",
        protection_level_m=0.04, excluded_sensors=(3,) if (usable is None) else (),
        consistent=True, fault_free_protection_level_m=0.0035)
    pipe2 = SensorPipeline(est2, _layout(), lambda t: np.zeros(9), np.array([0.0, 0.0, 0.6]))
    for k in range(12):
        pipe2.process(SensorFrame(np.full((18, 3), 1e-3), ("ok",) * 18, 0.01 + 0.003 * k))
    assert pipe2.suspect[3]


def test_acquisition_refuses_clear_passes_out_of_range():
    for bad in (0, -1, 2.5, 10_000):
        with pytest.raises(BadInputError, match="clear_passes"):
            Acquisition(clear_passes=bad)


def test_a_gated_jump_is_confirmed_by_the_next_fix_solved_cold():
    """A fix 40 mm from the track fails the gate; the next one, solved cold (its frame rejected
    the track's prior) and consistent with it, restarts the tracker there. A warm fix (the
    prior used) does not confirm: it could repeat a wrong basin."""
    from firmware_io.runner import InnovationGate

    def fix(x, t, prior_used):
        return Fix(np.array([x, 0.0, 0.03]), np.array([0.0, 0.0, 0.6]), True, t, (),
                   np.zeros(18, bool), 0.0, covariance_m2=np.eye(3) * 1e-8,
                   prior_used=prior_used)

    for second_prior_used, restarts in ((False, True), (True, False)):
        kf = PoseTracker()
        for k in range(10):
            kf.update(np.array([-0.02, 0.0, 0.03]), 0.005 * k, True, np.array([0.0, 0.0, 0.6]))
        gate = InnovationGate(1e-4)
        why, restart = gate.check(fix(0.02, 0.05, False), kf)
        assert why and not restart
        why, restart = gate.check(fix(0.0201, 0.055, second_prior_used), kf)
        assert restart is restarts and (why == "") is restarts
