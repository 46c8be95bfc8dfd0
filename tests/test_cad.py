"""cad/: parameters from the design, exact part volumes, design rules, checked export, CLI."""

from __future__ import annotations

import dataclasses
import json
import math
import struct

import numpy as np
import pytest
from scipy.integrate import quad

from designkit.design import default_design
from designkit.errors import BadInputError, DesignRuleError

from cad import meshcheck
from cad.params import from_design
from cad.rules import check_rules, fit_in_build_volume, violations

import build123d  # noqa: E402,F401  (a required dependency: no skip)
from cad import parts as P  # noqa: E402  (needs build123d)
from cad.assembly import build_part, interferences, part_names, quantities  # noqa: E402

pi = math.pi


@pytest.fixture(scope="module")
def params():
    return from_design(default_design())


# -- the one SI -> mm conversion -------------------------------------------------------------
def test_params_follow_the_thesis_design(params):
    # thesis 2.2/2.3/3.2.1: 24/38 mm winding, 100 mm long, 110 mm core, 3x3 at 50 mm, 14 mm sensors
    b = params.bobbin
    assert (b.winding_inner_radius_mm, b.winding_outer_radius_mm, b.winding_length_mm) == \
        pytest.approx((12.0, 19.0, 100.0))
    assert params.core.length_mm == pytest.approx(110.0)
    assert params.core.top_z_mm == pytest.approx(5.0)  # protrudes 5 mm beyond each end
    outline = np.asarray(params.upper.outline_mm)
    assert np.ptp(outline[:, 0]) == pytest.approx(150.0)
    xs = sorted({round(top[0], 9) for top, _ in params.coil_frames})
    assert xs == pytest.approx([-50.0, 0.0, 50.0])
    assert params.sensor_mount.sensor_z_mm == pytest.approx(14.0)
    # the design's core fills the 24 mm bore: no room for a printed tube -> wound on the core
    assert b.mandrel == "core"
    assert quantities(params)["bobbin_flange"] == 18


def test_default_design_passes_every_rule(params):
    assert violations(params) == []


# -- exact volumes against closed forms --------------------------------------------------------
def test_slot_area_matches_quadrature():
    a, r, w = 12.15, 20.5, 1.8
    numeric, _ = quad(lambda y: math.sqrt(r * r - y * y) - math.sqrt(a * a - y * y), -w / 2, w / 2,
                      epsabs=1e-13)
    assert P.slot_area_mm2(a, r, w) == pytest.approx(numeric, rel=1e-12)


def test_core_and_standoff_volumes(params):
    assert P.core(params.core).volume == pytest.approx(pi * 12.0**2 * 110.0, rel=1e-9)
    s = params.standoff
    assert P.standoff(s).volume == pytest.approx(pi * (4.0**2 - 1.7**2) * 100.0, rel=1e-9)


def test_flange_volume(params):
    b = params.bobbin
    slot, _ = quad(lambda y: math.sqrt(b.flange_radius_mm**2 - y * y)
                   - math.sqrt(b.bore_radius_mm**2 - y * y), -b.slot_width_mm / 2, b.slot_width_mm / 2)
    exact = b.flange_thickness_mm * (pi * (b.flange_radius_mm**2 - b.bore_radius_mm**2) - slot)
    part = P.bobbin_flange(b)
    assert part.is_valid
    assert part.volume == pytest.approx(exact, rel=1e-9)


def test_printed_tube_bobbin_volume():
    design = default_design().replace(**{"core.radius_m": 0.010})
    p = from_design(design)
    b = p.bobbin
    assert b.mandrel == "printed_tube" and b.tube_wall_mm == pytest.approx(12 - 10.15)
    L, t = 100.0, 2.0
    slot = P.slot_area_mm2(12.0, 20.5, b.slot_width_mm)
    exact = pi * (12.0**2 - 10.15**2) * (L + 2 * t) + 2 * t * (pi * (20.5**2 - 12.0**2) - slot)
    part = P.bobbin(b)
    assert len(part.solids()) == 1
    assert part.volume == pytest.approx(exact, rel=1e-9)


