"""The cores' saturation end to end: what the map stores, what the runner applies, what the
simulated plant does -- each against an independent reference.

References: the nonlinear (1010 steel) axisymmetric GetDP FEM of the thesis coil, cached in
tests/data/saturation_refs.json (``PYTHONPATH=$PWD python tests/data/make_saturation_refs.py``;
levels 0 -> 1 change the factors by <= 1.2e-4): the factor on the axis at 20 / 30 / 50 mm above
the winding's top and the factors of Br, Bz, dBr/dz, dBz/dz at three off-axis points, at 3, 5
and 6 A. numpy.interp and finite differences for the firmware's table; the linear allocation's
equations for the runner.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from conftest import load_study, small_steel_design
from designkit.design import default_design, pose_on_axis
from designkit.model.array import CoilArray, force_matrix, gradient_from_g5
from designkit.model.coil import Coil
from designkit.sim import run as sim_run
from designkit.sim.device import SimulatedDevice
from designkit.sim.saturation import PlantSaturation
from firmware_io.mapfile import MapFile, SaturationTable
from firmware_io.runner import Fix, PoseTracker, Runner, RunnerConfig, RunnerIO

from _runner_fakes import PlaneScene, TruthEstimator, device_map, md10c_drive

REFS = json.loads((Path(__file__).parent / "data" / "saturation_refs.json").read_text())
STEEL = default_design().replace(**{"core.bh": "steel1010"})


def _fem_inputs_match():
    c, k = STEEL.coil, STEEL.core
    return REFS["inputs"] == {"coil": [c.inner_radius_m, c.outer_radius_m, c.length_m, c.turns],
                              "core": [k.radius_m, k.length_m, k.relative_permeability,
                                       k.offset_m]}


# ---------------------------------------------------------------------------------------------
# the firmware's table


def test_saturation_table_interpolates_like_numpy_and_linearizes_g():
    rng = np.random.default_rng(3)
    cur = np.linspace(0.0, 6.0, 7)
    fac = np.c_[np.ones(7), 1.0 - 0.02 * cur ** 1.5, 1.0 - 0.004 * cur ** 2]
    t = SaturationTable(cur, fac)
    i = rng.uniform(-8.0, 8.0, (50, 3))          # both signs, beyond the table too
    want = np.stack([[np.interp(abs(v), cur, fac[:, k]) for k, v in enumerate(r)] for r in i])
    np.testing.assert_allclose(t.factor_at(i), want, rtol=0, atol=1e-15)
    np.testing.assert_allclose(t.equivalent(i), want * i, rtol=0, atol=1e-15)
    np.testing.assert_allclose(t.factor_at(i[0, 1:], coils=[1, 2]), want[0, 1:], atol=1e-15)
    # the linearization: exact at its point, slope = dg/dI (central differences inside a
    # segment), error ~ |s'| dI^2 within a segment (g is quadratic there)
    h = 1e-6
    for r in i[np.all(np.abs(np.abs(i) - np.round(np.abs(i))) > 1e-3, axis=1)]:
        gain, offset = t.linearize(r)
        np.testing.assert_allclose(gain * r + offset, t.equivalent(r), atol=1e-12)
        inside = np.abs(r) < 6.0
        fd = (t.equivalent(r + h) - t.equivalent(r - h)) / (2 * h)
        np.testing.assert_allclose(gain[inside], fd[inside], rtol=0, atol=1e-6)
        np.testing.assert_allclose(gain[~inside], t.factor_at(r)[~inside])  # held: slope 0
    assert not t.linear and SaturationTable([0.0, 1.0], np.ones((2, 2))).linear


# ---------------------------------------------------------------------------------------------
# designkit's saturating cores (the plant) and the map's factor against the nonlinear FEM


def test_the_plants_saturating_core_against_the_nonlinear_fem():
    """One 1010-steel coil: the plant's column (the coupled linear model + the nonlinear core's
    change at the current) at the FEM's points, as the ratio to the linear model, against the
    FEM's ratio. Measured: within 1.13 % everywhere (3-6 A, on the axis and off it; 0.92 % at
    6 A), where the factor itself ranges 0.86-0.93 at 6 A: one factor per point, not per coil
    (the map's 0.919 at (50 mm, 40 mm) for dBz/dz would be 6 % off)."""
    assert _fem_inputs_match()
    coil = Coil.from_design(STEEL, (0.0, 0.0, 0.0))
    arr = CoilArray((coil,))
    plant = PlantSaturation(arr, 6.0)
    top = coil.length / 2
    probes = np.array([[r, 0.0, top + h] for r, h in REFS["probes_m"]])
    axis = np.array([[0.0, 0.0, top + h] for h in REFS["heights_m"]])
    pts = np.r_[probes, axis]
    a, d = arr.actuation_matrix(pts), plant.deltas(pts)

    def components(x):   # Br, Bz, dBr/dz, dBz/dz at (r, 0, z)
        return np.stack([x[:, 0, 0], x[:, 2, 0], x[:, 5, 0], -(x[:, 3, 0] + x[:, 6, 0])], 1)

    worst = 0.0
    for j, i in enumerate(REFS["currents_a"]):
        cols = np.stack([plant.columns(a[k], d[k], [i]) for k in range(len(pts))])
        ratio = components(cols) / components(a)
        worst = max(worst, np.abs(ratio[:3] - np.array(REFS["probe_factor"][j])).max(),
                    np.abs(ratio[3:, 3] - np.array(REFS["factor"][j])).max())
    assert worst < 0.015, worst
    # the factor is not one number: at 6 A it spans more than the tolerance
    f6 = np.array(REFS["probe_factor"][-1])
    assert f6.max() - f6.min() > 0.05


def test_the_plant_follows_each_coils_own_core_and_pose():
    """A 1010-steel coil tilted 35 degrees beside a linear-core one: the plant's change of the
    tilted coil's column is the upright coil's, turned with it (B -> R B, grad B -> R G R^T at
    the point turned back), and the linear core's column does not change; the map's factor
    table likewise (1 for the linear core)."""
    up = Coil.from_design(STEEL, (0.0, 0.0, 0.0))
    axis = np.array([np.sin(np.radians(35.0)), 0.0, np.cos(np.radians(35.0))])
    tilted = up.replace(pose=pose_on_axis((0.09, 0.0, 0.0), axis))
    linear = Coil.from_design(default_design(), (-0.09, 0.0, 0.0))
    pts = np.array([[0.1, 0.02, 0.09], [0.05, -0.01, 0.08], [-0.08, 0.0, 0.07]])
    both = PlantSaturation(CoilArray((tilted, linear)), 6.0)
    d = both.deltas(pts)
    assert np.all(d[..., 1] == 0.0) and np.abs(d[..., 0]).max() > 0
    rot = tilted.pose.matrix
    local = (pts - np.asarray(tilted.pose.position)) @ rot          # R^T (p - c)
    ref = PlantSaturation(CoilArray((up,)), 6.0).deltas(local)
    b = np.einsum("ij,nlj->nli", rot, ref[:, :, :3, 0])
    g = np.einsum("ij,nljk,mk->nlim", rot, gradient_from_g5(ref[:, :, 3:, 0]), rot)
    np.testing.assert_allclose(d[:, :, :3, 0], b, rtol=0, atol=1e-9 * np.abs(b).max())
    np.testing.assert_allclose(gradient_from_g5(d[:, :, 3:, 0]), g, rtol=0,
                               atol=1e-9 * np.abs(g).max())
    fac = CoilArray((tilted, linear)).saturation_correction(currents_a=[0.0, 6.0])
    assert np.all(fac["saturation_factor"][:, 1] == 1.0)
    assert fac["saturation_factor"][1, 0] < 0.93


def test_the_maps_saturation_factor_against_the_nonlinear_fem(steel_small_map):
    """The factor the map stores (the builder) as the reader returns it, at the design point
    (30 mm above the top), against the FEM: measured -0.82 / -0.46 / -0.35 % at 3 / 5 / 6 A.
    Inverted (1.087 at 6 A) in the builder or the reader, or taken at the wrong current, it is
    far off. A map of linear cores stores 1."""
    path, _ = steel_small_map
    fm = MapFile.load(path)
    col = REFS["heights_m"].index(0.030)
    for j, i in enumerate(REFS["currents_a"]):
        got = fm.saturation_factor(np.full(fm.n_coils, -i if j % 2 else i))
        assert np.all(np.abs(got - REFS["factor"][j][col]) < 0.01), (i, got)
    tab = fm.saturation_table()
    assert not tab.linear and tab.factor_at(np.full(fm.n_coils, 6.0)).max() < 0.93


def test_a_linear_core_design_stores_no_saturation(small_map):
    fm = MapFile.load(small_map)
    assert fm.saturation_table().linear
    np.testing.assert_array_equal(fm.saturation_factor(np.full(9, 6.0)), np.ones(9))


def test_the_simulated_device_saturates_its_cores_at_the_true_currents():
    """One steel coil on the device: its force per ampere at the true current against the
    nonlinear core solved at exactly that current (the plant interpolates between 0.5 A
    levels: measured within 0.1 %); the linear device's is 8 % higher at 5.8 A."""
    design = STEEL.replace(**{"array.rows": 1, "array.columns": 1})
    dev = SimulatedDevice(design, sensor_errors="ideal", noise_t=0.0)
    p = np.array([[0.002, -0.001, 0.030]] * 3)
    dev.prepare(p)
    coil = dev.array.coils[0]
    steel = dataclasses.replace(coil, core=dataclasses.replace(coil.core, bh="steel1010"))
    m = dev.moment
    for i in (5.77, -2.3):
        _, g = steel.field(p[0], i, gradient=True)
        want = float((force_matrix(m) @ [g[0, 0], g[0, 1], g[0, 2], g[1, 1], g[1, 2]])[2]) / i
        got = float(dev.force_per_amp(1, np.array([i]))[2, 0])
        assert got == pytest.approx(want, rel=2e-3), (i, got, want)
    linear = float((force_matrix(m) @ dev.array.actuation_matrix(p[:1])[0, 3:])[2, 0])
    assert linear > 1.05 * float(dev.force_per_amp(1, np.array([5.77]))[2, 0])


# ---------------------------------------------------------------------------------------------
# the runner


def test_the_runner_allocates_on_the_saturated_columns(thesis_array):
    """A 3 N push 10 mm below a plane at 30 mm above the centre coil, with a table that takes
    15 % off its column at 6 A: after a few steps at one position the commanded currents give
    the target through the saturated columns, F diag(s(I)) I = f - F0 (to the linearization's
    tolerance), not through the linear ones (which would render ~6 % less than asked); the
    reported torque is that of the saturated columns too."""
    design = default_design()
    drive = md10c_drive(design, limit=6.0, total=54.0)
    cur = np.linspace(0.0, 6.0, 7)
    fac = np.ones((7, 9))
    fac[:, 4] = 1.0 - 0.15 * (cur / 6.0) ** 2
    table = SaturationTable(cur, fac)
    cfg = RunnerConfig(drive, saturation=table, force_axes="xyz")
    dev = SimulatedDevice(design, thesis_array, drive=drive)
    p = np.array([0.0, 0.0, 0.030])
    a = thesis_array.actuation_matrix(p)
    scene = PlaneScene(0.040, 300.0)

    def source(t):
        return Fix(p.copy(), dev.moment.copy(), True, t, (), np.zeros(18, bool), 0.0,
                   (0.3e-3) ** 2 * np.eye(3), 1e-3)

    r = Runner(device_map(a, (p - 0.02, p + 0.02), dev), scene, TruthEstimator(lambda: p),
               RunnerIO(dev.coils, source, lambda line: None, lambda: 0.0), cfg,
               tracker=PoseTracker())
    r.start()
    for k in range(4):
        rec = r.step(k * 1e-3)
    assert rec.state == "running"
    i = rec.command_a
    fm = force_matrix(dev.moment) @ a[3:]
    target = scene.force(p, np.zeros(3))
    assert abs(i[4]) > 4.0 and table.factor_at(i)[4] < 0.93      # well into the table
    np.testing.assert_allclose(fm @ (table.factor_at(i) * i), target, rtol=0,
                               atol=2e-3 * np.linalg.norm(target))
    assert np.linalg.norm(fm @ i - target) > 0.04 * np.linalg.norm(target)
    b = a[:3] @ (table.factor_at(i) * i)
    np.testing.assert_allclose(rec.torque_n_m, np.cross(dev.moment, b), rtol=1e-9, atol=1e-12)


# ---------------------------------------------------------------------------------------------
# end to end: run --simulate on the saturating device at the current limit


@pytest.fixture(scope="module")
def steel_hold(steel_small_map, tmp_path_factory):
    """The finger pressed into the hemisphere 30 mm above the centre coil (lambda 60 N/m: 3 N),
    circling 2-3 mm for 0.3 s, on the 1010-steel device (studies/saturation_run.py's hold)."""
    path, arr = steel_small_map
    out = tmp_path_factory.mktemp("steel_hold")
    t = np.linspace(0.0, 0.3, 31)
    z = 0.030 + 0.002 * np.sin(2 * np.pi * t / 0.5)
    x = 0.003 * np.sin(2 * np.pi * t / 1.0)
    csv = out / "hold.csv"
    csv.write_text("t_s,x_m,y_m,z_m\n" + "".join(f"{a:.6f},{b:.6f},0.0,{c:.6f}\n"
                                                  for a, b, c in zip(t, x, z)))
    mp = pytest.MonkeyPatch()
    mp.setattr(sim_run, "plot_run", lambda *a, **k: None)  # figures are not physics
    try:
        return sim_run.run_simulation(
            sim_run.RunSettings(obj="hemisphere", trajectory=str(csv), lam_n_per_m=60.0),
            design=small_steel_design(), map_path=path, array=arr, out=out / "r",
            progress=False)
    finally:
        mp.undo()


def test_run_simulate_renders_the_saturating_device_within_3_percent(steel_hold):
    """The acceptance line: at the current limit, the force the runner renders (its model: the
    map's A and saturation factor at the commanded currents, which the commands solve for)
    within 3 % of the exact
    saturating-core force of the same currents at the finger's position (the plant: designkit's
    nonlinear cores, never the map). Measured here (0.3 s, 217 steps at >= 5.2 A, up to 5.77 A):
    0.72 % RMS, 0.92 % max; the same currents on the map's linear columns 5.5 % RMS, 6.2 % max
    (studies/saturation_run.py, 1 s: 0.9 / 2.3 % against 5.6 / 6.3 %)."""
    sat = steel_hold["saturation"]
    assert steel_hold["faults"] == [] and sat["steps"] >= 100, sat
    assert sat["max_command_a"] > 5.5 and sat["factor_at_max"] < 0.94
    assert sat["with_factor"]["rel_rms"] < 0.02 and sat["with_factor"]["rel_max"] < 0.03, sat
    assert sat["without_factor"]["rel_rms"] > 0.04, sat
    # ... and the runner's commands are that model's answer to what it renders (64 steps near
    # the limit with no coil at its bound: measured -1e-6; a runner that ignores the factor
    # commands currents that model at -5.4 %, one that applies it twice at ~ +6 %)
    assert sat["below_bound_steps"] >= 30, sat
    assert abs(sat["commands_vs_rendered_mean_rel"]) < 0.01, sat
    causes = steel_hold["force_error_causes"]
    assert causes["saturation"]["norm_rms_n"] < 0.02 * steel_hold["object_force_rms_n"]


@pytest.mark.slow
def test_saturation_study_runs(tmp_path):
    """Smoke test of studies/saturation_run.py (its own steel map, the hold with and without
    the factor); the physics it reports is held by the default tests above."""
    res = load_study("saturation_run").run(tmp_path, quick=True)
    assert res["hold_with_factor"]["saturation"]["steps"] > 0
    assert (res["hold_factor_1"]["saturation"]["with_factor"]["rel_rms"]
            > res["hold_with_factor"]["saturation"]["with_factor"]["rel_rms"])
