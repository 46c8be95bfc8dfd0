"""Smoke test of studies/sensor_plan.py: a coarse run writes its table and JSON under the
folder it is given (nowhere else), its checks hold, and a planned layout is listed per count."""

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "studies"))

import sensor_plan  # noqa: E402


def test_quick_run_writes_under_its_folder_and_checks_the_bound(tmp_path):
    out = tmp_path / "study"
    res = sensor_plan.run(out, counts=(6,), currents=(2.0,), quick=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study"]
    assert sorted(p.name for p in out.iterdir()) == ["bound_maps_2A.png", "sensor_plan.json",
                                                     "sensor_plan.txt"]
    assert json.loads((out / "sensor_plan.json").read_text())["plans"][0]["count"] == 6
    q = res["quoted"]
    for got, want in zip(q["quoted model"]["one_mm"], q["issue"]["one_mm"]):
        assert abs(got - want) <= 0.05 * want + 0.005
    for f in res["fit_check"]:  # 20 fits: within 5 sampling sd
        assert abs(f["fit_rms_m"] / f["bound_rms_m"] - 1) < 5 * f["sampling_sd"]
    text = (out / "sensor_plan.txt").read_text()
    assert "| 2 A | thesis 18" in text and "| 2 A | planned 6 |" in text
