"""``designkit report``: the main job writes a complete, idempotent report folder.

Reference for the numbers: :meth:`designkit.Coil.field` evaluated directly, F = (grad B)^T m.
"""

import contextlib
import io
import json

import numpy as np
import pytest

from designkit import Coil, default_design, viz
from designkit.model.array import array_for_design
from designkit.cli import main
from designkit.cores import ArraySystem


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    """A quick report, the coil count of every coupled core solve it built, what it printed."""
    out = tmp_path_factory.mktemp("report")
    printed = io.StringIO()
    built, build = [], ArraySystem.__init__

    def counting(self, array, *args, **kwargs):
        built.append(array.n_coils)
        build(self, array, *args, **kwargs)

    array_for_design.cache_clear()     # the report's own solves, not an earlier test's
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ArraySystem, "__init__", counting)
        with contextlib.redirect_stdout(printed):
            assert main(["report", "--quick", "--no-progress", "--out", str(out)]) == 0
    return out, built, printed.getvalue()


@pytest.fixture(scope="module")
def quick_report(quick_run):
    return quick_run[0]


def test_report_solves_the_design_s_coupled_cores_once(quick_run):
    # figures, array force and map all use one array; the map's magnet tables solve one coil
    built = quick_run[1]
    n = default_design().n_coils
    assert built.count(n) == 1 and set(built) <= {1, n}, built


def test_the_summary_says_which_force_is_one_coil_and_which_the_whole_array(quick_run):
    out, _, printed = quick_run
    rep = json.loads((out / "report.json").read_text())
    e = rep["designs"]["design"]
    [line] = [ln for ln in printed.splitlines() if ln.startswith("design '")]
    assert (f"upward Fz {round(e['upward_force_design_point_n'] * 1e3, 1):.1f} mN at the design "
            f"point from its coil alone at {e['current_a']:g} A; with every coil") in line
    assert f"Fz >= {round(e['min_upward_force_workspace_n'] * 1e3, 1):.1f} mN" in line


def test_report_folder_is_complete(quick_report):
    out = quick_report
    for name in ("report.json", "report.md", "design.json", "design.md", "design.toml"):
        assert (out / name).stat().st_size > 0
    rep = json.loads((out / "report.json").read_text())
    for key in ("designkit_version", "design_name", "design_hash", "design", "design_point"):
        assert key in rep
    assert set(rep["figures"]) == {"scene", "fieldlines", "slice-B", "slice-F", "forcemap",
                                   "isosurface"}
    for rel in list(rep["figures"].values()) + list(rep["vtk"].values()):
        assert (out / rel).stat().st_size > 1000, rel
        assert rel in (out / "report.md").read_text()
    # optional parts: present, or listed under "skipped" with the reason
    assert ("designs" in rep) != ("design vs optimized" in rep["skipped"])
    assert ("map" in rep) != ("map file" in rep["skipped"])
    assert not [p for p in out.rglob(".*")]  # no temporary files left behind


def test_report_files_have_the_right_content(quick_report):
    """Not only present: each file reads back to what it claims."""
    import pyvista as pv
    from matplotlib.image import imread

    from designkit.design import load_design

    out = quick_report
    rep = json.loads((out / "report.json").read_text())
    d = default_design()
    # design.toml reproduces the design exactly; design.json carries the same hash
    assert load_design(out / "design.toml").spec_hash() == rep["design_hash"] == d.spec_hash()
    assert json.loads((out / "design.json").read_text())["design"] == json.loads(
        json.dumps(d.to_dict()))
    # report.md states the design-point force that report.json holds
    fz_mn = rep["design_point"]["force_n"][2] * 1e3
    assert f"{fz_mn:+.4g}" in (out / "report.md").read_text()
    # figures: PNGs of the quick sizes, not blank
    for kind, rel in rep["figures"].items():
        img = imread(out / rel)
        want = (420, 960) if kind in viz.output.WIDE_KINDS else (480, 640)
        assert img.shape[:2] == want, kind
        assert img[..., :3].std() > 0.05, kind
    # VTK files load and carry the SI arrays the docs promise
    vol = pv.read(out / rep["vtk"]["slice_horizontal.vts"])
    assert {"B (T)", "F (N)", "grad B (T/m)"} <= set(vol.point_data.keys())
    assert vol.n_points > 100 and np.all(np.isfinite(vol["F (N)"]))
    coils = pv.read(out / rep["vtk"]["coils.vtp"])
    assert coils["current (A)"].max() == d.drive.max_current_a
    # the map file is a numpy archive
    if "map" in rep:
        with np.load(out / rep["map"], allow_pickle=False) as z:
            assert len(z.files) > 0


def test_report_shows_the_thesis_and_the_optimized_device_side_by_side(quick_report):
    from designkit.model import electrical as el

    rep = json.loads((quick_report / "report.json").read_text())
    assert rep["quick"] is True
    md = (quick_report / "report.md").read_text()
    assert "QUICK RUN" in md
    thesis, opt = rep["designs"]["design"], rep["designs"]["optimized"]
    # the thesis device misses what the issue measured; each flagged in JSON and Markdown
    for name in ("settling_time_s", "design_supply_voltage_v", "turns", "resistance_ohm"):
        assert name in thesis["violated"] and not thesis["constraints"][name]["met"]
    assert md.count("**VIOLATED**") >= len(thesis["violated"])
    assert thesis["turns_that_fit"] == el.turns_from_geometry(0.012, 0.019, 0.1, 0.7e-3)
    assert opt["feasible"] and opt["violated"] == []
    assert opt["upward_force_design_point_n"] > 0 and opt["min_upward_force_workspace_n"] > 0
    # every number's key carries its unit (or is a count/flag/name)
    for e in (thesis, opt):
        for key, val in e.items():
            if isinstance(val, float):
                assert key.rsplit("_", 1)[-1] in ("m", "n", "ohm", "h", "s", "v", "a", "c",
                                                  "t", "kg", "m"), key


