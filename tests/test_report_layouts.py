"""``designkit report`` on other layouts: a figure that fails is named and the rest written,
``--no-figures``, the comparison with the shipped optimum only between like devices, and (slow)
the gallery's 4 x 4 grid and tilted ring end to end."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from designkit import viz
from designkit.cli import main
from designkit.commands.report import not_comparable
from designkit.design import (GridLayout, HexLayout, default_design, design_to_toml,
                              load_design, named_design)
from designkit.viz import output as viz_output

GALLERY = Path(__file__).resolve().parents[1] / "docs" / "gallery"
AIR_PAIR = default_design().replace(
    name="air-pair", array=GridLayout(1, 2, 0.05), core=None,
    **{"workspace.shape": "box", "workspace.half_width_m": 0.03, "workspace.z_min_m": 0.02,
       "workspace.z_max_m": 0.05})


@pytest.fixture(scope="module")
def design_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("report_layouts") / "air-pair.toml"
    path.write_text(design_to_toml(AIR_PAIR))
    return path


def test_a_failing_figure_is_named_and_the_rest_is_written(design_file, tmp_path, monkeypatch,
                                                           capsys):
    def broken(*args, **kwargs):
        raise RuntimeError("planted failure")

    monkeypatch.setattr(viz_output, "plot_slices", broken)
    out = tmp_path / "r"
    assert main(["report", "--quick", "--design", str(design_file), "--out", str(out),
                 "--no-progress"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert set(report["failed"]) == {"figure slice-B", "figure slice-F"}
    assert all("RuntimeError: planted failure" in why for why in report["failed"].values())
    assert set(report["figures"]) == {"scene", "fieldlines", "forcemap", "isosurface"}
    for kind in report["figures"]:
        assert (out / "figures" / f"{kind}.png").stat().st_size > 1000
    assert not (out / "figures" / "slice-B.png").exists()
    # the slices' data were built, so their VTK files are written
    assert "slice_vertical.vts" in report["vtk"]
    assert "## Failed" in (out / "report.md").read_text()
    assert "FAILED figure slice-B: RuntimeError: planted failure" in capsys.readouterr().out


def test_no_figures_leaves_out_the_figures_and_their_vtk_files(design_file, tmp_path):
    out = tmp_path / "r"
    assert main(["report", "--quick", "--no-figures", "--design", str(design_file), "--out",
                 str(out), "--no-progress"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert not (out / "figures").exists() and not (out / "vtk").exists()
    assert report["skipped"]["figures"] == "--no-figures" and (out / "map").is_dir()


def test_the_optimum_is_compared_only_with_a_device_of_its_kind_and_coil_count():
    optimum = named_design("optimized")  # a 3 x 3 grid
    assert not_comparable(default_design(), optimum) == ""
    assert not_comparable(default_design().replace(array=GridLayout(3, 3, 0.044)),
                          optimum) == ""
    for other in (GridLayout(4, 4, 0.05), GridLayout(1, 9, 0.05), HexLayout(1, 0.044)):
        why = not_comparable(default_design().replace(array=other), optimum)
        assert "3 x 3 grid" in why and other.describe() in why


@pytest.mark.slow
@pytest.mark.parametrize("name", ["grid-4x4", "ring-6-tilted"])
def test_gallery_report_runs_through_the_design_point(name, tmp_path):
    design = load_design(GALLERY / f"{name}.toml")
    out = tmp_path / name
    assert main(["report", "--quick", "--design", str(GALLERY / f"{name}.toml"), "--out",
                 str(out), "--no-progress"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report.get("failed", {}) == {}
    assert set(report["figures"]) == set(viz.KINDS)
    assert report["design_point_m"] == pytest.approx(list(design.design_point_m))
    assert report["designs"]["optimized"]["skipped"].startswith("the shipped optimum")
