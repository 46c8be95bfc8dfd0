"""The coupled array of any layout: the symmetry group found from the poses, the symmetric solve
against the plain one, invariance under a rigid motion of the whole device, a design file's
layout against the same coils built by hand, and the refusals of coils that meet and sensors in
the iron.

Which wrong change each test catches is said in it; the accuracy against an independent 3-D
reference is in tests/test_coupling_layouts_fem.py.
"""

import math
import tomllib

import numpy as np
import pytest

from designkit import Coil, CoilArray, Pose
from designkit.cores import Core
from designkit.cores.coupled import ArraySystem
from designkit.design import design_from_dict
from designkit.errors import BadInputError, DesignRuleError
from designkit.model.array import gradient_from_g5

HEX = '[array]\nlayout = "hex"\nrings = 1\npitch_m = 0.044\n'
RING = '[array]\nlayout = "ring"\ncount = 6\nradius_m = 0.075\ntilt_deg = 30\n'


def _design(toml: str):
    return design_from_dict(tomllib.loads(toml))


@pytest.mark.parametrize("toml, order, mirrors", [
    ("", 8, 4),                                                     # 3 x 3: D4
    ("[array]\nrows = 4\ncolumns = 4\n", 8, 4),                     # 4 x 4: D4
    ("[array]\nrows = 2\ncolumns = 3\n", 4, 2),                     # 2 x 3: D2
    (HEX, 12, 6),                                                   # hexagonal: C6v
    (RING, 12, 6),                                                  # tilted ring of 6: C6v
    ('[array]\nlayout = "ring"\ncount = 5\nradius_m = 0.07\ntilt_deg = 20\n', 10, 5),  # C5v
    ('[array]\nlayout = "free"\npositions_m = [[0, 0, 0], [0.05, 0, 0], [0.01, 0.06, 0]]\n',
     1, 0),                                                          # nothing
])
def test_the_group_of_each_layout_is_found_from_its_poses(toml, order, mirrors):
    group = CoilArray.from_design(_design(toml)).symmetries()
    assert len(group) == order
    assert sum(not s.proper for s in group.elements) == mirrors
    # every element maps the coils (positions and axes) onto the coils it says
    arr = CoilArray.from_design(_design(toml))
    pos = arr.positions()
    axes = np.array([c.pose.matrix[:, 2] for c in arr.coils])
    for s in group.elements:
        np.testing.assert_allclose(group.apply(s, pos), pos[s.perm], atol=1e-12)
        np.testing.assert_allclose(axes @ s.g.T, axes[s.perm], atol=1e-12)


def test_a_group_coil_of_another_size_breaks_the_symmetry_it_would_have():
    # the hexagon with one outer coil rewound: only the mirror through it and the centre stays
    d = _design(HEX + '[[groups]]\ncoils = [1]\n[groups.coil]\nturns = 900\n')
    group = CoilArray.from_design(d).symmetries()
    assert len(group) == 2
    assert np.allclose(group.elements[1].g, np.diag([1.0, -1.0, 1.0]))


@pytest.mark.parametrize("toml", ["[array]\nrows = 2\ncolumns = 3\n", HEX])
def test_symmetric_solve_equals_the_plain_solve(toml):
    # the split LU, the blocks and columns taken from images against the dense LU of M
    # assembled without any symmetry: a symmetry used on a layout that lacks it, a turn of
    # the wrong core or R for R^T changes A by O(1)
    d = _design(toml)
    arr, ref = CoilArray.from_design(d), CoilArray.from_design(d)
    object.__setattr__(ref, "_system", ArraySystem(ref, symmetry="none"))
    assert len(arr.coupled().group) > 1 and len(ref.coupled().group) == 1
    pts = np.random.default_rng(1).uniform([-0.06, -0.05, 0.015], [0.06, 0.05, 0.08], (20, 3))
    a, b = arr.actuation_matrix(pts), ref.actuation_matrix(pts)
    scale = np.abs(b).max(axis=(0, 2))
    assert (np.abs(a - b).max(axis=(0, 2)) / scale).max() < 1e-11
    m = d.magnet.moment_vector_a_m2
    f, g = arr.bias_force(pts[:4], m), ref.bias_force(pts[:4], m)
    assert np.abs(f - g).max() < 1e-11 * np.abs(g).max()


