"""Scene maps and the symmetric sampling of the map build.

* the array's symmetries: A and F0 filled from one point per orbit equal direct evaluation at
  the images (air coils: exact superposition; the coupled cores' cross blocks from their
  images equal the directly computed blocks);
* a scene map covers the closed-form reach of the thesis hemisphere plus the margin, matches
  the direct model inside it, and the runner fails safe (out_of_box) outside it.
"""

import math
import tomllib

import numpy as np
import pytest

from designkit import default_design, fieldmap
from designkit.model.array import CoilArray
from designkit.cli import main
from designkit.cores import coupled as cp
from designkit.design import design_from_dict, design_to_toml
from designkit.errors import BadInputError
from designkit.fieldmap.symmetry import Orbits, random_orbits, sampling_group
from designkit.geometry.pose import Pose
from designkit.render import Hemisphere
from designkit.sim import SimulatedDevice
from firmware_io.runner import Runner, RunnerConfig, RunnerIO, SensorFrame
from firmware_io.scene import Scene

from _runner_fakes import HoldTracker, PlaneScene, TruthEstimator, clipped_lstsq, md10c_drive

AIR = default_design().replace(core=None)
GRID = ""
HEX = '[array]\nlayout = "hex"\nrings = 1\npitch_m = 0.044\n'
RING = '[array]\nlayout = "ring"\ncount = 6\nradius_m = 0.075\ntilt_deg = 30\n'


def _layout(toml: str):
    return design_from_dict(tomllib.loads(toml))


def test_square_array_has_the_eight_symmetries_and_an_off_centre_coil_fewer():
    arr = CoilArray.from_design(AIR)
    assert len(arr.symmetries()) == 8
    # a coil moved off the square leaves only the mirror through it and the array's centre
    moved = CoilArray(arr.coils[:2] + (arr.coils[2].moved((0.06, 0.06, -0.05)),)
                      + arr.coils[3:])
    got = moved.symmetries()
    assert len(got) == 2 and np.allclose(got.elements[1].g[:2, :2] @ [1.0, 1.0], [1.0, 1.0])


def test_orbit_fill_equals_direct_evaluation_at_the_images():
    arr = CoilArray.from_design(AIR)
    group = arr.symmetries()
    rng = np.random.default_rng(3)
    p = rng.uniform([-0.07, -0.07, 0.02], [0.07, 0.07, 0.06], (4, 3))
    pts = np.concatenate([p @ s.g.T for s in group.elements])
    orb = Orbits.of(pts, group)
    assert len(orb.reps) == 4
    a = arr.actuation_matrix(pts)
    np.testing.assert_allclose(orb.expand_actuation(a[orb.reps]), a, rtol=0,
                               atol=1e-12 * np.abs(a).max())
    # a point set that is not closed under the group keeps only the elements that map it
    half = Orbits.of(pts[:8], group)
    assert len(half.reps) >= 4 and len(half.group) >= 1


def test_random_check_points_are_images_in_the_box_and_their_fill_is_direct():
    arr = CoilArray.from_design(AIR)
    group = arr.symmetries()
    lo, hi = np.array([-0.07, -0.07, 0.02]), np.array([0.07, 0.07, 0.06])
    pts, orb = random_orbits(lo, hi, 20, group, np.random.default_rng(5))
    assert pts.shape == (20, 3) and np.all((pts >= lo) & (pts <= hi))
    assert len(orb.reps) == 3 and np.array_equal(orb.reps, [0, 1, 2])  # ceil(20 / 8)
    assert len(np.unique(np.round(pts, 12), axis=0)) == 20
    a = arr.actuation_matrix(pts)
    np.testing.assert_allclose(orb.expand_actuation(a[orb.reps]), a, rtol=0,
                               atol=1e-12 * np.abs(a).max())
    # a box 140 x 100 mm: the quarter turns do not map it onto itself, the mirrors do
    hi2 = np.array([0.07, 0.05, 0.06])
    pts2, orb2 = random_orbits(-hi2 * [1, 1, -0.5], hi2, 8, group, np.random.default_rng(5))
    assert len(orb2.group) == 4 and len(orb2.reps) == 2
    assert np.all(np.abs(pts2[:, :2]) <= hi2[:2])
    a2 = arr.actuation_matrix(pts2)
    np.testing.assert_allclose(orb2.expand_actuation(a2[orb2.reps]), a2, rtol=0,
                               atol=1e-12 * np.abs(a2).max())