def test_frame_plate_volume(params):
    f = params.upper
    T, d = f.thickness_mm, f.seats[0].pocket_depth_mm
    rp, rt = f.seats[0].pocket_radius_mm, f.seats[0].through_radius_mm
    exact = (150.0 * 150.0 * T - 9 * (pi * rp**2 * d + pi * rt**2 * (T - d))
             - 4 * pi * f.fixing_hole_radius_mm**2 * T)
    assert T == pytest.approx(6.0)
    for plate in (params.upper, params.lower):
        assert P.frame_plate(plate).volume == pytest.approx(exact, rel=1e-9)
    lower = P.frame_plate(params.lower).bounding_box()
    assert (lower.min.Z, lower.max.Z) == pytest.approx((-106.0, -100.0))


def test_sensor_mount_volume(params):
    s = params.sensor_mount
    top, bottom = s.top_z_mm, s.bottom_z_mm
    bx = s.board_size_mm[0] + 2 * s.pocket_clearance_mm
    by = s.board_size_mm[1] + 2 * s.pocket_clearance_mm
    cw, hx = s.channel_width_mm, 75.0
    leg_h = bottom - s.leg_bottom_z_mm
    removed_per_row = 3 * bx * by + (hx - (-50.0)) * cw - (bx / 2 + 2 * bx) * cw  # channel minus overlaps
    exact = (150.0 * 150.0 * (top - bottom) - 3 * removed_per_row * s.board_thickness_mm
             + 4 * pi * s.leg_outer_radius_mm**2 * leg_h
             - 4 * pi * s.fixing_hole_radius_mm**2 * (top - s.leg_bottom_z_mm))
    for side in ("upper", "lower"):
        assert P.sensor_mount(s, side).volume == pytest.approx(exact, rel=1e-9)


def test_magnet_holder_pocket_fits_magnet(params):
    h = params.magnet_holder
    holder, magnet = P.magnet_holder(h), P.magnet(h)
    assert magnet.volume == pytest.approx(pi * 5.0**2 * 10.0, rel=1e-9)
    # the magnet sits in the pocket without sharing volume; the pocket is 0.05 mm bigger
    common = holder & magnet
    assert (common.volume if common is not None else 0.0) < 1e-6
    # same boss, pocket exactly the magnet's size: the difference is the clearance annulus
    snug = dataclasses.replace(h, press_fit_clearance_mm=0.0, boss_wall_mm=h.boss_wall_mm + 0.05)
    removed = P.magnet_holder(snug).volume - holder.volume
    assert removed == pytest.approx(pi * (5.05**2 - 5.0**2) * 10.0, rel=1e-6)


def test_outer_radius_changes_flange_and_frame_pocket(params):
    wider = from_design(default_design().replace(**{"coil.outer_radius_m": 0.021}))
    f0, f1 = P.bobbin_flange(params.bobbin), P.bobbin_flange(wider.bobbin)
    assert f0.bounding_box().size.Y == pytest.approx(2 * (19.0 + 1.5), abs=1e-6)
    assert f1.bounding_box().size.Y == pytest.approx(2 * (21.0 + 1.5), abs=1e-6)
    # nine pockets 2 mm deep grow from r = 20.8 mm to 22.8 mm
    dv = P.frame_plate(params.upper).volume - P.frame_plate(wider.upper).volume
    assert dv == pytest.approx(9 * pi * (22.8**2 - 20.8**2) * 2.0, rel=1e-9)


# -- design rules ---------------------------------------------------------------------------
def _rule_error(design=None, **kw) -> str:
    with pytest.raises(DesignRuleError) as info:
        check_rules(from_design(design or default_design(), **kw))
    return str(info.value)


def test_rule_flanges_overlap_at_pitch():
    msg = _rule_error(default_design().replace(**{"coil.outer_radius_m": 0.0245}))
    assert "overlap" in msg and "array.pitch_m" in msg


def test_rule_min_wall():
    msg = _rule_error(min_wall_mm=2.5)
    assert "flange thickness (printer minimum wall): 2 mm < the limit 2.5 mm" in msg
    assert "cad.flange_thickness_m" in msg


def test_rule_magnet_pocket_smaller_than_magnet():
    msg = _rule_error(press_fit_clearance_mm=-0.1)
    assert "smaller than the magnet" in msg and "cad.press_fit_clearance_m" in msg


def test_rule_sensor_inside_bobbin():
    msg = _rule_error(default_design().replace(**{"sensors.offset_m": 0.004}))
    assert "sensor board above the bobbin/core" in msg and "sensors.offset_m to >= 0.0058" in msg


def test_rule_printed_tube_without_room_suggests_fix():
    msg = _rule_error(mandrel="printed_tube")
    assert "tube wall" in msg and "core.radius_m" in msg


def test_bad_mandrel_is_bad_input():
    with pytest.raises(BadInputError):
        from_design(default_design(), mandrel="spool")


