"""``designkit sensors plan`` end to end: what it writes is a layout a design file takes as is
(the same sensors, the same bounds when judged again), and bad input is one line naming the
option, its value and the valid range, with nothing written."""

import json
import tomllib

import numpy as np
import pytest

from designkit import default_design
from designkit.cli import main
from designkit.design import load_design
from designkit.design.files import design_from_dict
from designkit.errors import BadInputError
from designkit.sensing.crb import BoundSettings
from designkit.sensing.maps import Layout, layout_bounds
from designkit.sensing.region import RegionSettings, one_magnet

SMALL = ["--heights", "30:60", "--lattice", "30", "--spacing", "25", "--max-current", "2",
         "--no-progress"]


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    out = tmp_path_factory.mktemp("plan") / "sp"
    assert main(["sensors", "plan", "--count", "10", *SMALL, "--out", str(out)]) == 0
    return out


def test_the_plan_is_a_sensors_table_a_design_file_takes(planned):
    files = sorted(p.name for p in planned.iterdir())
    assert files == ["bound_maps.png", "design.toml", "plan.json", "sensors.toml"]
    assert (planned / "bound_maps.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    plan = json.loads((planned / "plan.json").read_text())
    table = tomllib.loads((planned / "sensors.toml").read_text())
    design = design_from_dict(table, source="sensors.toml")
    pos, frames = design.sensor_poses()
    np.testing.assert_allclose(pos, plan["layouts"]["planned"]["positions_m"], atol=1e-12)
    assert len(pos) == 10 and design.sensors.layout == "free"
    full = load_design(planned / "design.toml")
    np.testing.assert_allclose(full.sensor_poses()[0], pos)
    # judged again from the file: the bounds plan.json reports
    region = RegionSettings((0.03, 0.06), 0.03, 0.03)
    scen = one_magnet(full.workspace_region(), region, full.magnet.direction)
    b = layout_bounds(full, [Layout("planned", pos, frames)], scen, BoundSettings())["planned"]
    row = plan["summaries"]["one magnet"]["planned"]["rows"][-1]
    assert row["worst_rms_m"] == pytest.approx(b.position_rms_m.max(), rel=1e-9)
    # every planned sensor keeps 80 % of its range at the asked 2 A
    assert all(r["all_coils_a"] >= 2.0 for r in plan["layouts"]["planned"]["headroom"])
    # the thesis layout's sensors leave it near 2.2-2.6 A, each named with its current
    assert all(2.0 < r["all_coils_a"] < 2.7 for r in plan["layouts"]["design"]["headroom"])


@pytest.mark.parametrize("args,words", [
    (["--count", "2"], ["--count", "at least 3 sensors", "8 unknowns", "2"]),
    (["--count", "4", "--magnets", "2"], ["--count", "at least 5 sensors", "13 unknowns"]),
    (["--magnets", "3"], ["--magnets", "1 or 2", "3"]),
    (["--plane", "-20"], ["--plane", "the coils and their cores span", "-20 mm"]),
    (["--plane", "50"], ["--plane", "the magnet moves there", "50 mm"]),
    (["--heights", "10:60"], ["--heights", "[20, 80] mm", "'10'"]),
    (["--separation", "60:30"], ["--separation", "LO <= HI"]),
    (["--max-current", "-1"], ["--max-current", "> 0", "-1"]),
    (["--noise-mt", "0"], ["--noise-mt", "> 0"]),
    (["--count", "500", "--spacing", "50"], ["--count", "at most", "sites"]),
    (["--spacing", "1"], ["--spacing", "at most 24000 grid points", "1 mm (", "points)"]),
    (["--separation", "1:2", "--magnets", "2"], ["--separation", "lattice step 30 mm", "1:2 mm"]),
    (["--seed", "-1"], ["--seed", "[0, 2^63)", "-1"]),
    (["--design", "no-such-design.toml"], ["design", "existing TOML file",
                                           "no-such-design.toml"]),
])
def test_bad_input_is_one_line_and_nothing_is_written(tmp_path, capsys, args, words):
    out = tmp_path / "sp"
    assert main(["sensors", "plan", *SMALL, *args, "--out", str(out)]) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1, err
    for w in words:
        assert w in err[0], err[0]
    assert list(tmp_path.iterdir()) == []


def test_magnets_beyond_what_the_coils_serve_are_refused(tmp_path, capsys):
    line = tmp_path / "line.toml"
    line.write_text("[array]\nrows = 1\ncolumns = 3\n")
    assert main(["sensors", "plan", "--design", str(line), "--magnets", "2", *SMALL,
                 "--out", str(tmp_path / "sp")]) == 1
    err = capsys.readouterr().err.strip()
    assert "--magnets" in err and "must be 1 (" in err and "3 coils" in err
    assert not (tmp_path / "sp").exists()


def test_the_default_count_is_the_designs():
    from designkit.commands.sensors import add_arguments, request_of
    import argparse
    p = argparse.ArgumentParser()
    add_arguments(p)
    req = request_of(p.parse_args(["plan"]), default_design())
    assert req.count == 18 and req.magnets == 1
    assert req.region.heights_m == (0.02, 0.08)


def test_the_report_section_reads_a_planned_table_and_refuses_a_bad_one(planned, tmp_path):
    from designkit.sensing.layout_report import layout_report, planned_layout
    design = default_design()
    lay = planned_layout(design, planned / "sensors.toml")
    plan = json.loads((planned / "plan.json").read_text())
    np.testing.assert_allclose(lay.positions_m, plan["layouts"]["planned"]["positions_m"])
    entry = layout_report(design, tmp_path / "b.png", "quick", lay,
                          BoundSettings(cores="none"))
    assert list(entry["summaries"]["two magnets"]) == ["design", "planned (sensors.toml)"]
    assert (tmp_path / "b.png").stat().st_size > 10000
    bad = tmp_path / "bad.toml"
    bad.write_text("[sensors]\nlayout = \"free\"\npositions_m = [[0, 0]]\n")
    with pytest.raises(BadInputError, match="sensors.positions_m"):
        planned_layout(design, bad)
    bad.write_text("[coil]\nturns = 3\n")
    with pytest.raises(BadInputError, match=r"--sensors.*\[sensors\] table"):
        planned_layout(design, bad)


@pytest.mark.parametrize("args", [["--plane", "0"], ["--count", "500", "--spacing", "50"],
                                  ["--separation", "1:2", "--magnets", "2"]])
def test_refusals_found_with_the_sites_come_before_the_progress_bar(tmp_path, capsys, args):
    # refusals that need the array, the sites or the scenarios are raised before the bar starts
    base = [a for a in SMALL if a != "--no-progress"]
    assert main(["sensors", "plan", *base, *args, "--out", str(tmp_path / "sp")]) == 1
    cap = capsys.readouterr()
    err = [ln for ln in (cap.out + cap.err).splitlines() if ln.strip()]
    assert len(err) == 1 and args[0] in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_the_usage_line_puts_the_action_first_as_it_is_typed(capsys):
    assert main(["sensors", "--help"]) in (0, None)
    assert capsys.readouterr().out.startswith("usage: designkit sensors {plan} [options]")