def test_bias_force_symmetry_of_the_coupled_array():
    design = default_design().replace(**{"array.rows": 1, "array.columns": 2})
    arr = CoilArray.from_design(design)
    group = sampling_group(arr, design.magnet.moment_vector_a_m2)
    assert len(group) == 4  # 1 x 2: the rectangle's group (180 degrees, two mirrors)
    p = np.array([[0.012, 0.007, 0.03]])
    pts = np.concatenate([p @ s.g.T for s in group.elements])
    orb = Orbits.of(pts, group)
    f = arr.bias_force(pts, design.magnet.moment_vector_a_m2)
    np.testing.assert_allclose(orb.expand_force(f[orb.reps]), f, rtol=1e-10,
                               atol=1e-12 * np.abs(f).max())


def test_split_lu_only_for_symmetric_arrays_and_it_solves_the_system():
    coil = CoilArray.from_design(default_design()).coils[0]
    pair = CoilArray(tuple(coil.replace(pose=Pose(position=(x, 0.0, -0.05)))
                           for x in (-0.025, 0.025)))
    odd = CoilArray(tuple(coil.replace(pose=Pose(position=(x, y, -0.05)))
                          for x, y in ((0.0, 0.0), (0.05, 0.0), (0.02, 0.06))))
    assert odd.coupled()._sym is None
    system = pair.coupled()
    assert system._sym is not None
    # the coupled columns solve the assembled system: the single-core self blocks plus the
    # cross block, rebuilt here directly
    m, poses = system.models[0], system.poses
    n = m.n_unknowns
    mat = np.zeros((2 * n, 2 * n))
    for j in range(2):
        mat[j * n:(j + 1) * n, j * n:(j + 1) * n] = m.self_block()
        i = 1 - j
        mat[j * n:(j + 1) * n, i * n:(i + 1) * n] = system.coupling_block(m, poses[i], m,
                                                                            poses[j])
    b = np.random.default_rng(0).random((2 * n, 3))
    np.testing.assert_allclose(mat @ system.solve(b), b, atol=1e-10)


@pytest.mark.parametrize("toml", [GRID, HEX, RING])
def test_cross_blocks_from_their_images_equal_the_computed_blocks(toml):
    # every cross block the solve takes from an image under the group (T(h_j) B T(h_i)^T)
    # against the block computed directly at its own placement: a turn applied as R instead
    # of R^T, an action of the wrong core, or a symmetry the layout lacks moves them by O(1)
    system = CoilArray.from_design(_layout(toml)).coupled()
    reps, pairs = system.placements()
    assert len(reps) < len(pairs)
    m, poses = system.models, system.poses
    for jj, ii, key, hj, hi in pairs:
        if hj is None:
            continue
        got = cp.turn(cp.turn(reps[key], m[jj], hj).T, m[ii], hi).T
        want = system.coupling_block(m[ii], poses[ii], m[jj], poses[jj])
        # a hexagon's positions carry rounding of cos / sin: 1e-11, not 1e-12
        assert np.abs(got - want).max() < 1e-11 * np.abs(want).max()


