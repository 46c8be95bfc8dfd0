"""The runner's innovation gate on the simulated device: a fix that jumps away from the
tracker's prediction is gated out (state 'gated', every coil command zero in run.csv), the
sensor side re-acquires, a confirmed jump re-starts the tracker, a dead sensor still fails
safe, and no running step renders at a gated-out position."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from designkit.model.array import CoilArray
from designkit.design import default_design
from designkit.sim import (FaultSchedule, SimulatedDevice, simulate, slide_trajectory,
                           time_to_safe)
from designkit.sim.faults import FAULT_CLEARS_S
from designkit.sim.report import write_run_csv
from firmware_io.localization import Estimate
from firmware_io.runner import PoseTracker, Runner, RunnerConfig, RunnerIO

from _runner_fakes import PlaneScene, clipped_lstsq, device_map, md10c_drive

BOX = (np.array([-0.075, -0.075, 0.010]), np.array([0.075, 0.075, 0.080]))
JUMP = np.array([0.030, 0.0, 0.0])


MOMENT = np.array([0.0, 0.0, 0.909])


def _estimate(p, ok, sigma_m, pl_m):
    """A pose estimate at p with covariance sigma^2 I and protection level ``pl_m``."""
    return Estimate(np.asarray(p, float), MOMENT.copy(), ok, "" if ok else "no sensor",
                    sigma_m ** 2 * np.eye(3), pl_m)


class JumpingLocalizer:
    """The true position with a 0.3 mm covariance, except on the frames listed in ``spikes``
    (one frame 30 mm off) and from frame ``moved`` on (30 mm off for good: the finger 'really'
    moved, as after a lost stretch). Counts its resets (re-acquisition requests)."""

    integrity_risk = 1e-4
    model_bias_m = 0.0

    def __init__(self, truth, spikes, moved):
        self.truth, self.spikes, self.moved = truth, set(spikes), moved
        self.calls, self.resets = 0, 0

    def reset(self):
        self.resets += 1

    def magnet_free(self, readings_t, currents_a=None):
        return False

    def estimate(self, readings_t, currents_a=None, *, usable=None, seed=None, time_s=None):
        k = self.calls
        self.calls += 1
        p = np.asarray(self.truth(), float)
        if k in self.spikes or k >= self.moved:
            p = p + JUMP
        return _estimate(p, bool(np.isfinite(readings_t).any()), 0.3e-3, 1e-3)


@pytest.fixture(scope="module")
def device():
    design = default_design()
    array = CoilArray.from_design(design)
    return design, array, array.actuation_matrix(np.array([0.0, 0.0, 0.04]))


def _jumping_run(device, seed, duration, faults, spikes, moved, **cfg):
    """The closed loop on the simulated device with a :class:`JumpingLocalizer`, the
    constant-velocity tracker and a slide at 50 mm: (result, runner, localizer)."""
    design, array, a = device
    dev = SimulatedDevice(design, array, seed=seed, drive=md10c_drive(design))
    traj = slide_trajectory(lambda x, y: np.full_like(x, 0.05), duration_s=duration,
                            samples=401)
    holder = {}

    def factory(source, clock, hook):
        conf = RunnerConfig(dev.drive, **cfg)
        loc = JumpingLocalizer(lambda: source.frame_truth_m, spikes=spikes, moved=moved)
        r = Runner(device_map(a, BOX, dev), PlaneScene(0.05, 6.0), loc,
                   RunnerIO(dev.coils, source, lambda line: None, clock), conf,
                   tracker=PoseTracker(), allocate=hook(clipped_lstsq))
        r.start()
        holder["runner"], holder["loc"] = r, loc
        return r

    res = simulate(dev, factory, traj, duration_s=duration,
                   faults=FaultSchedule.parse(faults, duration), progress=False)
    return res, holder["runner"], holder["loc"]


def test_gated_fixes_render_no_force_and_are_reacquired(device, tmp_path):
    res, runner, loc = _jumping_run(device, 4, 0.7, "sensor_dead@0.4", (30, 31, 60), 95,
                                    resume_after_s=0.02)
    write_run_csv(tmp_path / "run.csv", res.columns)
    with (tmp_path / "run.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    state = np.array([r["state"] for r in rows])
    cmd = np.array([[float(r[k]) for k in r if k.startswith("cmd")] for r in rows])
    assert loc.calls > 105, "too few frames for the scripted jumps"
    gated = state == "gated"
    assert gated.sum() >= 2
    assert np.all(cmd[gated] == 0.0)
    assert np.all(cmd[state == "sensor_dead"] == 0.0) and (state == "sensor_dead").any()
    assert np.all(cmd[state == "lost"] == 0.0)
    # each gated fix asked the sensor side to re-acquire (the next fit starts cold)
    assert loc.resets >= 2
    assert sum(name == "gated" for _, name, _ in runner.fault_log) >= 2
    # no running step renders at a gated-out spike (30 mm off): the rendered position follows
    # the truth within what the tracker's extrapolation over a fix's age allows this fast slide
    running = state == "running"
    est = np.array([[float(r[k]) for k in ("xe_m", "ye_m", "ze_m")] for r in rows])
    true = np.array([[float(r[k]) for k in ("x_m", "y_m", "z_m")] for r in rows])
    t = np.array([float(r["t_s"]) for r in rows])
    moved_t = t[np.flatnonzero(gated)[-1]]
    before = running & (t < moved_t)
    assert np.abs(est[before, 0] - true[before, 0]).max() < 0.015
    # the lasting jump is confirmed by the next (cold) fix: the loop runs again, there
    after = running & (t > moved_t)
    assert after.sum() > 50
    assert np.abs(est[after, 0] - (true[after, 0] + JUMP[0])).max() < 0.015


def test_bad_frames_reach_the_loop_as_not_ok_fixes_with_a_reason():
    """The sensor side never raises on a bad frame: wrong shape, all sensors saturated -> a
    not-ok Fix with a 'lost' problem naming the cause; an Inf reading is a saturated sensor,
    excluded (the others still fix the position); then a good frame is fitted."""
    import dataclasses

    import magpylib as magpy

    from firmware_io.localization import POSITION_ONLY, ModelEstimator, SensorModel
    from firmware_io.runner import SensorFrame, SensorLayout, SensorPipeline

    rng = np.random.default_rng(0)
    xy = np.array([[x, y] for y in (0.05, 0.0, -0.05) for x in (-0.05, 0.0, 0.05)])
    sp = np.stack([np.c_[xy, np.full(9, 0.014)], np.c_[xy, np.full(9, -0.114)]])
    up = rng.normal(scale=5e-3, size=(9, 3, 9))
    moment = np.array([0.0, 0.0, 0.909])
    model = SensorModel(sp.reshape(-1, 3),
                        np.concatenate([up, up * np.array([-1.0, -1.0, 1.0])[None, :, None]]),
                        moment, "a" * 64, 0.0, None)
    layout = SensorLayout(sp.reshape(-1, 3), model.coil_field_t_per_a.reshape(18, 3, 9))
    # the upright magnet's position alone: this synthetic board's cold fix is trusted
    pipe = SensorPipeline(ModelEstimator(model, dataclasses.replace(POSITION_ONLY, cores=False)),
                          layout, lambda t: np.zeros(9), moment)
    p = np.array([0.0, 0.01, 0.04])
    good = magpy.misc.Dipole(moment=moment, position=p).getB(sp.reshape(-1, 3))
    ok18 = ("ok",) * 18
    fix = pipe.process(SensorFrame(np.where(np.arange(18)[:, None] == 3, np.inf, good), ok18,
                                   0.0))
    assert fix.ok and fix.excluded[3] and fix.problems[0][0] == "sensor_saturated"
    assert np.linalg.norm(fix.position_m - p) < 1e-4
    bad = {"shape": SensorFrame(good[:17], ok18, 0.0),
           "usable": SensorFrame(np.full((18, 3), np.nan), ("saturated",) * 18, 0.0),
           "numbers": SensorFrame([["a", 1, 2]] * 18, ok18, 0.0)}
    for word, frame in bad.items():
        fix = pipe.process(frame)
        assert not fix.ok and np.all(np.isfinite(fix.position_m))
        assert any(name == "lost" and word in detail for name, detail in fix.problems), \
            (word, fix.problems)
    fix = pipe.process(SensorFrame(good, ok18, 0.01))
    assert fix.ok and np.linalg.norm(fix.position_m - p) < 1e-4
    assert fix.covariance_m2.shape == (3, 3) and 0 < fix.protection_level_m < 20e-3


def test_multi_frame_protection_level_of_the_filtered_position():
    """The filtered position (1 - K) x_pred + K x_fix has the error covariance
    (1 - K)^2 p I + K^2 C: with C = s^2 I its noise part scales by
    sqrt(((1 - K)^2 p + K^2 s^2) / s^2) (the bias part is not filtered); K = p / (p + s^2), the
    optimal gain, gives the harmonic combination s^2 p / (s^2 + p)."""
    from firmware_io.localization.integrity import fused_protection_level

    s2, p, bias, pl = (0.8e-3) ** 2, (0.4e-3) ** 2, 1e-3, 6e-3
    k = p / (p + s2)
    got = fused_protection_level(pl, s2 * np.eye(3), p, bias, k)
    assert got == pytest.approx(bias + (pl - bias) * np.sqrt(p / (s2 + p)), rel=1e-12)
    # anisotropic C, a tracker gain: the worst direction is C's largest eigenvalue; the
    # filtered covariance is rounder than C (l2 / l1 = 0.0625, tabulated as 0.1): its quantile
    # grows at most by the ratios' quotient
    cov = np.diag([0.2e-3, 0.5e-3, 2e-3]) ** 2
    want = (0.7 ** 2 * p + 0.3 ** 2 * (2e-3) ** 2) / (2e-3) ** 2
    want *= (0.7 ** 2 * p + 0.3 ** 2 * (0.5e-3) ** 2) / (0.7 ** 2 * p + 0.3 ** 2 * (2e-3) ** 2) / 0.1
    assert fused_protection_level(pl, cov, p, bias, 0.3) == pytest.approx(
        bias + (pl - bias) * np.sqrt(want), rel=1e-12)
    # gain 1: the fix alone; no prediction, no covariance, or an infinite PL: the fix's own
    assert fused_protection_level(pl, cov, p, bias, 1.0) == pytest.approx(pl, rel=1e-12)
    assert fused_protection_level(pl, s2 * np.eye(3), 0.0, bias, k) == pl
    assert fused_protection_level(pl, None, p, bias, k) == pl
    assert fused_protection_level(np.inf, s2 * np.eye(3), p, bias, k) == np.inf


class NoisyLocalizer:
    """The true position, ok, with covariance sigma^2 I and the PL a single frame gives it
    (1 mm bias + 4.6 sigma): over the 5 mm alert limit for sigma = 1.5 mm."""

    model_bias_m = 1e-3
    integrity_risk = 1e-4

    def __init__(self, truth, sigma_m):
        self.truth, self.sigma = truth, sigma_m

    def reset(self):
        pass

    def estimate(self, readings_t, currents_a=None, *, usable=None, seed=None, time_s=None):
        pl = self.model_bias_m + 4.6 * self.sigma
        return _estimate(self.truth(), True, self.sigma, pl)


@pytest.mark.parametrize("sigma_m, renders", [(1.5e-3, True), (20e-3, False)])
def test_multi_frame_pl_lets_the_runner_acquire_and_render(device, sigma_m, renders, tmp_path):
    """Alert limit 5 mm, every fix's own PL above it: with sigma 1.5 mm the tracker's filtered
    position gets a PL within the limit after a few frames (acquisition, then rendering);
    with sigma 20 mm it never does, and nothing renders."""
    design, array, a = device
    dev = SimulatedDevice(design, array, seed=5, drive=md10c_drive(design))
    traj = slide_trajectory(lambda x, y: np.full_like(x, 0.05), duration_s=0.3, samples=201)

    def factory(source, clock, hook):
        cfg = RunnerConfig(dev.drive, resume_after_s=0.02, alert_limit_m=5e-3)
        loc = NoisyLocalizer(lambda: source.frame_truth_m, sigma_m)
        r = Runner(device_map(a, BOX, dev), PlaneScene(0.05, 6.0), loc,
                   RunnerIO(dev.coils, source, lambda line: None, clock), cfg,
                   tracker=PoseTracker(), allocate=hook(clipped_lstsq))
        r.start()
        return r

    res = simulate(dev, factory, traj, duration_s=0.3, progress=False)
    write_run_csv(tmp_path / "run.csv", res.columns)
    with (tmp_path / "run.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    state = np.array([r["state"] for r in rows])
    cmd = np.array([[float(r[k]) for k in r if k.startswith("cmd")] for r in rows])
    assert bool((state == "running").sum() > 100) is renders, np.unique(state, return_counts=True)
    assert np.all(cmd[state != "running"] == 0.0)


def test_recovery_takes_a_few_frames_once_the_fault_is_gone(device):
    """A dead sensor (excluded) and an out-of-box excursion: the runner is running again within
    the frames the design needs, not after a fixed hold time. A frame holds the field of the
    previous pass's start, so after the fault is gone 2 frames still show it (after the bus's
    gap while the dead sensor is reset they are older than ``max_fix_age_s``); back from the
    excursion the track is older than ``max_fix_age_s`` and was dropped, so the first trusted
    fix restarts it (the bound still allows a gated fix and its confirmation); then
    ``resume_fixes`` accepted fixes; plus one frame interval for the fit's modelled compute
    time on the sensor side. While the sensor is still dead the runner runs with it excluded;
    nothing renders in between."""
    dead_at, box_at = 0.15, 0.5
    res, runner, _ = _jumping_run(device, 6, 0.9, f"sensor_dead@{dead_at},out_of_box@{box_at}",
                                  (), 10 ** 9)
    c = res.columns
    t, st, fresh = c["t_s"], np.asarray(c["state"]), np.asarray(c["new_frame"], bool)
    cmd = np.stack([c[f"cmd{j + 1}_a"] for j in range(9)], 1)
    assert np.all(cmd[st != "running"] == 0.0)
    frames = t[fresh]
    n_fix = runner.cfg.resume_fixes
    rows = {f["fault"]: f for f in time_to_safe(c, res.faults, 1e-3)}

    def frame_intervals(t0, t1):
        """The gaps between the frames handed over in [t0, t1] (and the one before t0), s."""
        inside = frames[(frames >= t0 - 1e-9) & (frames <= t1 + 1e-9)]
        before = frames[frames < t0 - 1e-9][-1:]
        return np.diff(np.r_[before, inside])

    # the dead sensor: running again with it excluded before it answers again
    dead = rows["sensor_dead"]
    assert dead["state"] == "sensor_dead" and dead["resumed_s"] is not None
    t_det, t_run = dead_at + dead["time_to_safe_s"], dead_at + dead["resumed_s"]
    d = frame_intervals(t_det, t_run)
    bound = d.max() + (2 + n_fix) * np.sort(d)[-2] + 1e-3
    assert t_run - t_det <= bound, (dead, d)
    assert dead["resumed_s"] < FAULT_CLEARS_S["sensor_dead"]
    # the excursion: running again within the frames that confirm the finger is back
    out = rows["out_of_box"]
    assert out["state"] == "out_of_box" and out["recovered_s"] is not None
    t_clear = box_at + FAULT_CLEARS_S["out_of_box"]
    d = frame_intervals(t_clear, t_clear + out["recovered_s"])
    assert out["recovered_s"] <= (2 + 2 + n_fix + 1) * d.max() + 1e-3, (out, d)


def test_no_force_with_a_position_older_than_one_sensor_pass(device):
    """Fixes every 5 ms (frames 8 ms old at hand-over), then none: the runner renders while
    the newest trusted fix is at most STALE_PASSES passes (+ 2 periods) old at hand-over and
    goes 'lost' at the first step beyond; after max_fix_age_s it drops the track, so a finger
    that comes back 40 mm away is taken at once (not gated against where it left) and renders
    after resume_fixes fixes."""
    from firmware_io.runner import Fix
    from firmware_io.runner.loop import STALE_PASSES

    design, array, a = device
    dev = SimulatedDevice(design, array, seed=2, drive=md10c_drive(design))
    cfg = RunnerConfig(dev.drive)
    here, there = np.array([0.0, 0.0, 0.04]), np.array([0.04, 0.0, 0.04])

    def source(t):
        k = int(round(t * 1e3))
        if k % 5 or 50 < k < 120:
            return None
        p = here if k <= 50 else there
        return Fix(p.copy(), MOMENT.copy(), True, t - 0.008, (), np.zeros(18, bool), 0.0,
                   (0.3e-3) ** 2 * np.eye(3), 1e-3)

    r = Runner(device_map(a, BOX, dev), PlaneScene(0.05, 6.0), NoisyLocalizer(None, 0.3e-3),
               RunnerIO(dev.coils, source, lambda line: None, lambda: 0.0), cfg,
               tracker=PoseTracker(), allocate=clipped_lstsq)
    r.start()
    recs = [r.step(k * 1e-3) for k in range(140)]
    states = [x.state for x in recs]
    limit_ms = STALE_PASSES * 5 + 2                          # 9.5 ms after the hand-over at 50
    assert states[50:60] == ["running"] * 10 and states[60] == "lost"
    assert 50 + limit_ms < 60 <= 50 + limit_ms + 1
    assert all(s == "lost" for s in states[60:130])
    # the track was dropped: the fixes at 120, 125, 130 are accepted, the third one resumes
    assert states[130] == "running" and "gated" not in states
    assert np.linalg.norm(recs[130].position_m - there) < 1e-3
    assert all(not np.any(x.command_a) for x in recs[60:130])
