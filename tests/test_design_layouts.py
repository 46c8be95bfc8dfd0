"""Layouts in the design file (designkit.design.layouts): each generator's poses from its own
geometry, the design file's keys, the free form against coils built by hand."""

import math
import tomllib

import numpy as np
import pytest

from designkit import Coil, CoilArray, Pose
from designkit.cores import Core
from designkit.design import (Design, FreeLayout, GridLayout, HexLayout, RingLayout,
                              design_from_dict, design_to_toml, load_design)
from designkit.errors import BadInputError

AIR = {"core": {"enabled": False}}


def _design(toml: str) -> Design:
    return design_from_dict(tomllib.loads(toml))


def test_grid_is_the_thesis_array_row_major():
    d = Design()
    tops = d.array.top_centres_m()
    # row-major from the +y row, x increasing: the thesis' coil numbering
    assert tops[0].tolist() == [-0.05, 0.05, 0.0] and tops[4].tolist() == [0.0, 0.0, 0.0]
    assert tops[8].tolist() == [0.05, -0.05, 0.0]
    assert [p.position for p in d.coil_poses()][4] == (0.0, 0.0, -0.05)
    assert all(p.is_identity_rotation for p in d.coil_poses())
    lo, hi = d.workspace_region().bounds_m()
    assert lo.tolist() == [-0.075, -0.075, 0.02] and hi.tolist() == [0.075, 0.075, 0.08]


@pytest.mark.parametrize("rings, count", [(0, 1), (1, 7), (2, 19), (3, 37)])
def test_hex_rings_have_six_neighbours_at_one_pitch(rings, count):
    lay = HexLayout(rings=rings, pitch_m=0.044)
    xy = lay.top_centres_m()[:, :2]
    assert len(xy) == count == 1 + 3 * rings * (rings + 1)
    d = np.linalg.norm(xy[:, None] - xy[None], axis=-1)
    np.fill_diagonal(d, np.inf)
    if rings:
        assert d.min() == pytest.approx(0.044, abs=1e-15)
        # the centre coil has exactly six neighbours at one pitch
        assert np.sum(np.isclose(d[0], 0.044)) == 6
        # the k-th ring lies on a hexagon: distances from the centre between k cos30 and k pitch
        r = np.linalg.norm(xy, axis=1)
        assert r.max() == pytest.approx(rings * 0.044)


@pytest.mark.parametrize("tilt", [0.0, 15.0, 30.0, 60.0])
def test_ring_axes_lean_inwards_and_meet_above_the_centre(tilt):
    lay = RingLayout(count=6, radius_m=0.075, tilt_deg=tilt)
    tops, axes = lay.top_centres_m(), lay.axes()
    assert np.allclose(np.linalg.norm(tops[:, :2], axis=1), 0.075)
    assert np.allclose(np.linalg.norm(axes, axis=1), 1.0)
    # each axis makes tilt with +z and leans towards the array axis (inwards)
    assert np.allclose(np.degrees(np.arccos(axes[:, 2])), tilt)
    if tilt:
        assert np.all(np.einsum("ij,ij->i", axes[:, :2], tops[:, :2]) < 0)
        # every axis passes through (0, 0, R / tan(tilt))
        apex = np.array([0.0, 0.0, 0.075 / math.tan(math.radians(tilt))])
        s = (apex[2] - tops[:, 2]) / axes[:, 2]
        assert np.allclose(tops + s[:, None] * axes, apex, atol=1e-12)


def test_layout_keys_from_the_design_file():
    d = _design('[array]\nlayout = "ring"\ncount = 6\nradius_m = 0.075\ntilt_deg = 30\n')
    assert isinstance(d.array, RingLayout) and d.n_coils == 6
    assert d.array.tilt_deg == 30
    h = _design('[array]\nlayout = "hex"\nrings = 2\npitch_m = 0.044\n')
    assert h.n_coils == 19
    with pytest.raises(BadInputError, match="rows.*belongs to layout 'grid'"):
        _design('[array]\nlayout = "hex"\nrings = 1\nrows = 3\n')
    with pytest.raises(BadInputError, match="array.layout"):
        _design('[array]\nlayout = "spiral"\n')
    with pytest.raises(BadInputError, match="array.tilt_deg"):
        _design('[array]\nlayout = "ring"\ntilt_deg = 95\n')


