"""``designkit run --simulate`` and ``scene compile --map`` as a user meets them: --duration
keeps the trajectory's speed, the fault table is each fault's own (checked against run.csv),
the output folder has the permissions of a plain mkdir, and --design next to --map is checked."""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from designkit.sim.faults import FAULT_CLEARS_S, FAULT_TYPES
from conftest import ROOT
from test_run_simulated import map_file  # noqa: F401  (the module's map, built once)

pytestmark = pytest.mark.slow


def _run(tmp_path, *args):
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    return subprocess.run([sys.executable, "-m", "designkit.cli", *args], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=900)


def _csv(path):
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    t = np.array([float(r["t_s"]) for r in rows])
    return rows, t, np.array([r["state"] for r in rows])


def test_duration_cuts_the_trajectory_at_its_own_speed(map_file, tmp_path):
    res = _run(tmp_path, "run", "--simulate", "--trajectory", "poke", "--duration", "1",
               "--map", str(map_file), "--out", "o", "--no-progress")
    assert res.returncode == 0, res.stderr[-2000:]
    assert "simulated 1 s of the 3 s trajectory" in res.stdout
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["trajectory_played"] == "cut" and summary["trajectory_duration_s"] == 3.0
    rows, t, _ = _csv(tmp_path / "o" / "run.csv")
    assert t[-1] < 1.0
    z = np.array([float(r["z_m"]) for r in rows])
    # poke: depth (15 + 10) mm * (0.5 - 0.5 cos(4 pi t / T)), T = 3 s: at most
    # 25 mm * 2 pi / 3 s = 52 mm/s (clipping only slows it); squeezed into 1 s it would be 157
    speed = np.abs(np.diff(z) / np.diff(t))
    assert speed.max() <= 0.025 * 2 * math.pi / 3.0 * 1.01
    assert speed.max() >= 0.02  # and the finger does move
    # the folder is made like a plain mkdir (not mkdtemp's 0700)
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "o").stat().st_mode & 0o777 == 0o777 & ~mask


def test_fault_table_is_each_faults_own_from_run_csv(map_file, tmp_path):
    res = _run(tmp_path, "run", "--simulate", "--faults", "default", "--duration", "1",
               "--map", str(map_file), "--out", "o", "--no-progress")
    assert res.returncode == 0, res.stderr[-2000:]
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    _, t, state = _csv(tmp_path / "o" / "run.csv")
    table = summary["faults"]
    detected = [f for f in table if f["state"] is not None]
    assert len(detected) >= len(table) - 1 >= 4
    for f in table:
        te = f["injected_s"]
        if f["state"] is None:  # masked: never in its own state after the injection
            assert not np.any((t >= te - 1e-9) & (state == f["fault"]))
            continue
        assert f["state"] == f["fault"]          # its own state, not the previous fault's
        k = int(np.argmin(np.abs(t - (te + f["time_to_safe_s"]))))
        assert state[k] == f["fault"]
        # counted from run.csv: no step between the injection and the detection is in it
        assert not np.any((t >= te - 1e-9) & (t < t[k] - 1e-9) & (state == f["fault"]))
        if f["ended_s"] is not None:
            j = int(np.argmin(np.abs(t - (te + f["ended_s"]))))
            assert state[j] == f["ended_into"] != f["fault"]
            assert np.all(state[k:j] == f["fault"])
        if f["resumed_s"] is not None:
            j = int(np.argmin(np.abs(t - (te + f["resumed_s"]))))
            assert state[j] == "running" and not np.any(state[k:j] == "running")
        if f["recovered_s"] is not None:    # from when the cause is gone (or the detection)
            tc = max(te + FAULT_CLEARS_S[f["fault"]], t[k])
            j = int(np.argmin(np.abs(t - (tc + f["recovered_s"]))))
            assert state[j] == "running" and not np.any((t >= tc - 1e-9) & (t < t[j] - 1e-9)
                                                        & (state == "running"))
        assert f["currents_off_s"] is None or f["currents_off_s"] >= f["time_to_safe_s"]
    # every scheduled fault is accounted for: injected (in the table) or said not to be
    assert len(table) + len(summary["faults_not_injected"]) == len(FAULT_TYPES)
    assert "fault sensor_stuck @" in res.stdout


def test_scene_design_next_to_map_must_be_the_maps(map_file, tmp_path):
    (tmp_path / "other.toml").write_text("[array]\npitch_m = 0.06\n")
    res = _run(tmp_path, "scene", "compile", "plane", "--map", str(map_file), "--design",
               "other.toml", "--lambda", "5", "--out", "s.npz")
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 1 and len(lines) == 1 and "Traceback" not in res.stderr
    assert "--design" in lines[0] and "other.toml" in lines[0] and "map" in lines[0]
    assert not (tmp_path / "s.npz").exists()
    ok = _run(tmp_path, "scene", "compile", "plane", "--map", str(map_file), "--design",
              "thesis", "--lambda", "5", "--out", "s.npz")
    assert ok.returncode == 0, ok.stderr[-2000:]
