"""The whole chain on the simulated device: map v2 -> compiled scene -> firmware_io runner (real
localizer, exact allocator) -> simulated PWM boards and sensors -> exact array physics."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, load_study

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def map_file(tmp_path_factory):
    from designkit import fieldmap
    from designkit.design import default_design

    path = tmp_path_factory.mktemp("map") / "map.npz"
    fieldmap.write(path, fieldmap.build(default_design(), progress=False))
    return path


def test_designkit_run_simulate_writes_a_consistent_run(map_file, tmp_path):
    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "designkit.cli", "run", "--simulate", "--object", "plane",
           "--duration", "0.8", "--faults", "over_limit@0.5", "--map", str(map_file),
           "--out", str(out), "--no-progress"]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-2000:]
    summary = json.loads((out / "summary.json").read_text())
    rows = list(csv.DictReader((out / "run.csv").open()))
    assert len(rows) == 800 and (out / "run.png").is_file() and (out / "loop_timing.png").is_file()
    cols = rows[0].keys()
    for c in ("t_s", "x_m", "xe_m", "fz_ref_n", "fz_n", "i1_a", "cmd9_a", "loop_s", "state"):
        assert c in cols
    # the estimate follows the true path (independent: the trajectory is scripted)
    fix = [r for r in rows if r["xe_m"] != "nan"]
    err = [np.linalg.norm([float(r[a]) - float(r[b]) for a, b in
                           (("x_m", "xe_m"), ("y_m", "ye_m"), ("z_m", "ze_m"))]) for r in fix]
    # with the start-up calibration and the fit on the sensor side the tracked estimate is
    # ~0.7 mm from the finger (median, studies/render_runner.py); 3 mm leaves room for the
    # cold start in this short run
    assert np.median(err) < 3e-3
    # the scheduled defect reached no output, and no command ever exceeded its bounds
    drive = summary["drive"]
    cmd_a = np.array([[float(r[f"cmd{k}_a"]) for k in range(1, 10)] for r in rows])
    # run.csv holds 9 significant digits
    assert np.abs(cmd_a).max() <= drive["current_limit_a"] * (1 + 1e-8)
    assert np.abs(cmd_a).sum(axis=1).max() <= drive["total_current_a"] * (1 + 1e-8)
    [f] = summary["faults"]
    assert f["fault"] == "over_limit" and f["state"] == "over_limit"
    assert f["time_to_safe_s"] <= 1e-3 + 1e-12


def test_run_refuses_a_map_from_another_design(map_file, tmp_path):
    other = tmp_path / "other.toml"
    other.write_text("[array]\npitch_m = 0.06\n")
    res = subprocess.run([sys.executable, "-m", "designkit.cli", "run", "--simulate",
                          "--design", str(other), "--map", str(map_file), "--duration", "0.2",
                          "--out", str(tmp_path / "r")], cwd=ROOT, capture_output=True, text=True,
                         timeout=600)
    assert res.returncode != 0
    assert "Traceback" not in res.stderr and "design" in res.stderr
    # the refusal came after the map was read: nothing half written is left behind
    assert not (tmp_path / "r").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".r.")]


def test_bench_runner_smoke(map_file, tmp_path):
    res = load_study("bench_runner").run(tmp_path / "b", map_path=map_file, quick=True)
    loop = res["loop_force"]
    for kind in ("without_frame", "with_frame", "sensor_side_fit"):
        assert loop[kind]["n"] > 0 and loop[kind]["median_us"] > 0
    assert {"fix", "predict", "object_force", "force_matrix", "allocation", "drive"} \
        <= set(loop["stages"])
    skip = res["skip"]
    assert skip["bound_holds"] and skip["rows_used_3d"] == [3, 5, 6, 7]
    assert skip["rows_used_fz"] == [3, 6]
    # the step per runner state, from the run with every fault injected
    assert res["by_state"]["running"]["n"] > 0 and res["reference"]["median_us"] > 0
    assert len(res["recovery"]) >= 4


def test_render_runner_study_smoke(map_file, tmp_path):
    res = load_study("render_runner").run(tmp_path / "r", map_path=map_file, quick=True)
    [(key, v)] = res["runs"].items()
    # a sanity bound: the quick run squeezes the 80 mm slide there and back into 0.5 s (peak
    # 0.5 m/s, 16 m/s^2: far faster than a finger, and the cold start of the fit)
    assert key == "plane/force" and v["localization_mae_m"] < 1e-2
    assert res["all_within_limits"]
