"""The sensor side's exclusions and the faults they raise: a sensor the estimator's fault
detection keeps excluding is latched out after FDE_LATCH_PASSES trusted frames ('sensor_value',
logged, left out from then on); sensors the model predicts beyond EXPECTED_SATURATION of the
TLV493D's 130 mT range are dropped before the fit without a fault, one that reads beyond the
range unpredicted raises 'sensor_saturated'; bad frames never raise."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from designkit.design import default_design
from designkit.sim import SimulatedDevice
from firmware_io.localization import Estimate
from firmware_io.runner import (EXPECTED_SATURATION, FDE_LATCH_PASSES, CurrentHistory,
                                ExclusionLatch, Runner, RunnerConfig, RunnerIO, SensorFrame,
                                SensorLayout, SensorPipeline)

from _runner_fakes import PlaneScene, clipped_lstsq, device_map, md10c_drive

BOX = (np.array([-0.075, -0.075, 0.010]), np.array([0.075, 0.075, 0.080]))
P = np.array([0.0, 0.0, 0.04])
M = np.array([0.0, 0.0, 0.909])


class ExcludingEstimator:
    """Trusted fixes at P; its fault detection excludes ``bad`` while that sensor's reading is
    finite (as RAIM FDE would a lying sensor). Records what it was given."""

    integrity_risk = 1e-4
    model_bias_m = 0.0

    def __init__(self, bad):
        self.bad, self.seen = bad, []

    def reset(self):
        pass

    def estimate(self, readings_t, currents_a=None, *, usable=None, seed=None, time_s=None):
        self.seen.append(np.array(readings_t))
        excl = (self.bad,) if np.isfinite(readings_t[self.bad]).all() else ()
        return Estimate(P.copy(), M.copy(), True, "", (0.3e-3) ** 2 * np.eye(3), 1e-3, 0.0,
                        excl)


def test_exclusion_latch_counts_consistent_frames_until_a_trusted_fix_vouches():
    latch = ExclusionLatch(5, passes=3)
    assert latch.update((2,), True) == [] and latch.update((2,), True) == []
    assert latch.update((2,), False) == []          # a refused frame: no evidence either way
    assert latch.update((2, 4), True) == [2]        # third frame the others agreed with
    assert latch.update((4,), True) == []
    assert latch.update((), True, vouched=(0, 1, 3, 4)) == []   # a trusted fix used sensor 4
    assert latch.count[4] == 0 and latch.latched.tolist() == [False, False, True, False, False]
    assert latch.update((4,), True) == [] and latch.count[4] == 1


@pytest.fixture(scope="module")
def dev(thesis_array):
    return SimulatedDevice(default_design(), thesis_array, seed=1,
                           drive=md10c_drive(default_design(), 6.0, 54.0))


def test_a_sensor_fault_detection_keeps_excluding_is_latched_out_and_logged(dev):
    """Sensor 5 excluded by fault detection in every frame: the runner logs the exclusion
    once, keeps rendering (the estimate is trusted), enters 'sensor_value' at the
    FDE_LATCH_PASSES-th frame, and from then on the estimator gets NaN for sensor 5 (it is out
    before the fit) and the runner resumes after resume_fixes fixes."""
    a = dev.array.actuation_matrix(P)
    est = ExcludingEstimator(5)
    lines = []
    drive = dataclasses.replace(dev.drive, current_limit_a=4.8, total_current_a=20.0)
    cfg = RunnerConfig(drive, force_axes="xyz")
    frames = lambda t: SensorFrame(np.full((18, 3), 1e-3), ("ok",) * 18, t)  # noqa: E731
    r = Runner(device_map(a, BOX, dev), PlaneScene(0.05, 6.0), est,
               RunnerIO(dev.coils, frames, lines.append, lambda: 0.0), cfg,
               allocate=clipped_lstsq)
    r.start()
    states = [r.step(k * 1e-3).state for k in range(FDE_LATCH_PASSES + 6)]
    n = FDE_LATCH_PASSES
    assert states[:n - 1] == ["running"] * (n - 1)
    assert states[n - 1] == "sensor_value"
    assert states[n - 1 + cfg.resume_fixes] == "running"
    assert sum("fault detection excludes sensors [5]" in s for s in lines) == 1
    assert any("FAULT sensor_value: sensor 5 excluded" in s for s in lines)
    assert np.isfinite(est.seen[n - 1][5]).all() and np.isnan(est.seen[n][5]).all()
    assert r.exclusion_log[0][1] == (5,) and r.exclusion_log[-1][1] == ()


def _layout(field_per_amp):
    """18 sensors far from the magnet (1 m below), sensor 0 with the coils' field
    ``field_per_amp`` (3, 9) T/A, the others none."""
    cf = np.zeros((18, 3, 9))
    cf[0] = field_per_amp
    return SensorLayout(np.tile([0.0, 0.0, -1.0], (18, 1)), cf)


class RecordingEstimator:
    def __init__(self):
        self.seen = []

    def reset(self):
        pass

    def estimate(self, readings_t, currents_a=None, *, usable=None, seed=None, time_s=None):
        self.seen.append(np.array(readings_t))
        return Estimate(P.copy(), M.copy(), True, "", None, 1e-3)


@pytest.mark.parametrize("current_a, dropped", [(3.3, False), (3.6, True)])
def test_sensors_predicted_beyond_the_linear_range_are_dropped_without_a_fault(current_a,
                                                                               dropped):
    """Coil 0 puts 30 mT/A on sensor 0's z axis: at 3.6 A the model predicts 108 mT, beyond
    0.8 x 130 = 104 mT, so the sensor is left out before the fit (NaN to the estimator, listed
    as saturating, no fault) although it still reads in range; at 3.3 A (99 mT) it is used."""
    cf = np.zeros((3, 9))
    cf[2, 0] = 0.030
    est = RecordingEstimator()
    h = CurrentHistory(9, 8)
    h.push(0.0, np.r_[current_a, np.zeros(8)])
    pipe = SensorPipeline(est, _layout(cf), h.at, M)
    readings = np.full((18, 3), 1e-3)
    readings[0, 2] = 0.030 * current_a
    fix = pipe.process(SensorFrame(readings, ("ok",) * 18, 0.001))
    assert fix.ok and fix.problems == ()
    assert bool(np.isnan(est.seen[0][0]).all()) is dropped
    assert fix.saturating == ((0,) if dropped else ())
    assert EXPECTED_SATURATION * 0.130 == pytest.approx(0.104)


def test_a_reading_beyond_the_range_the_model_did_not_predict_is_a_fault():
    """No current, so no predicted field at sensor 0; it reads 150 mT (a stray magnet, a
    broken model): excluded with 'sensor_saturated'. The same reading while the model
    predicts it (coil 0 at 5 A): excluded quietly."""
    cf = np.zeros((3, 9))
    cf[2, 0] = 0.030
    readings = np.full((18, 3), 1e-3)
    readings[0, 2] = 0.150
    for current_a, fault in ((0.0, True), (5.0, False)):
        est = RecordingEstimator()
        h = CurrentHistory(9, 8)
        h.push(0.0, np.r_[current_a, np.zeros(8)])
        fix = SensorPipeline(est, _layout(cf), h.at, M).process(
            SensorFrame(readings, ("ok",) * 18, 0.001))
        assert np.isnan(est.seen[0][0]).all() and fix.excluded[0]
        assert (fix.problems[:1] == (("sensor_saturated", "sensor 0 reports 'saturated'; "
                                      "excluded"),)) is fault


@pytest.mark.parametrize("frame", [
    SensorFrame(np.zeros((17, 3)), ("ok",) * 18, 0.0),                  # wrong shape
    SensorFrame(np.zeros((18, 3)), ("ok",) * 17, 0.0),                  # statuses
    SensorFrame(np.full((18, 3), np.inf), ("ok",) * 18, 0.0),           # non-finite
    SensorFrame(np.full((18, 3), np.nan), ("ok",) * 18, 0.0),           # nothing usable
    SensorFrame([["x", 1, 2]] * 18, ("ok",) * 18, 0.0),                 # not numbers
    SensorFrame(None, None, None),                                       # nothing at all
])
def test_the_control_step_never_raises_on_a_bad_frame(dev, frame):
    """Each bad frame, processed inside the step (the single-threaded path): the step returns
    with every coil off and a fault naming why; then good frames bring it back. (The
    estimator's own refusals -- nothing usable -- are the shim's: test_runner_integrity.)"""
    from _runner_fakes import TruthEstimator

    a = dev.array.actuation_matrix(P)
    frames = {0: frame}
    source = lambda t: frames.get(round(t * 1e3),  # noqa: E731
                                  SensorFrame(np.full((18, 3), 1e-3), ("ok",) * 18, t))
    lines = []
    drive = dataclasses.replace(dev.drive, current_limit_a=4.8, total_current_a=20.0)
    cfg = RunnerConfig(drive)
    r = Runner(device_map(a, BOX, dev), PlaneScene(0.05, 6.0), TruthEstimator(lambda: P, M),
               RunnerIO(dev.coils, source, lines.append, lambda: 0.0), cfg,
               allocate=clipped_lstsq)
    r.start()
    rec = r.step(0.0)
    assert rec.state != "running" and not np.any(rec.command_a)
    assert any("FAULT" in s for s in lines), lines
    states = [r.step(k * 1e-3).state for k in range(1, 8)]
    assert states[-1] == "running", (states, lines)


def test_the_scene_can_keep_its_sensors_in_their_linear_range(dev):
    """A strong pull (1.5 N down) at 30 mm above the centre coil: the plain allocation drives
    the centre coil's field along the magnet's at the upper centre sensor (4), past 0.8 x 130
    mT; with the scene's SensorHeadroom((4,)) the commanded currents keep the predicted field
    there (the coils' field per ampere at the sensor from the device model + the magnet's
    dipole) within the limit on every axis, and still pull the finger down."""
    from firmware_io.allocation import Allocator
    from firmware_io.localization import multipole_field
    from firmware_io.runner import SensorHeadroom

    from _runner_fakes import TruthEstimator

    p = np.array([0.0, 0.0, 0.03])
    a = dev.array.actuation_matrix(p)
    cfg = RunnerConfig(dev.drive, force_axes="xyz")
    frames = lambda t: SensorFrame(np.full((18, 3), 1e-3), ("ok",) * 18, t)  # noqa: E731
    class Pull:
        def force(self, q, v):
            return np.array([0.0, 0.0, -1.5])

    scene = Pull()
    layout = device_map(a, BOX, dev)
    pts = layout.sensor_positions_m
    field = {}
    for name, headroom in (("plain", None), ("kept", SensorHeadroom((4,)))):
        r = Runner(layout, scene, TruthEstimator(lambda: p, M),
                   RunnerIO(dev.coils, frames, lambda line: None, lambda: 0.0), cfg,
                   allocate=Allocator(), headroom=headroom)
        r.start()
        rec = r.step(0.0)
        assert rec.state == "running"
        b = layout.sensor_coil_field()[4] @ rec.command_a + multipole_field(pts[4:5], p, M)[0]
        field[name] = np.abs(b).max()
        fz = (np.einsum("ij,jk->ik", np.array([[0, 0, 0, 0, 0], [0, 0, 0, 0, 0],
                                               [-M[2], 0, M[0], -M[2], M[1]]]), a[3:])
              @ rec.command_a)[2]
        assert fz < -0.3
    limit = EXPECTED_SATURATION * 0.130
    assert field["plain"] > limit * 1.05
    assert field["kept"] <= limit * (1 + 1e-9)
