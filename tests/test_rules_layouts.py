"""The rule book on any layout (designkit.rules, ``designkit check``): clearances as signed
distances of the coils' solids in their poses, per coil type, sensor boards, the magnet's floor.

Independent references: closed forms of the distance of two cylinders (parallel, crossed,
stacked) and of two boxes; a dense sampling of the two solids' surfaces (an upper bound of
their distance, within its spacing); the highest corner of a tilted part worked out by hand.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from designkit import rules
from designkit.cli import main
from designkit.design import design_from_dict, load_design
from designkit.rules.convex import Box, Cylinder, signed_distance

LAYOUTS = Path(__file__).parent / "data" / "layouts"


def _surface(c: Cylinder, n: int = 160) -> np.ndarray:
    """Points on a cylinder's surface (side and both ends), m."""
    u = np.asarray(c.axis)
    e1 = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    phi = np.linspace(0, 2 * np.pi, n, endpoint=False)
    z = np.linspace(-c.half_length_m, c.half_length_m, n)
    P, Z = np.meshgrid(phi, z)
    side = (np.asarray(c.centre) + Z.ravel()[:, None] * u
            + c.radius_m * (np.cos(P).ravel()[:, None] * e1 + np.sin(P).ravel()[:, None] * e2))
    R, P = np.meshgrid(np.linspace(0, c.radius_m, n // 4), phi)
    disc = R.ravel()[:, None] * (np.cos(P).ravel()[:, None] * e1
                                 + np.sin(P).ravel()[:, None] * e2)
    ends = [np.asarray(c.centre) + s * c.half_length_m * u + disc for s in (-1, 1)]
    return np.vstack([side] + ends)


def _sampled_distance(a: Cylinder, b: Cylinder, near_m: float, n: int = 160) -> float:
    """The smallest distance between the two sampled surfaces (looked for up to 5 mm beyond
    ``near_m``), m."""
    d = cKDTree(_surface(b, n)).query(_surface(a, n), distance_upper_bound=near_m + 0.005)[0]
    return float(d.min())


# -- the signed distance against closed forms --------------------------------------------------
def test_distance_of_cylinders_and_boxes_matches_closed_forms():
    # crossed axes (x at z = 0, y at z = 50 mm): the gap is 50 mm less both radii, not the
    # distance of the centres
    a = Cylinder((0, 0, 0), (1, 0, 0), 0.5, 0.01)
    b = Cylinder((0, 0, 0.05), (0, 1, 0), 0.5, 0.02)
    assert signed_distance(a, b) == pytest.approx(0.02, abs=1e-11)
    # parallel, side by side: the pitch less two radii; stacked on one axis: the end gap
    up = Cylinder((0, 0, 0), (0, 0, 1), 0.05, 0.019)
    assert signed_distance(up, Cylinder((0.05, 0, 0.01), (0, 0, 1), 0.05, 0.019)) == \
        pytest.approx(0.012, abs=1e-15)
    assert signed_distance(up, Cylinder((0, 0, 0.11), (0, 0, -1), 0.05, 0.01)) == \
        pytest.approx(0.01, abs=1e-15)
    # crossing through each other: minus the smallest move apart (sideways 19 + 10 mm)
    assert signed_distance(up, Cylinder((0, 0, 0), (1, 0, 0), 0.1, 0.01)) == \
        pytest.approx(-0.029, abs=1e-9)
    # two boxes, offset diagonally: the gap between their nearest corners
    eye = ((1, 0, 0), (0, 1, 0), (0, 0, 1))
    b1, b2 = Box((0, 0, 0), eye, (0.01, 0.01, 0.001)), Box((0.03, 0.04, 0), eye,
                                                            (0.01, 0.01, 0.001))
    assert signed_distance(b1, b2) == pytest.approx(math.hypot(0.01, 0.02), abs=1e-12)


def test_distance_of_tilted_cylinders_matches_a_dense_sampling():
    """Random tilted pairs apart: the distance is at most the sampled surfaces' (an upper
    bound) and not below it by more than the sampling's spacing (a capsule's or the
    centres' distance is wrong by millimetres here)."""
    rng = np.random.default_rng(5)
    checked = 0
    while checked < 6:
        axes = rng.normal(size=(2, 3))
        axes /= np.linalg.norm(axes, axis=1)[:, None]
        a = Cylinder((0, 0, 0), tuple(axes[0]), 0.03, 0.012)
        b = Cylinder(tuple(rng.uniform(-0.07, 0.07, 3)), tuple(axes[1]), 0.04, 0.015)
        d = signed_distance(a, b)
        if d <= 0.002:
            continue
        sampled = _sampled_distance(a, b, d)
        assert d <= sampled + 1e-12
        assert d >= sampled - 1.2e-3  # the samples' spacing (2 pi r / 160 and 2 h / 160)
        checked += 1


# -- clearances of tilted coils ------------------------------------------------------------------
def _pair(distance_m: float, tilt_deg: float):
    """Two coils whose top faces are ``distance_m`` apart on x, each axis tilted by
    ``tilt_deg`` towards the other's top (positive: the tops lean together, the bodies apart)."""
    t = math.radians(tilt_deg)
    return design_from_dict({"array": {
        "layout": "free", "positions_m": [[-distance_m / 2, 0, 0], [distance_m / 2, 0, 0]],
        "axes": [[math.sin(t), 0, math.cos(t)], [-math.sin(t), 0, math.cos(t)]]}})


def test_a_tilted_pair_is_judged_in_its_poses_not_as_upright_coils():
    """Tops 1 mm closer than two winding radii overlap when upright, but tilted 30 degrees so
    that the bodies lean apart they clear each other (and the reverse); a rule that checked
    them upright, or by their centres, gets both wrong."""
    ro = 0.019
    together = {r.name: r for r in rules.rules(_pair(2 * ro - 0.001, 30.0))}["coils_overlap"]
    apart = {r.name: r for r in rules.rules(_pair(2 * ro + 0.001, -30.0))}["coils_overlap"]
    upright = {r.name: r for r in rules.rules(_pair(2 * ro - 0.001, 0.0))}["coils_overlap"]
    assert not upright.met and upright.limit == pytest.approx(2 * ro - 0.001, abs=1e-12)
    assert together.met and not apart.met
    # the limit is the closest distance of the two windings plus their radii: by sampling
    d = _pair(2 * ro - 0.001, 30.0)
    w = [rules.coil_solid(d, rules.assembly(d).types[0], k, "winding") for k in (0, 1)]
    sampled = _sampled_distance(w[0], w[1], together.limit - together.value, 240)
    assert together.limit - together.value == pytest.approx(sampled, abs=6e-4)
    assert "array.positions_m" in together.keys and "array.axes" in together.keys


def test_the_ring_of_tilted_coils_is_checked_and_its_rows_name_the_ring_keys():
    d = load_design(LAYOUTS / "ring6_tilt30.toml")
    table = {r.name: r for r in rules.rules(d)}
    for name in ("coils_overlap", "flanges_overlap", "frame_web", "standoff_to_pocket",
                 "seat_overhang", "sensor_board_to_coils", "sensor_cap_wall"):
        assert table[name].met, table[name].message
    assert table["seat_overhang"].value == pytest.approx(30.0)
    assert "array.radius_m" in table["frame_web"].keys
    # neighbours' top faces are 75 mm apart; the windings lean apart below: the windings'
    # spacing is at least that less the top rims' tilt (a few mm), never the bodies' far ends
    assert 0.075 - 0.002 < table["coils_overlap"].limit < 0.08
    # tilted 50 degrees: the printed seats overhang beyond what the printer makes
    steep = dataclasses.replace(d, array=dataclasses.replace(d.array, tilt_deg=50.0))
    bad = {r.name: r for r in rules.violations(steep)}
    assert "seat_overhang" in bad and bad["seat_overhang"].keys == ("array.tilt_deg",)


def test_the_magnet_floor_follows_tilted_boards_and_caps():
    """Upright boards: board top + half the magnet (14.8 + 5 mm). A ring tilted 30 degrees:
    its sensor caps (bore radius less the press fit, up to the board's outer face 14.8 mm
    along the axis) lean into the workspace; their highest rim point, by hand, is
    14.8 cos 30 + 12.1 sin 30 mm, and the floor is that + 5 mm (+ the 24-gon's < 1 %)."""
    assert rules.reachable_height_m(load_design(LAYOUTS / "hex7.toml")) == \
        pytest.approx(0.0198, abs=1e-12)
    d = load_design(LAYOUTS / "ring6_tilt30.toml")
    r_cap = 0.012 + 0.00015 - 0.00005
    hand = 0.0148 * math.cos(math.radians(30)) + r_cap * math.sin(math.radians(30)) + 0.005
    floor = rules.reachable_height_m(d)
    assert hand <= floor <= hand + r_cap * 0.01
    row = {r.name: r for r in rules.rules(d)}["workspace_z_min_m"]
    assert not row.met and row.limit == floor and "workspace.z_min_m" in row.keys


def test_rules_per_coil_type_name_the_groups_keys():
    d = design_from_dict({
        "array": {"layout": "hex", "rings": 1, "pitch_m": 0.044},
        "groups": [{"coils": [0], "coil": {"outer_radius_m": 0.017, "turns": 1000},
                    "core": {"enabled": False}}]})
    table = {r.name: r for r in rules.rules(d)}
    turns = table["turns@groups[0]"]
    # the group's own winding: 1000 turns in 5 mm x 100 mm of 0.7 mm wire (7 x 142 = 994)
    assert turns.value == 1000 and turns.limit == 994 and not turns.met
    assert turns.keys[0] == "groups[0].coil.turns"
    assert table["turns"].value == 1429  # the other six coils: the design's [coil]
    assert table["bobbin_tube_wall@groups[0]"].value == pytest.approx(0.0012)
    # the air coil's clearance to its cored neighbours uses its own radius (17 mm)
    assert table["coils_overlap"].value == pytest.approx(0.019 + 0.019)


def test_a_sensor_in_a_coils_iron_is_a_violated_rule():
    d = design_from_dict({"array": {"rows": 1, "columns": 2},
                          "sensors": {"layout": "free",
                                      "positions_m": [[0.0, 0.0, 0.02], [0.025, 0.0, -0.05]]}})
    row = {r.name: r for r in rules.rules(d)}["sensor_board_to_coils"]
    assert not row.met and row.value < -0.005 and "sensors.positions_m" in row.keys


# -- designkit check: exit codes ----------------------------------------------------------------
def test_check_exit_codes(tmp_path, capsys):
    assert main(["check", "--design", "optimized"]) == 0
    assert main(["check", "--design", str(LAYOUTS / "hex7.toml")]) == 3  # the thesis coil
    out = capsys.readouterr().out
    assert "resistance_ohm" in out and "VIOLATED" in out
    bad = tmp_path / "bad.toml"
    bad.write_text('[array]\nlayout = "ring"\ncount = 6\npitch_m = 0.05\n')
    assert main(["check", "--design", str(bad)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "pitch_m" in err and "ring" in err
    assert main(["check", "--design", str(tmp_path / "missing.toml")]) == 1


@pytest.mark.slow
@pytest.mark.parametrize("name", ["grid4x4", "air2x3", "hex7", "ring6_tilt30"])
def test_check_runs_on_the_acceptance_designs(name, capsys):
    """The thesis coil breaks its electrical limits on every layout (R, I R, 5 L/R, turns:
    exit 3); the ring's tilted caps also lift the magnet's floor above workspace.z_min_m.
    No cad rule is broken."""
    assert main(["check", "--design", str(LAYOUTS / f"{name}.toml")]) == 3
    out = capsys.readouterr().out
    assert "buildable by designkit cad: yes" in out and "turns" in out