def test_free_axes_must_be_unit_vectors_and_the_hint_gives_the_unit_vector():
    with pytest.raises(BadInputError, match=r"array.axes\[1\].*Did you mean \[0.0, 0.6, 0.8\]"):
        _design('[array]\nlayout = "free"\npositions_m = [[0, 0, 0], [0.06, 0, 0]]\n'
                'axes = [[0, 0, 1], [0, 3, 4]]\n')
    with pytest.raises(BadInputError, match="array.axes"):
        _design('[array]\nlayout = "free"\npositions_m = [[0, 0, 0]]\naxes = [[0, 0, 1], '
                '[0, 0, 1]]\n')


def test_free_layout_gives_the_same_actuation_matrix_as_coils_built_by_hand():
    # two coils, one tilted 30 degrees about x, the design's winding and core
    tilt = math.radians(30.0)
    axis = (0.0, -math.sin(tilt), math.cos(tilt))
    d = _design('[array]\nlayout = "free"\npositions_m = [[0, 0, 0], [0, 0.06, 0.01]]\n'
                f'axes = [[0, 0, 1], [0, {axis[1]!r}, {axis[2]!r}]]\n')
    c, k = d.coil, d.core
    core = Core(radius=k.radius_m, length=k.length_m, relative_permeability=k.relative_permeability,
                offset=k.offset_m, bh=k.bh, knee_t=k.saturation_t)
    half = c.length_m / 2
    by_hand = CoilArray((
        Coil(c.inner_radius_m, c.outer_radius_m, c.length_m, c.turns, core,
             Pose((0.0, 0.0, -half))),
        Coil(c.inner_radius_m, c.outer_radius_m, c.length_m, c.turns, core,
             Pose.from_axis((0.0, 0.06 - half * axis[1], 0.01 - half * axis[2]), axis))))
    pts = np.array([[0.0, 0.0, 0.03], [0.02, 0.03, 0.05], [-0.03, 0.07, 0.08]])
    a_file = CoilArray.from_design(d).actuation_matrix(pts)
    a_hand = by_hand.actuation_matrix(pts)
    scale = np.abs(a_hand).max(axis=(0, 2), keepdims=True)
    assert np.abs(a_file - a_hand).max() / scale.min() < 1e-9


def test_groups_give_coils_their_own_winding_and_core():
    d = _design('[array]\nrows = 1\ncolumns = 3\n[[groups]]\ncoils = [0]\n[groups.coil]\n'
                'turns = 700\n[groups.core]\nenabled = false\n[[groups]]\ncoils = [2]\n'
                '[groups.core]\nrelative_permeability = 300.0\n')
    arr = CoilArray.from_design(d)
    assert [c.turns for c in arr.coils] == [700, 1429, 1429]
    assert arr.coils[0].core is None and arr.coils[1].core.relative_permeability == 1000.0
    assert arr.coils[2].core.relative_permeability == 300.0
    # a group's coil field is its own: coil 0 has half the turns and no core -> much weaker
    p = np.array([[-0.05, 0.0, 0.03]])
    b0 = arr.coils[0].field(p - [[0.0, 0.0, 0.0]], 1.0)[0, 2]
    b1 = arr.coils[1].moved((-0.05, 0.0, -0.05)).field(p, 1.0)[0, 2]
    assert 0 < b0 < 0.2 * b1
    with pytest.raises(BadInputError, match=r"groups\[1\].coils"):
        _design('[[groups]]\ncoils = [0]\n[[groups]]\ncoils = [0]\n')
    with pytest.raises(BadInputError, match=r"groups\[0\].coils"):
        _design('[[groups]]\ncoils = [9]\n')


@pytest.mark.parametrize("toml", [
    '[array]\nlayout = "hex"\nrings = 1\npitch_m = 0.044\n',
    '[array]\nlayout = "ring"\ncount = 6\nradius_m = 0.075\ntilt_deg = 30\n',
    '[array]\nlayout = "free"\npositions_m = [[0, 0, 0], [0.06, 0, 0]]\n'
    'axes = [[0, 0, 1], [0, 0.6, 0.8]]\n[sensors]\nlayout = "free"\n'
    'positions_m = [[0, 0, 0.014], [0.06, 0, 0.02]]\n',
    '[array]\nrows = 1\ncolumns = 2\n[[groups]]\ncoils = [1]\n[groups.coil]\nturns = 900\n'
    '[workspace]\nshape = "disc"\nradius_m = 0.05\n',
])
def test_every_layout_round_trips_through_toml(tmp_path, toml):
    d = _design(toml)
    f = tmp_path / "d.toml"
    f.write_text(design_to_toml(d))
    again = load_design(f)
    assert again == d and again.spec_hash() == d.spec_hash()