@pytest.mark.parametrize("toml", [GRID, HEX, RING])
def test_coil_columns_from_their_images_equal_the_computed_columns(toml):
    # the projected winding field of each coil on each core: the columns the coupled solve
    # takes from an image under the group against every column computed directly (a wrong
    # turn, or a ring not symmetric under the group, moves them by O(1))
    arr = CoilArray.from_design(_layout(toml))
    system = arr.coupled()
    rhs = system.factors[:, None] * system.coil_columns()
    want = np.zeros_like(rhs)
    for jj, (mj, pj) in enumerate(zip(system.models, system.poses)):
        ring = mj.ring_points(cp.N_PHI_RING)
        glob = ring.reshape(-1, 3) @ pj.matrix.T + np.asarray(pj.position)
        for k, c in enumerate(arr.coils):
            h = c.field(glob, 1.0, include="winding", rtol=1e-9) / cp.MU0 @ pj.matrix
            want[system.offsets[jj]:system.offsets[jj + 1], k] = \
                system.factors[system.offsets[jj]:system.offsets[jj + 1]] * \
                mj.project(h.reshape(ring.shape[:2] + (3,)))
    assert np.abs(rhs - want).max() < 1e-12 * np.abs(want).max()


def test_mode_transform_is_an_orthogonal_representation_and_turn_applies_it():
    model = CoilArray.from_design(default_design()).coupled().models[0]
    els = [g.g[:2, :2] for g in CoilArray.from_design(default_design()).symmetries().elements]
    els += [np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) for a in (0.3, 2.0)]
    t = {k: cp.mode_transform(model, g) for k, g in enumerate(els)}
    b = np.random.default_rng(2).random((model.n_unknowns, 7))
    for a, ga in enumerate(els):
        np.testing.assert_allclose(t[a] @ t[a].T, np.eye(model.n_unknowns), atol=1e-12)
        np.testing.assert_allclose(cp.turn(b, model, ga), t[a] @ b, atol=1e-12)
        for c, gc in enumerate(els):  # T(g h) = T(g) T(h)
            np.testing.assert_allclose(cp.mode_transform(model, ga @ gc), t[a] @ t[c],
                                       atol=1e-12)


# ---------------------------------------------------------------------------- scene maps
def test_scene_region_of_the_thesis_hemisphere_is_its_closed_form_reach():
    lo, hi = fieldmap.default_box(default_design())
    margin, step = 0.005, fieldmap.region.SPACING_M
    r_lo, r_hi = fieldmap.scene_region([Hemisphere()], 0.0, lo, hi, margin_m=margin)
    reach = math.sqrt(0.05 ** 2 - lo[2] ** 2)  # the ball's rim at the box's floor
    for k in range(2):
        assert reach + margin - step <= -r_lo[k] <= reach + margin + step + 1e-12
        assert reach + margin - step <= r_hi[k] <= reach + margin + step + 1e-12
    assert r_lo[2] == lo[2] and 0.05 + margin <= r_hi[2] <= 0.05 + margin + 2 * step


def test_scene_region_refuses_objects_outside_the_box():
    lo, hi = fieldmap.default_box(default_design())
    with pytest.raises(BadInputError, match="reach into"):
        fieldmap.scene_region([Hemisphere(diameter_m=0.02, centre_m=(0.3, 0, 0))], 0.0, lo, hi)


SMALL = default_design().replace(**{"core": None, "workspace.shape": "box",
                                     "workspace.half_width_m": 0.04,
                                     "workspace.z_min_m": 0.01, "workspace.z_max_m": 0.04})


@pytest.fixture(scope="module")
def scene_map(tmp_path_factory):
    folder = tmp_path_factory.mktemp("scene")
    lo, hi = fieldmap.default_box(SMALL)
    obj = Hemisphere(diameter_m=0.04)
    box = fieldmap.scene_region([obj], 0.0, lo, hi, margin_m=0.003)
    path = folder / "scene_map.npz"
    fieldmap.write(path, fieldmap.build(SMALL, box=box, n_check=20, progress=False,
                                        region={"objects": ["half_ball"]}))
    return fieldmap.load(path, SMALL), box