def _random_layout(rng, n: int) -> tuple:
    """n thesis coils at random positions (30-60 mm apart in x, y) and random tilts up to 40
    degrees, each with a random spin about its axis, none meeting another."""
    d = _design("")
    base = Coil.of_design(d, 4)
    coils = []
    while len(coils) < n:
        tilt, az, spin = rng.uniform(0, math.radians(40)), rng.uniform(0, 2 * math.pi), \
            rng.uniform(0, 2 * math.pi)
        axis = np.array([math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az),
                         math.cos(tilt)])
        frame = Pose.from_axis((0, 0, 0), axis).matrix
        c, s = math.cos(spin), math.sin(spin)
        frame = frame @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        top = np.r_[rng.uniform(-0.06, 0.06, 2), rng.uniform(-0.01, 0.01)]
        coil = base.replace(pose=Pose.from_rotation(top - 0.05 * axis, frame))
        try:
            CoilArray(tuple(coils) + (coil,))
        except DesignRuleError:
            continue
        coils.append(coil)
    return tuple(coils)


def _moved(coils, rot, shift) -> tuple:
    return tuple(c.replace(pose=Pose.from_rotation(rot @ np.asarray(c.pose.position) + shift,
                                                   rot @ c.pose.matrix)) for c in coils)


@pytest.mark.parametrize("seed", [3, 4])
def test_rigid_motion_of_the_whole_device_rotates_the_coupled_solve(seed):
    # rotate and translate coils (tilted, random) and points together: B rows rotate as
    # vectors, gradient rows as tensors, F0 as a vector (moment rotated with them). A rotation
    # applied as R instead of R^T anywhere in the coupled solve (sources to a core's frame,
    # its field back) or a gradient turned as R G instead of R G R^T fails by O(1).
    rng = np.random.default_rng(seed)
    coils = _random_layout(rng, 3)
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    rot = q * np.sign(np.linalg.det(q))
    shift = rng.uniform(-0.2, 0.2, 3)
    a0, a1 = CoilArray(coils), CoilArray(_moved(coils, rot, shift))
    pts = np.r_[rng.uniform(-0.05, 0.05, (6, 2)).T, [rng.uniform(0.03, 0.07, 6)]].T
    m = np.array([0.1, -0.2, 0.9])
    ref, got = a0.actuation_matrix(pts), a1.actuation_matrix(pts @ rot.T + shift)
    b = np.einsum("ij,njk->nik", rot, ref[:, :3])
    g = gradient_from_g5(np.moveaxis(ref[:, 3:], 1, -1))  # (n, coils, 3, 3)
    g = np.einsum("ia,nkab,jb->nkij", rot, g, rot)
    want = np.concatenate([b, np.moveaxis(g[..., [0, 0, 0, 1, 1], [0, 1, 2, 1, 2]], -1, 1)], 1)
    scale = np.abs(want).max(axis=(0, 2), keepdims=True)
    assert np.abs(got - want).max(axis=(0, 2)).max() / scale.min() < 1e-9
    assert np.abs(got - ref).max() > 1e-2 * np.abs(ref).max()  # the rotation is not trivial
    f0 = a0.bias_force(pts[:2], m) @ rot.T
    f1 = a1.bias_force(pts[:2] @ rot.T + shift, rot @ m)
    assert np.abs(f1 - f0).max() < 1e-9 * np.abs(f0).max()


def test_a_tilted_ring_written_free_gives_the_ring_built_by_hand_and_by_its_generator():
    # the ring of 6 tilted 30 degrees as a generator, as a free layout (top centres and axes
    # written out) and built by hand with each coil spun about its axis: the same array, the
    # same group, the same A (the solve's frames are the group's, not the coils' own)
    ring = _design(RING)
    tops, axes = ring.array.top_centres_m(), ring.array.axes()
    free = _design('[array]\nlayout = "free"\npositions_m = '
                   f'{[list(map(float, t)) for t in tops]}\naxes = '
                   f'{[list(map(float, a)) for a in axes]}\n')
    c, k = ring.coil, ring.core
    core = Core(radius=k.radius_m, length=k.length_m, relative_permeability=k.relative_permeability,
                offset=k.offset_m, bh=k.bh, knee_t=k.saturation_t)
    spins = np.random.default_rng(2).uniform(0, 2 * math.pi, 6)
    hand = []
    for top, axis, spin in zip(tops, axes, spins):
        frame = Pose.from_axis((0, 0, 0), axis).matrix @ np.array(
            [[math.cos(spin), -math.sin(spin), 0], [math.sin(spin), math.cos(spin), 0],
             [0, 0, 1]])
        hand.append(Coil(c.inner_radius_m, c.outer_radius_m, c.length_m, c.turns, core,
                         Pose.from_rotation(top - axis * c.length_m / 2, frame)))
    arrays = [CoilArray.from_design(ring), CoilArray.from_design(free), CoilArray(tuple(hand))]
    assert [len(a.symmetries()) for a in arrays] == [12, 12, 12]
    pts = np.array([[0.0, 0.0, 0.03], [0.03, -0.02, 0.05], [-0.05, 0.04, 0.025]])
    a = [arr.actuation_matrix(pts) for arr in arrays]
    scale = np.abs(a[0]).max(axis=(0, 2)).min()
    assert np.abs(a[1] - a[0]).max() / scale < 1e-10
    assert np.abs(a[2] - a[0]).max() / scale < 1e-10