def test_build_volume_fit():
    assert fit_in_build_volume((150, 150, 6), (230, 190, 200)) is not None
    assert fit_in_build_volume((24, 24, 210), (230, 190, 200)) == (2, 0, 1)  # laid down
    assert fit_in_build_volume((240, 240, 6), (230, 190, 200)) is None


def test_interference_check_finds_a_tight_pocket(params):
    # one coil keeps the boolean work small; the pocket (20 mm) is smaller than the flange (20.5)
    single = from_design(default_design().replace(**{"array.rows": 1, "array.columns": 1}))
    plates = {side: dataclasses.replace(getattr(single, side), seats=tuple(
        dataclasses.replace(s, pocket_radius_mm=20.0) for s in getattr(single, side).seats))
        for side in ("upper", "lower")}
    tight = dataclasses.replace(single, **plates)
    assert interferences(single) == []
    hits = interferences(tight)
    labels = {a.split("@")[0] for a, b, _ in hits} | {b.split("@")[0] for a, b, _ in hits}
    assert {"bobbin_flange", "frame_upper", "frame_lower"} <= labels


# -- the independent mesh checker ------------------------------------------------------------
def _binary_stl(tris: np.ndarray) -> bytes:
    out = bytearray(b"\0" * 80 + struct.pack("<I", len(tris)))
    for t in tris:
        out += struct.pack("<3f", 0, 0, 0) + struct.pack("<9f", *np.asarray(t, float).ravel()) + b"\0\0"
    return bytes(out)