def test_sensor_layouts():
    d = Design(array=RingLayout(count=4, radius_m=0.06, tilt_deg=20.0))
    pos, rot = d.sensor_poses()
    assert pos.shape == (8, 3) and rot.shape == (8, 3, 3)
    # each upper sensor on its coil's axis, offset above the top face; its frame the coil's
    tops, axes = d.array.top_centres_m(), d.array.axes()
    assert np.allclose(pos[:4], tops + 0.014 * axes)
    assert np.allclose(rot[:4, :, 2], axes)
    free = _design('[sensors]\nlayout = "free"\npositions_m = [[0, 0, 0.02], [0.01, 0, 0.02]]\n')
    assert free.sensor_poses()[0].shape == (2, 3)
    assert np.allclose(free.sensor_poses()[1], np.eye(3))
    with pytest.raises(BadInputError, match="sensors.positions_m"):
        _design('[sensors]\npositions_m = [[0, 0, 0.02]]\n')
    with pytest.raises(BadInputError, match=r"sensors.rotations\[0\]"):
        _design('[sensors]\nlayout = "free"\npositions_m = [[0, 0, 0.02]]\n'
                'rotations = [[[1, 0, 0], [0, 1, 0], [0, 0, -1]]]\n')


def test_workspace_follows_the_layout():
    hexd = Design(array=HexLayout(rings=1, pitch_m=0.044))
    ws = hexd.workspace_region()
    # half a pitch beyond the outer coils, a hexagon: the outer axes lie inside, a point past
    # the hexagon does not
    assert ws.contains(np.c_[hexd.array.top_centres_m()[:, :2], np.full(7, 0.03)]).all()
    assert not ws.contains([[0.0, 0.044 * 1.5 + 0.005, 0.03]])[0]
    box = _design('[workspace]\nhalf_width_m = 0.05\n')
    assert box.workspace.shape == "box" and box.workspace_region().half_width_m() == 0.05
    # in Python too: a half width given means the box
    assert Design().replace(**{"workspace.half_width_m": 0.03}).workspace_region().bounds_m()[
        1].tolist() == [0.03, 0.03, 0.08]
    grid = Design(array=GridLayout(rows=4, columns=4, pitch_m=0.05))
    assert grid.workspace_region().half_width_m() == pytest.approx(0.1)
    one = Design(array=FreeLayout(positions_m=((0.0, 0.0, 0.0),)))
    assert one.workspace_region().half_width_m() == pytest.approx(0.025)


def test_more_sensors_than_the_sensor_bus_addresses_are_refused():
    # the default bus: TCA9548A muxes 0x71..0x77, 8 channels each = 56 sensors; a hex of 3 rings
    # (37 coils, 74 sensors above and below) is refused at load, naming the count and the limit
    from firmware_io.errors import InputRangeError
    from firmware_io.hw.sensors import MAX_SENSORS, default_sensor_layout

    assert MAX_SENSORS == 56 and len(default_sensor_layout(56)) == 56
    with pytest.raises(BadInputError, match=r"sensors.layout .*at most 28 coils.*37 coils "
                                            r"\(74 sensors\)"):
        _design('[array]\nlayout = "hex"\nrings = 3\npitch_m = 0.044\n')
    _design('[array]\nlayout = "ring"\ncount = 28\nradius_m = 0.3\n')   # 56 sensors: fits
    free = [[0.01 * k, 0.0, 0.05] for k in range(57)]
    with pytest.raises(BadInputError, match=r"sensors.positions_m .*at most 56.*57 sensors"):
        _design(f'[sensors]\nlayout = "free"\npositions_m = {free}\n')
    with pytest.raises(InputRangeError, match="n_sensors"):   # firmware_io's own error
        default_sensor_layout(57)