def test_scene_map_covers_its_region_and_matches_the_direct_model(scene_map):
    fm, (lo, hi) = scene_map
    np.testing.assert_allclose(fm.bounds[0], lo)
    np.testing.assert_allclose(fm.bounds[1], hi)
    assert fm.meta["region"]["objects"] == ["half_ball"]
    full_lo, full_hi = fieldmap.default_box(SMALL)
    assert np.prod(hi - lo) < 0.5 * np.prod(full_hi - full_lo)
    p = np.random.default_rng(5).uniform(lo, hi, (300, 3))
    a = CoilArray.from_design(SMALL).actuation_matrix(p)
    err = np.abs(fm.actuation(p) - a).max(axis=(0, 2)) / np.abs(a).max(axis=(0, 2))
    assert np.all(err < 1e-3), err


def test_runner_fails_safe_outside_a_scene_maps_region(scene_map):
    fm, (lo, hi) = scene_map
    arr = CoilArray.from_design(SMALL)
    dev = SimulatedDevice(SMALL, arr, drive=md10c_drive(SMALL))
    cfg = RunnerConfig(dev.drive)
    truth = {"p": 0.5 * (lo + hi)}

    class Source:
        def __call__(self, t):
            return SensorFrame(np.zeros((18, 3)), ("ok",) * 18, t)

    r = Runner(fm, PlaneScene(hi[2], 6.0), TruthEstimator(lambda: truth["p"], dev.moment),
               RunnerIO(dev.coils, Source(), lambda line: None, lambda: 0.0), cfg,
               tracker=HoldTracker(), allocate=clipped_lstsq)
    r.start()
    assert r.step(0.0).state == "running"
    # inside the design's full box but beside the scene's region
    truth["p"] = np.array([hi[0] + 0.004, 0.0, lo[2] + 0.002])
    assert truth["p"][0] < fieldmap.default_box(SMALL)[1][0]
    rec = r.step(1e-3)
    assert rec.state == "out_of_box" and not np.any(rec.command_a)


