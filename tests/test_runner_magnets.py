"""firmware_io.runner with N magnets: the stacked allocation's rendered force against designkit's
coupled model and magpylib's pair force, the priority rule, the conditioning, the safe state for
N, each magnet's own contact and track. The estimator is a TEST DOUBLE (truth + noise,
tests/_magnets_truth_double.py): the runner's logic with a known localization error; the real
N-magnet estimator runs in tests/test_sim_pinch.py."""

from __future__ import annotations

import dataclasses

import magpylib as magpy
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from designkit.model.array import force_matrix
from designkit.render import scenefile
from designkit.render.laws import ConstraintLaw
from designkit.render.objects import Hemisphere
from designkit.sim.magnets import MagnetsDevice
from firmware_io.allocation import Allocator
from firmware_io.errors import BadInputError
from firmware_io.mapfile import MapFile
from firmware_io.runner import (MagnetsRunner, MagnetsSettings, Runner, RunnerIO, SceneForce,
                                SensorFrame, condition_number, config_from_map,
                                force_law_matrix, magnet_weights, stacked_rows)
from firmware_io.scene import Scene

from _magnets_truth_double import TruthPlusNoiseMagnets
from _runner_fakes import TruthEstimator

MU0 = 4e-7 * np.pi
P0 = np.array([-0.016, 0.002, 0.036])
P1 = np.array([0.017, -0.003, 0.034])
F_WANTED = {0: np.array([-0.12, 0.02, 0.05]), 1: np.array([0.10, 0.0, 0.03])}


class TwoForces:
    """A scene asking force F_WANTED[0] left of x = 0 and F_WANTED[1] right of it, N."""

    def force(self, p, v):
        return F_WANTED[0 if p[0] < 0 else 1].copy()

    def forces(self, p, v):
        return np.array([self.force(q, w) for q, w in zip(p, v)])


class Frames:
    """A sensor source handing over a raw frame (zeros, every sensor ok) every ``pass_s``."""

    def __init__(self, n_sensors, pass_s=4e-3):
        self.n, self.pass_s, self.next_s = n_sensors, pass_s, 0.0

    def __call__(self, t_s):
        if t_s + 1e-12 < self.next_s:
            return None
        self.next_s = t_s + self.pass_s
        return SensorFrame(np.zeros((self.n, 3)), ("ok",) * self.n, t_s)


@pytest.fixture(scope="module")
def rig(pinch_map, thesis_array):
    design, path = pinch_map
    fmap = MapFile.load(path)
    cfg = config_from_map(fmap, force_axes="xyz")
    device = MagnetsDevice(design, thesis_array, seed=3, drive=cfg.drive)
    return design, fmap, cfg, device


def _runner(rig, truth, *, compensate=True, untrusted=None, noise_m=0.0, weights=None):
    design, fmap, cfg, device = rig
    est = TruthPlusNoiseMagnets(truth, [m.moment_vector_a_m2 for m in design.magnets],
                                noise_m, seed=2, untrusted=untrusted)
    logs = []
    io = RunnerIO(device.coils, Frames(fmap.n_sensors), logs.append, lambda: 0.0)
    magnets = MagnetsSettings.of_specs(design.magnets, weights, compensate)
    r = MagnetsRunner(fmap, TwoForces(), est, io, cfg, magnets, allocate=Allocator())
    r.start()
    return r, est, logs


def _run(runner, steps, period=1e-3):
    return [runner.step(k * period) for k in range(steps)]


def _magpy(p, m, radius, length):
    rot = Rotation.align_vectors([m / np.linalg.norm(m)], [[0.0, 0.0, 1.0]])[0]
    mag = np.linalg.norm(m) / (np.pi * radius ** 2 * length)
    return magpy.magnet.Cylinder(dimension=(2 * radius, length),
                                 polarization=(0.0, 0.0, MU0 * mag), position=p,
                                 orientation=rot)


def _true_forces(design, array, positions, current_a):
    """The force on each magnet from designkit's coupled model (coils, every magnet's cores)
    and magpylib's getFT (the other magnet): (forces (2, 3), cross terms (2, 3), pair (2, 3))."""
    specs = design.magnets
    m = np.array([s.moment_vector_a_m2 for s in specs])
    sizes = np.array([(s.radius_m, s.length_m) for s in specs])
    a = array.actuation_matrix(positions)
    coils = np.array([force_matrix(m[k]) @ a[k, 3:] @ current_a for k in range(2)])
    core = array.bias_force_matrix(positions, m, magnet_sizes_m=sizes)[0]
    cross = core.sum(axis=1) - np.einsum("iij->ij", core)
    src = [_magpy(positions[k], m[k], *sizes[k]) for k in range(2)]
    pair = np.array([magpy.getFT(src[1 - k], src[k], meshing=(48, 12, 12))[0]
                     for k in range(2)])
    return coils + core.sum(axis=1) + pair, cross, pair