def test_coils_that_meet_are_refused_naming_the_layout_key_and_its_range():
    with pytest.raises(DesignRuleError, match=r"array.radius_m = 0.03 m at tilt_deg = 30.*"
                                              r"valid range: array.radius_m >= 0.03\d+ m") as exc:
        CoilArray.from_design(_design(RING.replace("0.075", "0.03")))
    # the smallest radius it names clears the coils, 2 % less does not
    need = float(str(exc.value).split(">= ")[1].split(" m")[0])
    CoilArray.from_design(_design(RING.replace("0.075", f"{need:.6g}")))
    with pytest.raises(DesignRuleError):
        CoilArray.from_design(_design(RING.replace("0.075", f"{0.98 * need:.6g}")))
    with pytest.raises(DesignRuleError, match=r"array.positions_m\[0\] = .* array.positions_m"
                                              r"\[1\] = \[0.03, 0.0, 0.0\]"):
        CoilArray.from_design(_design('[array]\nlayout = "free"\npositions_m = '
                                      '[[0, 0, 0], [0.03, 0, 0]]\n'))


def test_sensors_inside_iron_are_refused_naming_the_key_its_value_and_why():
    with pytest.raises(BadInputError, match=r"sensors.positions_m\[1\] must be a point outside "
                                            r"every coil's winding and core; instead received "
                                            r"\[0.0, 0.0, -0.01\]. It lies inside the core"):
        CoilArray.from_design(_design('[sensors]\nlayout = "free"\npositions_m = '
                                      '[[0, 0, 0.02], [0.0, 0, -0.01]]\n'))
    with pytest.raises(BadInputError, match=r"sensors.offset_m must be > 0.005 m"):
        CoilArray.from_design(_design("[sensors]\noffset_m = 0.003\n"))
    CoilArray.from_design(_design("[sensors]\noffset_m = 0.006\n"))


def test_saturation_correction_of_a_tilted_ring_and_of_groups():
    # the per-coil factor is its core type's single-core curve whatever the pose; the coupled
    # mid-plane flux per ampere follows the group: C[perm k, perm j] = C[k, j] for every
    # symmetry (a core's axis taken as +z instead of its own tilted axis breaks it: the flux
    # along z of a tilted core is cos 30 of its own); an air coil of a group has factor 1 and
    # no flux row
    steel = '[core]\nbh = "steel1010"\n'   # a linear core's model does not saturate
    ring = CoilArray.from_design(_design(RING + steel))
    upright = CoilArray.from_design(_design('[array]\nlayout = "ring"\ncount = 6\n'
                                            'radius_m = 0.075\n' + steel))
    cur = np.array([0.0, 3.0, 6.0])
    s, u = ring.saturation_correction(currents_a=cur), upright.saturation_correction(
        currents_a=cur)
    np.testing.assert_allclose(s["saturation_factor"], u["saturation_factor"])
    assert np.all(s["saturation_factor"][-1] < 1.0)  # the 1010 curve bends by 6 A
    c = s["core_flux_t_per_a"]
    for el in ring.symmetries().elements:
        np.testing.assert_allclose(c[np.ix_(el.perm, el.perm)], c, rtol=1e-9, atol=1e-12)
    # each core's own flux: its winding's own, to within the neighbours' coupling (a few %)
    assert np.allclose(np.diag(c), c[0, 0]) and 0.9 < c[0, 0] / u["core_flux_t_per_a"][0, 0] < 1.1
    mixed = CoilArray.from_design(_design(HEX + steel + '[[groups]]\ncoils = [0]\n'
                                                '[groups.core]\nenabled = false\n'))
    assert np.all(CoilArray.from_design(_design(HEX)).saturation_correction(
        currents_a=cur)["saturation_factor"] == 1.0)   # linear cores: factor 1
    m = mixed.saturation_correction(currents_a=cur)
    np.testing.assert_allclose(m["saturation_factor"][:, 0], 1.0)
    np.testing.assert_array_equal(m["core_flux_t_per_a"][0], 0.0)
    assert np.all(m["saturation_factor"][-1, 1:] < 1.0)