def _cube_triangles(a: float) -> np.ndarray:
    v = np.array([[x, y, z] for x in (0, a) for y in (0, a) for z in (0, a)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return np.array([[v[q[0]], v[q[k]], v[q[k + 1]]] for q in quads for k in (1, 2)])


def test_meshcheck_on_a_cube(tmp_path):
    tris = _cube_triangles(2.0)
    (tmp_path / "c.stl").write_bytes(_binary_stl(tris))
    rep = meshcheck.mesh_report(*meshcheck.read_stl(tmp_path / "c.stl"))
    assert rep.watertight and rep.manifold and rep.n_vertices == 8
    assert rep.volume == pytest.approx(8.0, rel=1e-12)
    assert meshcheck.check_mesh(rep, 8.0, 24.0, 0.0) == []
    (tmp_path / "open.stl").write_bytes(_binary_stl(tris[:-1]))
    rep = meshcheck.mesh_report(*meshcheck.read_stl(tmp_path / "open.stl"))
    assert not rep.watertight
    assert any("not watertight" in s for s in meshcheck.check_mesh(rep, 8.0, 24.0, 0.01))
    flipped = tris[:, ::-1]
    (tmp_path / "flip.stl").write_bytes(_binary_stl(flipped))
    rep = meshcheck.mesh_report(*meshcheck.read_stl(tmp_path / "flip.stl"))
    assert rep.watertight and rep.volume == pytest.approx(-8.0)
    assert any("not positive" in s for s in meshcheck.check_mesh(rep, 8.0, 24.0, 0.01))
    doubled = np.concatenate([tris, tris])
    rep = meshcheck.mesh_report(*meshcheck.merge_corners(doubled.reshape(-1, 3)))
    assert not rep.manifold


# -- export: the whole default set, once, through the CLI ------------------------------------------
@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    from designkit.cli import main

    out = tmp_path_factory.mktemp("cad")
    assert main(["cad", "--out", str(out)]) == 0
    return out


def test_cli_writes_every_part_in_every_format(exported, params):
    names = part_names(params, "exported")
    for name in names:
        for fmt in ("stl", "step", "3mf"):
            assert (exported / f"{name}.{fmt}").stat().st_size > 0
    for extra in ("assembly.step", "assembly.png", "parts.json", "parts.md"):
        assert (exported / extra).stat().st_size > 0
    assert not [p for p in exported.iterdir() if p.name.startswith(".")]  # no temp files left


def test_every_exported_mesh_is_closed_with_the_right_volume(exported, params):
    tol = params.printer.tolerance_mm
    for name in part_names(params, "exported"):
        shape = build_part(params, name)
        for reader, fmt in ((meshcheck.read_stl, "stl"), (meshcheck.read_3mf, "3mf")):
            rep = meshcheck.mesh_report(*reader(exported / f"{name}.{fmt}"))
            assert rep.watertight and rep.manifold, (name, fmt)
            assert rep.volume > 0
            assert abs(rep.volume - shape.volume) <= shape.area * tol, (name, fmt)
            bb = shape.bounding_box()
            assert rep.size == pytest.approx(tuple(bb.size), abs=tol + 1e-4)
        if name in ("core", "standoff"):  # lib3mf -> OCCT sewing is slow on big meshes
            # the reference 3MF library (lib3mf, via build123d) reads our package back
            (solid3mf,) = build123d.Mesher().read(exported / f"{name}.3mf")
            assert abs(solid3mf.volume - shape.volume) <= shape.area * tol, name
        back = build123d.import_step(exported / f"{name}.step")
        assert back.volume == pytest.approx(shape.volume, rel=1e-6)


def test_parts_list(exported, params):
    report = json.loads((exported / "parts.json").read_text())
    rows = {r["part"]: r for r in report["parts"]}
    core = rows["core"]
    assert core["material"] == "steel" and core["quantity"] == 9
    assert core["mass_g"] == pytest.approx(pi * 12**2 * 110 * 7.85e-3, rel=1e-9)
    # each part's mass in its own material (copper winding, NdFeB magnet)
    assert rows["magnet"]["mass_g"] == pytest.approx(pi * 5**2 * 10 * 7.5e-3, rel=1e-9)
    assert rows["winding"]["mass_g"] == pytest.approx(pi * (19**2 - 12**2) * 100 * 8.96e-3,
                                                      rel=1e-9)
    for r in rows.values():
        if r["kind"] == "printed":
            assert r["fits_printer"] is True
            assert r["print_time_proxy_h"] == pytest.approx(r["volume_mm3"] / 4.0 / 3600)
    md = (exported / "parts.md").read_text()
    assert "| frame_upper | 1 | PLA |" in md


def test_cli_design_rule_error_writes_nothing(tmp_path):
    from designkit.cli import main

    toml = tmp_path / "d.toml"
    toml.write_text("[sensors]\noffset_m = 0.004\n")
    out = tmp_path / "out"
    assert main(["cad", "--design", str(toml), "--out", str(out)]) == 1
    assert not out.exists() or list(out.iterdir()) == []


def test_oversize_part_is_reported_not_exported(tmp_path, capsys):
    from designkit.cli import main

    out = tmp_path / "small"
    args = ["cad", "--out", str(out), "--format", "stl", "--picture", "none",
            "--build-volume", "120,120,120"]
    assert main(args) == 1  # default: error before writing
    assert not out.exists() or list(out.iterdir()) == []
    assert "150.0 x 150.0 x 6.0 mm" in capsys.readouterr().err
    assert main(args + ["--oversize", "skip"]) == 3
    assert not (out / "frame_upper.stl").exists() and (out / "standoff.stl").exists()
    assert "NOT exported, larger than the build volume: frame_upper (150.0 x 150.0 x 6.0 mm)" \
        in capsys.readouterr().out


def test_failed_mesh_check_leaves_nothing(tmp_path, monkeypatch, params):
    from cad import export

    calls = {"n": 0}
    real = meshcheck.check_mesh

    def fail_third(*a, **k):
        calls["n"] += 1
        return ["forced failure"] if calls["n"] == 3 else real(*a, **k)

    monkeypatch.setattr(export.meshcheck, "check_mesh", fail_third)
    with pytest.raises(export.MeshCheckError, match="forced failure"):
        export.export_all(params, tmp_path / "o", ("stl",), picture="none", progress="none")
    # the folder export_all made for its output goes too: nothing partial anywhere
    assert list(tmp_path.iterdir()) == []


def test_air_core_design_gets_a_printed_tube():
    from designkit.design import design_from_dict

    p = from_design(design_from_dict({"core": {"enabled": False}}))
    assert p.core is None and p.bobbin.mandrel == "printed_tube"
    assert p.bobbin.bore_radius_mm == pytest.approx(12.0 - 1.2)
    assert "core" not in part_names(p) and violations(p) == []
    b = p.bobbin
    slot = P.slot_area_mm2(12.0, 20.5, b.slot_width_mm)
    exact = pi * (12.0**2 - 10.8**2) * 104.0 + 2 * 2.0 * (pi * (20.5**2 - 12.0**2) - slot)
    assert P.bobbin(b).volume == pytest.approx(exact, rel=1e-9)
    with pytest.raises(BadInputError):
        from_design(design_from_dict({"core": {"enabled": False}}), mandrel="core")
