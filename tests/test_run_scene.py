"""``designkit run --simulate``: a compiled scene runs with its own lambda (``--scene``), the
default lambda is the design's stiffness capped at what the device renders, and the summary
line counts injected faults and the faults the runner detected, each labelled.

A two-coil air-core grid with a small box keeps the map a few seconds. The scene's force is
checked against the hemisphere's own formula (lambda h n, |n| = 1), not against the runner.
"""

from __future__ import annotations

import csv
import re
from types import SimpleNamespace

import numpy as np
import pytest

from designkit.cli import main
from designkit.design import GridLayout, default_design, design_to_toml
from designkit.sim import run as sim_run

SCENE_LAMBDA = 3.3
HEMISPHERE_RADIUS_M = 0.05  # the thesis' half-sphere, 100 mm diameter, on z = 0

DESIGN = default_design().replace(
    name="two-air-coils", array=GridLayout(1, 2, 0.05), core=None,
    **{"workspace.shape": "box", "workspace.half_width_m": 0.03, "workspace.z_min_m": 0.02,
       "workspace.z_max_m": 0.06, "drive.supply_voltage_v": 30.0})


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    out = tmp_path_factory.mktemp("run_scene")
    design = out / "design.toml"
    design.write_text(design_to_toml(DESIGN))
    assert main(["map", "--design", str(design), "--out", str(out / "map.npz"),
                 "--no-progress"]) == 0
    assert main(["scene", "compile", "hemisphere", "--map", str(out / "map.npz"),
                 "--lambda", str(SCENE_LAMBDA), "--out", str(out / "scene.npz"),
                 "--no-progress"]) == 0
    # a slide inside the small box, 5-15 mm inside the dome (the scripted one starts at
    # x = -40 mm, outside this box)
    path = out / "path.csv"
    t = np.linspace(0.0, 0.3, 31)
    x = np.interp(t, [0.0, 0.3], [-0.02, 0.01])
    path.write_text("t_s,x_m,y_m,z_m\n" + "".join(f"{a:.6f},{b:.6f},0.0,0.035\n"
                                                   for a, b in zip(t, x)))
    return SimpleNamespace(out=out, design=design, map=out / "map.npz",
                           scene=out / "scene.npz", path=path)


@pytest.fixture(scope="module")
def scene_run(files):
    mp = pytest.MonkeyPatch()
    mp.setattr(sim_run, "plot_run", lambda *a, **k: None)  # figures are not what is tested
    printed = []
    mp.setattr("builtins.print", lambda *a, **k: printed.append(" ".join(map(str, a))))
    try:
        code = main(["run", "--simulate", "--design", str(files.design), "--map",
                     str(files.map), "--scene", str(files.scene), "--trajectory",
                     str(files.path), "--duration", "0.3",
                     "--faults", "sensor_dead@0.15", "--out", str(files.out / "run")])
    finally:
        mp.undo()
    rows = list(csv.DictReader((files.out / "run" / "run.csv").open()))
    return code, "\n".join(printed), rows


def test_a_compiled_scene_runs_with_its_own_lambda(scene_run, files):
    code, text, rows = scene_run
    assert code == 0
    assert f"lambda = {SCENE_LAMBDA:g} N/m (scene {files.scene})" in text
    # the force the runner asks for is the scene's: lambda h(x, y) along the unit normal, at
    # the estimated position (a runner on render.stiffness, 6 N/m, or on the device's own
    # lambda would ask for another magnitude)
    judged = 0
    for r in rows:
        if r["state"] != "running":
            continue
        x, y = float(r["xe_m"]), float(r["ye_m"])
        h = np.sqrt(max(HEMISPHERE_RADIUS_M ** 2 - x * x - y * y, 0.0))
        f = np.linalg.norm([float(r[k]) for k in ("fx_ref_n", "fy_ref_n", "fz_ref_n")])
        z = float(r["ze_m"])
        if h > 0.01 and z < h - 1e-3:  # inside the object, away from its rim
            assert f == pytest.approx(SCENE_LAMBDA * h, rel=1e-6)
            judged += 1
    assert judged > 50


def test_the_summary_counts_injected_and_detected_faults_apart(scene_run):
    _, text, _ = scene_run
    fault_lines = len(re.findall(r"\] FAULT ", text))
    m = re.search(r"faults injected (\d+), faults the runner detected (\d+)", text)
    assert m, text
    # one fault injected; the runner's own count is that of the FAULT lines it printed
    # (the dead sensor, and whatever followed from it), not the injected count
    assert int(m.group(1)) == 1 and int(m.group(2)) == fault_lines >= 1


def test_scene_and_lambda_or_object_are_refused_together(files, capsys):
    for extra in (["--lambda", "2"], ["--object", "plane"]):
        code = main(["run", "--simulate", "--design", str(files.design), "--map",
                     str(files.map), "--scene", str(files.scene), "--out",
                     str(files.out / "refused"), "--no-progress"] + extra)
        assert code == 1 and "with --scene" in capsys.readouterr().err
        assert not (files.out / "refused").exists()


def test_default_lambda_is_the_design_stiffness_capped_at_what_the_device_renders(monkeypatch):
    """choose_lambda: min(render.stiffness, lambda over the renderable points); points where
    nothing is renderable (lambda_j = 0) are counted, not allowed to make the object's lambda 0.
    The force constant itself is tested against the allocator in test_render_constant*."""
    from designkit.render.constant import ForceConstant

    def fake(lams):
        lams = np.asarray(lams, float)
        pts = np.c_[np.arange(len(lams)) * 1e-3, np.zeros(len(lams)), np.full(len(lams), 0.03)]
        return ForceConstant(float(lams.min()), pts[int(np.argmin(lams))], int(np.argmin(lams)),
                             pts, np.tile([0.0, 0.0, 1.0], (len(lams), 1)), np.ones(len(lams)),
                             lams, 0, "force", False, 6.0, 54.0)

    from types import SimpleNamespace

    drive = SimpleNamespace(current_limit_a=6.0, total_current_a=54.0)
    design = default_design()  # render.stiffness_n_per_m = 6
    for lams, want, zeros in (([9.0, 14.0], 6.0, 0), ([4.5, 7.0], 4.5, 0),
                              ([0.0, 8.1, 0.0, 12.0], 6.0, 2), ([0.0, 2.5], 2.5, 1)):
        monkeypatch.setattr(sim_run.render, "force_constant", lambda *a, _l=lams, **k: fake(_l))
        got = sim_run.choose_lambda(design, None, None, drive, sim_run.RunSettings(),
                                    progress=False)
        assert got["lambda_n_per_m"] == want and got["lambda_unrenderable_points"] == zeros
    assert sim_run.choose_lambda(design, None, None, drive,
                                 sim_run.RunSettings(lam_n_per_m=7.5),
                                 progress=False)["lambda_n_per_m"] == 7.5