def test_two_magnets_get_their_own_forces_with_the_pair_force_compensated(rig, thesis_array):
    design = rig[0]
    truth = np.array([P0, P1])
    r, _, _ = _run_still(rig, truth)
    rec = r.last
    assert rec.state == "running"
    f, cross, pair = _true_forces(design, thesis_array, truth, rec.command_a)
    for k in range(2):
        # what is left is the cross term the map cannot give (docs/runner.md, "Several
        # magnets"): a dropped pair force (~0.2 N), own F0 (~10 mN), a sign or a 2 % factor
        # on the pair force fails
        assert np.linalg.norm(f[k] - cross[k] - F_WANTED[k]) < 2e-3, k
    assert np.linalg.norm(pair[0]) > 0.15
    # the conditioning reported is the stacked rows' 2-norm condition number
    assert 1.0 < rec.condition < 100.0
    # without the compensation the miss is the pair force
    r2, _, _ = _run_still(rig, truth, compensate=False)
    f2, cross2, pair2 = _true_forces(design, thesis_array, truth, r2.last.command_a)
    for k in range(2):
        assert np.linalg.norm(f2[k] - cross2[k] - F_WANTED[k] - pair2[k]) < 2e-3


def _run_still(rig, truth, **kw):
    r, est, logs = _runner(rig, lambda t: truth, **kw)
    recs = _run(r, 40)
    r.last = recs[-1]
    return r, est, logs


def test_an_untrusted_magnet_switches_every_coil_off_and_names_it(rig):
    truth = np.array([P0, P1])
    window = (0.032, 0.048)        # frames every 4 ms: the 9th to the 12th are untrusted
    r, est, logs = _runner(rig, lambda t: truth,
                           untrusted=lambda t: {1} if window[0] <= t < window[1] else set())
    recs = _run(r, 90)
    states = [x.state for x in recs]
    t = np.array([x.t_s for x in recs])
    cmd = np.array([x.command_a for x in recs])
    # the window's first frame is handed over (and processed) in the step it is sampled
    bad = (t >= window[0] - 1e-9) & (t < window[1] - 1e-9)
    first = int(np.argmax(bad))
    assert states[first - 1] == "running" and states[first] == "lost"
    assert np.all(cmd[bad] == 0.0) and all(s == "lost" for s, b in zip(states, bad) if b)
    assert any("index" in line and "lost" in line for line in logs)
    assert states[-1] == "running"            # resumes once both are trusted again
    # each magnet's track seeds its own fit: identity carried by the seed's index
    assert est.seeds_seen[-1] == [True, True]


def test_overlapping_estimates_are_a_fault_not_a_traceback(rig):
    truth = np.array([P0, P0 + np.array([0.004, 0.0, 0.0])])   # 4 mm apart: overlapping
    r, _, logs = _runner(rig, lambda t: truth)
    recs = _run(r, 30)
    assert all(not np.any(x.command_a) for x in recs)
    assert recs[-1].state == "lost" and any("overlap" in line for line in logs)


def test_priority_weights_decide_which_contact_wins_when_the_forces_cannot_be_met(rig):
    _, fmap, cfg, _ = rig
    m = fmap.moment_a_m2
    rows = [force_law_matrix(m) @ fmap.actuation(p)[3:] for p in (P0, P1)]
    far = [np.array([0.0, 0.0, 3.0]), np.array([0.0, 0.0, 3.0])]   # beyond the bounds
    miss = {}
    for w in ((1.0, 1.0), (9.0, 1.0), (1.0, 9.0)):
        fm, target = stacked_rows(rows, far, w)
        i, _ = Allocator()(fm, target, 6.0, 54.0)
        miss[w] = [np.linalg.norm(rows[k] @ i - far[k]) for k in range(2)]
    assert miss[(9.0, 1.0)][0] < miss[(1.0, 1.0)][0] < miss[(1.0, 9.0)][0]
    assert miss[(1.0, 9.0)][1] < miss[(1.0, 1.0)][1] < miss[(9.0, 1.0)][1]


def test_condition_number_against_numpy_and_finite_without_full_rank():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 9))
    assert condition_number(a) == pytest.approx(np.linalg.cond(a), rel=1e-12)
    assert np.isfinite(condition_number(np.r_[a[:3], a[:3]]))
    assert np.isfinite(condition_number(np.zeros((6, 9))))