def test_cli_map_scene_refuses_a_scene_of_another_design(tmp_path, capsys):
    other = tmp_path / "s.npz"
    assert main(["scene", "compile", "hemisphere", "--lambda", "5", "--out", str(other),
                 "--quiet"]) == 0
    toml = tmp_path / "d.toml"
    toml.write_text(design_to_toml(SMALL))
    assert main(["map", "--design", str(toml), "--scene", str(other), "--out",
                 str(tmp_path / "m.npz"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "scene file" in err and "Traceback" not in err
    assert not (tmp_path / "m.npz").exists()
    assert main(["map", "--scene", str(other), "--scene-margin", "-1", "--out",
                 str(tmp_path / "m.npz"), "--quiet"]) == 1
    assert "--scene-margin" in capsys.readouterr().err
    assert fieldmap.scene_band_m(Scene.load(other)) == 0.0


def test_cli_scene_compile_builds_its_scene_map(tmp_path):
    toml = tmp_path / "d.toml"
    toml.write_text(design_to_toml(SMALL))
    out, mp = tmp_path / "s.npz", tmp_path / "m.npz"
    assert main(["scene", "compile", "hemisphere", "--design", str(toml), "--build-map",
                 str(mp), "--n-side", "5", "--out", str(out), "--quiet"]) == 0
    fm = fieldmap.load(mp, SMALL)
    lo, hi = fieldmap.default_box(SMALL)
    want = fieldmap.scene_region([Hemisphere()], 0.0, lo, hi)
    np.testing.assert_allclose(fm.bounds[0], want[0])
    np.testing.assert_allclose(fm.bounds[1], want[1])
    assert fm.meta["region"]["objects"] == ["half_ball"]
    assert Scene.load(out, fm.meta["design_sha256"]).lam_n_per_m > 0
    assert main(["scene", "compile", "hemisphere", "--map", str(mp), "--build-map",
                 str(tmp_path / "m2.npz"), "--out", str(out), "--quiet"]) == 1


def _assembled(system) -> np.ndarray:
    """M assembled block by block, every cross block computed at its own placement."""
    n, off = system.n_unknowns, system.offsets
    m, poses = system.models, system.poses
    mat = np.zeros((n, n))
    for j in range(len(m)):
        for i in range(len(m)):
            mat[off[j]:off[j + 1], off[i]:off[i + 1]] = (
                m[j].self_block() if i == j
                else system.coupling_block(m[i], poses[i], m[j], poses[j]))
    return mat


def _solves_the_assembled_system(system, seed, columns):
    """The split solve (and its transpose) against M assembled block by block."""
    mat = _assembled(system)
    n = system.n_unknowns
    r = np.random.default_rng(seed).standard_normal((n, columns))
    np.testing.assert_allclose(mat @ system.solve(r), r, atol=1e-10 * np.abs(r).max())
    np.testing.assert_allclose(mat.T @ system.solve(r, transpose=True), r,
                               atol=1e-10 * np.abs(r).max())


def test_split_lu_of_the_square_array_pairs_the_two_dimensional_blocks(thesis_array):
    system = thesis_array.coupled()  # the session's default array (conftest)
    sizes = sorted(lu[0].shape[0] for _, lu in system._sym.blocks)
    # D4 on 4176 unknowns: the 2-dimensional type's 2112 split by a reflection into two
    # blocks of 1056 whose matrices are equal (one the quarter turn of the other): one LU
    assert sizes == [384, 528, 528, 624, 1056, 1056]
    big = [lu for _, lu in system._sym.blocks if lu[0].shape[0] == 1056]
    assert big[0] is big[1]
    _solves_the_assembled_system(system, seed=5, columns=3)


@pytest.mark.parametrize("toml, sizes", [
    (HEX, [192, 256, 336, 352, 528, 528, 528, 528]),
    (RING, [192, 192, 272, 272, 464, 464, 464, 464])])
def test_split_of_hexagonal_and_tilted_arrays_solves_the_assembled_system(toml, sizes):
    # C6v on 7 upright cores (the centre on the axis) and on a ring of 6 cores tilted 30
    # degrees (frames adapted to the group): the components of its 6 irreducible types, the
    # two 2-dimensional ones split by a reflection into equal twins; against M assembled
    # from blocks computed at every placement (a symmetry the layout lacks, or a turn of the
    # wrong core, fails by O(1))
    system = CoilArray.from_design(_layout(toml)).coupled()
    assert len(system.group) == 12 and system._lu is None
    assert sorted(lu[0].shape[0] for _, lu in system._sym.blocks) == sizes
    _solves_the_assembled_system(system, seed=7, columns=2)


def test_a_free_layout_without_symmetry_gets_the_plain_solve():
    d = _layout('[array]\nlayout = "free"\npositions_m = [[0, 0, 0], [0.05, 0, 0], '
                '[0.01, 0.06, 0.004]]\naxes = [[0, 0, 1], [-0.2, 0, 0.9797958971132712], '
                '[0, 0, 1]]\n')
    system = CoilArray.from_design(d).coupled()
    assert len(system.group) == 1 and system._sym is None
    _solves_the_assembled_system(system, seed=8, columns=1)


def test_split_of_a_rectangular_array_solves_the_assembled_system():
    # 2 x 3 cores on unequal pitches (group D2: the two reflections and the half turn): the
    # blocks summed from the distinct placements' coupling blocks, without M, against M
    # assembled block by block (a wrong coefficient, turn or placement fails by O(1))
    coil = CoilArray.from_design(default_design()).coils[0]
    arr = CoilArray(tuple(coil.replace(pose=Pose(position=(x, y, -0.05)))
                          for x in (-0.05, 0.0, 0.05) for y in (-0.021, 0.021)))
    system = arr.coupled()
    assert system._sym is not None and system._lu is None
    _solves_the_assembled_system(system, seed=6, columns=2)