def test_report_force_matches_the_field_engine(quick_report):
    rep = json.loads((quick_report / "report.json").read_text())
    d = default_design()
    dp = rep["design_point"]
    b, g = Coil.from_design(d).field(np.array(d.design_point_m), d.drive.max_current_a,
                                     gradient=True)
    m = np.array(d.magnet.moment_vector_a_m2)
    np.testing.assert_allclose(dp["flux_density_t"], b, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(dp["force_n"], g.T @ m, rtol=1e-9, atol=1e-12)
    # default figure currents (centre coil only): the array is the coupled engine (all nine
    # cores iron, issue 12), which pushes ~12 % harder than the single coil at the design point
    from designkit.model.array import CoilArray

    cur = np.zeros(9)
    cur[4] = d.drive.max_current_a
    f_arr = CoilArray.from_design(d).force(np.array([d.design_point_m]), m, cur)[0]
    np.testing.assert_allclose(rep["array"]["force_n"], f_arr, rtol=1e-9, atol=1e-12)
    assert 1.05 < rep["array"]["force_n"][2] / dp["force_n"][2] < 1.2
    assert dp["point_m"] == [0.0, 0.0, d.optimize.height_m]


def test_design_table_lists_every_field_in_mm(quick_report):
    text = (quick_report / "design.md").read_text()
    d = default_design()
    assert f"| coil.inner_radius_m | {d.coil.inner_radius_m * 1e3:.6g} mm |" in text
    assert f"| coil.turns | {d.coil.turns} |" in text
    design = json.loads((quick_report / "design.json").read_text())
    assert design["design_hash"] == d.spec_hash()


def test_report_puts_the_design_point_forces_side_by_side_with_their_assumptions(quick_report):
    import re

    md = (quick_report / "report.md").read_text()
    rep = json.loads((quick_report / "report.json").read_text())
    table = md.split("## Forces at the design point, side by side")[1].split("\n## ")[0]
    rows = [r for r in table.splitlines()
            if r.startswith("| ") and not r.startswith(("| case", "| ---"))]
    assert len(rows) == 4  # single coil, array, saturating single coil, workspace minimum
    assert "linear core (mu_r 1000)" in rows[0] and "| 6 A |" in rows[0]
    assert "coupled" in rows[1] and "coil 5 at +6 A" in rows[1]
    assert "saturating core (steel1010 B-H)" in rows[2]
    ev = rep["designs"]["design"]
    assert f"{ev['upward_force_design_point_n'] * 1e3:+.1f} mN" in rows[2]
    assert "LP allocation" in rows[3] and "sum <= 54 A" in rows[3]
    assert "Why they differ" in table
    # round-off is printed as 0, never as 1e-16 mT
    assert not re.search(r"[+-]\d\.\d+e-\d\d", table), table
    # the design summary gives every derived quantity a unit (inductance in H)
    assert re.search(r"\| inductance_h \| [0-9.]+ H \|", (quick_report / "design.md").read_text())


@pytest.mark.slow
def test_report_is_idempotent(quick_report, tmp_path):
    # the module's quick report run again over a copy of its own folder: the same files, the
    # same JSON bytes
    import shutil

    out = tmp_path / "again"
    shutil.copytree(quick_report, out)
    first = {p.relative_to(out): p.read_bytes() for p in out.rglob("*.json")}
    files = sorted(p.relative_to(out) for p in out.rglob("*"))
    assert main(["report", "--quick", "--no-progress", "--out", str(out)]) == 0
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == files
    for rel, content in first.items():
        if rel.name != "optimized_coil.json":  # holds the optimizer's wall-clock seconds
            assert (out / rel).read_bytes() == content, rel


def test_report_prints_the_sensor_layouts_bound_maps(quick_report):
    rep = json.loads((quick_report / "report.json").read_text())
    sb = rep["sensor_bounds"]
    assert (quick_report / "figures" / sb["figure"]).stat().st_size > 10000
    # the thesis array serves two magnets: both kinds, the design's layout in each
    assert set(sb["summaries"]) == {"one magnet", "two magnets"}
    one = sb["summaries"]["one magnet"]["design"]["rows"]
    assert [r["group"] for r in one] == ["z 20 mm", "z 50 mm", "z 80 mm", "all"]
    # a magnet higher up is located worse
    assert one[0]["median_rms_m"] < one[1]["median_rms_m"] < one[2]["median_rms_m"]
    md = (quick_report / "report.md").read_text()
    assert "## Sensor layout: Cramer-Rao bound" in md and "figures/sensor_bounds.png" in md


@pytest.mark.parametrize("force_n, says", [
    (-2e-5, "Fz = 0 mN: somewhere in the region the array cannot push the magnet up"),
    (-0.004, "Fz = 0 mN: somewhere in the region the array cannot push the magnet up"),
    (0.01234, "Fz >= 12.3 mN")])
def test_a_smallest_upward_force_of_zero_or_below_says_what_it_means(quick_report, force_n,
                                                                       says):
    """The report never prints '>= -0.0 mN' (a force rounding to minus zero, or one below
    zero, means the array cannot push the magnet up somewhere in the region)."""
    import re

    from designkit.commands.report import report_markdown

    report = json.loads((quick_report / "report.json").read_text())
    for e in report["designs"].values():
        e["min_upward_force_workspace_n"] = force_n
    text = report_markdown(report)
    assert says in text and not re.search(r"-0\.0(?![0-9])", text)
