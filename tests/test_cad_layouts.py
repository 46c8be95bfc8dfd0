"""cad/ for any layout: tilted seats, standoffs clear of the coils, segmented plates, sensor caps,
placements in each coil's frame, and the acceptance designs exported and mesh-checked.

Independent references: the tilted plate's thickness and the cap's height worked out by hand
from the design's numbers; the cap's volume in closed form; the six segments of a plate
against the plate built whole; the written meshes read back by cad.meshcheck.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cad import meshcheck
from cad import parts as P
from cad.assembly import placements, quantities
from cad.export import section_plane
from cad.params import fit_in_build_volume, from_design, segment_outline
from designkit.cli import main
from designkit.design import default_design, load_design

LAYOUTS = Path(__file__).parent / "data" / "layouts"


@pytest.fixture(scope="module")
def ring():
    return from_design(load_design(LAYOUTS / "ring6_tilt30.toml"))


def test_a_tilted_ring_gets_tilted_seats_in_a_plate_thick_enough(ring):
    t = math.radians(30)
    for s in ring.upper.seats:
        axis = np.asarray(s.rotation)[:, 2]
        assert axis[2] == pytest.approx(math.cos(t))  # each seat along its coil's axis
    # 6 mm of plate along the axis above the pocket's rim where the tilt lifts it most:
    # 6 cos 30 + 20.8 sin 30 mm (pocket = 19 + 1.5 lip + 0.3 clearance)
    assert (ring.upper.z0_mm, ring.upper.z1_mm) == pytest.approx(
        (0.0, 6 * math.cos(t) + 20.8 * math.sin(t)))
    # the lower plate holds the bottoms, 100 cos 30 mm down
    assert ring.lower.z1_mm == pytest.approx(-100 * math.cos(t))
    assert ring.standoff.length_mm == pytest.approx(100 * math.cos(t))


def test_standoffs_stand_between_the_coils_and_every_plate_piece_fits_the_printer(ring):
    # the corners of the upper plate lie outside the coil tops, where the tilted coils lean
    # out below; the standoffs go to the edge midpoints, between the coils (30 deg off them)
    ang = sorted(round(math.degrees(math.atan2(y, x)) % 60, 6) for x, y in ring.fixing_xy_mm)
    assert ang == pytest.approx([30.0] * 6)
    assert ring.lower.segments_identical and len(ring.lower.segments) == 6
    assert not ring.upper.segments
    build = ring.printer.build_volume_mm
    outline = np.asarray(ring.lower.outline_mm)
    whole = (np.ptp(outline[:, 0]), np.ptp(outline[:, 1]), ring.lower.thickness_mm)
    assert fit_in_build_volume(whole, build) is None  # why it is cut
    for seg in ring.lower.segments:
        piece = segment_outline(outline, ring.lower.centre_xy_mm, seg)
        assert fit_in_build_volume((np.ptp(piece[:, 0]), np.ptp(piece[:, 1]),
                                    ring.lower.thickness_mm), build) is not None
    assert quantities(ring)["frame_lower_segment"] == 6


def test_caps_hold_the_tilted_boards_and_have_the_closed_form_volume(ring):
    cap = ring.types[0].cap_upper
    # from the core top (5 mm above the winding) to the board's outer face (14 + 0.8 mm)
    assert cap.height_mm == pytest.approx(14.8 - 5.0)
    assert cap.radius_mm == pytest.approx(12.15 - 0.05)
    assert quantities(ring)["sensor_cap"] == 12
    part = P.sensor_cap(cap)
    assert part.is_valid
    assert part.volume == pytest.approx(P.sensor_cap_volume_mm3(cap), rel=1e-9)


def test_each_coils_parts_are_placed_in_its_frame(ring):
    d = load_design(LAYOUTS / "ring6_tilt30.toml")
    tops, axes = d.array.top_centres_m() * 1e3, d.array.axes()
    flanges = [pl for pl in placements(ring) if pl.part == "bobbin_flange"]
    top_flanges = flanges[0::2]
    for k, pl in enumerate(top_flanges):
        np.testing.assert_allclose(pl.offset_mm, tops[k], atol=1e-9)
        np.testing.assert_allclose(pl.matrix()[:3, 2], axes[k], atol=1e-12)
    # the bottom flange: turned over, 100 mm down the axis
    bottom = flanges[1]
    np.testing.assert_allclose(bottom.offset_mm, tops[0] - 100 * axes[0], atol=1e-9)
    np.testing.assert_allclose(bottom.matrix()[:3, 2], -axes[0], atol=1e-12)


def test_segments_make_up_the_whole_plate(ring):
    whole = P.frame_plate(ring.lower)
    piece = P.frame_plate(ring.lower, 0)
    assert whole.is_valid and piece.is_valid
    assert 6 * piece.volume == pytest.approx(whole.volume, rel=1e-9)


def test_the_picture_cuts_through_the_magnet_and_its_nearest_coil(ring):
    origin, normal, k = section_plane(from_design(default_design()))
    assert k == 4 and np.allclose(normal, (0, 1, 0))  # the thesis array: y = 0, centre coil
    origin, normal, k = section_plane(ring)
    assert k == 0 and np.allclose(normal, (0, 1, 0))  # the first of six at equal distance
    grid = from_design(load_design(LAYOUTS / "grid4x4.toml"))
    origin, normal, k = section_plane(grid)
    top = np.asarray(grid.coil_frames[k][0])
    # no coil lies under the design point: the plane holds the nearest one's axis
    assert abs((top - origin) @ normal) < 1e-9 and np.hypot(*top[:2]) == pytest.approx(
        25 * math.sqrt(2))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["grid4x4", "air2x3", "hex7", "ring6_tilt30"])
def test_cad_exports_the_acceptance_designs(name, tmp_path):
    """Acceptance: ``cad`` exits 0 on the four layouts; every written mesh is closed,
    manifold and of positive volume (cad checks the bytes itself; this reads them again)."""
    out = tmp_path / name
    assert main(["cad", "--design", str(LAYOUTS / f"{name}.toml"), "--out", str(out),
                 "--format", "stl", "--no-progress"]) == 0
    assert (out / "assembly.png").stat().st_size > 0
    for stl in out.glob("*.stl"):
        rep = meshcheck.mesh_report(*meshcheck.read_stl(stl))
        assert rep.watertight and rep.manifold and rep.volume > 0, stl.name