@pytest.mark.parametrize("weights", [(1.0,), (1.0, -1.0), (1.0, np.nan), "ab"])
def test_bad_weights_are_refused_in_one_line(weights):
    with pytest.raises(BadInputError, match="magnet_weights"):
        magnet_weights(weights, 2)


def test_one_magnet_renders_as_the_single_magnet_runner(rig):
    """N = 1 is today's rule: the same fixes give the same commands as :class:`Runner`."""
    design, fmap, cfg, device = rig
    one = design.replace(other_magnets=())
    truth = np.array([P0])
    est = TruthPlusNoiseMagnets(lambda t: truth, [one.magnet.moment_vector_a_m2], 0.0)
    n = fmap.n_sensors
    r1 = MagnetsRunner(fmap, TwoForces(), est, RunnerIO(device.coils, Frames(n), print,
                                                        lambda: 0.0), cfg,
                       MagnetsSettings.of_specs(one.magnets), allocate=Allocator())
    r0 = Runner(fmap, TwoForces(), TruthEstimator(lambda: P0, one.magnet.moment_vector_a_m2),
                RunnerIO(device.coils, Frames(n), print, lambda: 0.0), cfg,
                allocate=Allocator())
    for r in (r0, r1):
        r.start()
    a, b = _run(r0, 30), _run(r1, 30)
    assert [x.state for x in a] == [x.state for x in b]
    assert a[-1].state == "running"
    np.testing.assert_allclose(np.array([x.command_a for x in b]),
                               np.array([x.command_a for x in a]), atol=1e-12)


def test_two_fingers_on_a_sphere_each_get_their_own_contact(rig, thesis_array, tmp_path):
    """A compiled scene (the thesis' hemisphere, eq. 4.1-4.2): each magnet gets the object's
    force at its own position, through the scene's one evaluation of both."""
    design, fmap, cfg, device = rig
    lam = 4.0
    path = scenefile.compile_scene(Hemisphere(), tmp_path / "scene.npz", lam_n_per_m=lam,
                                   law=ConstraintLaw(lam), map_design_sha256=fmap.design_sha256)
    scene = SceneForce(Scene.load(path))
    truth = np.array([P0, P1])
    est = TruthPlusNoiseMagnets(lambda t: truth, [m.moment_vector_a_m2 for m in design.magnets],
                                0.0)
    r = MagnetsRunner(fmap, scene, est, RunnerIO(device.coils, Frames(fmap.n_sensors),
                                                 lambda line: None, lambda: 0.0), cfg,
                      MagnetsSettings.of_specs(design.magnets), allocate=Allocator())
    r.start()
    rec = _run(r, 40)[-1]
    assert rec.state == "running"
    f, cross, _ = _true_forces(design, thesis_array, truth, rec.command_a)
    for k in range(2):
        # the hemisphere's force there: lambda h(x, y) along the top's outward normal
        want = scene.force(truth[k], np.zeros(3))
        h = np.sqrt(0.05 ** 2 - truth[k, 0] ** 2 - truth[k, 1] ** 2)
        np.testing.assert_allclose(np.linalg.norm(want), lam * h, rtol=1e-6)
        assert np.sign(want[0]) == np.sign(truth[k, 0])       # each pushed out on its side
        np.testing.assert_allclose(rec.forces_ref_n[k], want, atol=1e-12)
        assert np.linalg.norm(f[k] - cross[k] - want) < 2e-3, k


class FrameOnly(TruthPlusNoiseMagnets):
    """The double with a frame-only measurement 1 mm beside each (prior-fused) fix."""

    def estimate(self, readings_t, currents_a=None, **kw):
        fit = super().estimate(readings_t, currents_a, **kw)
        return dataclasses.replace(
            fit, frame_positions_m=tuple(m.position_m + [0.0, 1e-3, 0.0] for m in fit.magnets),
            frame_covariances_m2=tuple(np.eye(3) * 1e-8 for _ in fit.magnets))


def test_each_track_filters_the_frame_only_measurement(rig):
    """A fix made with the track's prior already holds the prediction: the lane's tracker takes
    the estimator's frame-only position instead (docs/localization.md, "Several magnets")."""
    design, fmap, cfg, device = rig
    truth = np.array([P0, P1])
    est = FrameOnly(lambda t: truth, [m.moment_vector_a_m2 for m in design.magnets], 0.0)
    r = MagnetsRunner(fmap, TwoForces(), est, RunnerIO(device.coils, Frames(fmap.n_sensors),
                                                       lambda line: None, lambda: 0.0), cfg,
                      MagnetsSettings.of_specs(design.magnets), allocate=Allocator())
    r.start()
    rec = _run(r, 60)[-1]
    assert rec.state == "running"
    np.testing.assert_allclose(rec.positions_m, truth + [0.0, 1e-3, 0.0], atol=1e-6)
