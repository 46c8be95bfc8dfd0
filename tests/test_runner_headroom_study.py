"""studies/runner_headroom.py, quick: at 6 A in every coil no sensor stays linear (what
`designkit check` says), at 0 A all 18 do; the closed loop with the upper sensors kept runs."""

import pytest

from conftest import load_study

pytestmark = pytest.mark.slow


def test_runner_headroom_study_quick(tmp_path):
    res = load_study("runner_headroom").run(tmp_path, quick=True)
    assert (tmp_path / "runner_headroom.json").is_file()
    rows = {r["amplitude_a"]: r for r in res["open_loop"]}
    assert rows[0.0]["sensors_left_min"] == 18 and rows[0.0]["trusted_fraction"] > 0.9
    assert rows[6.0]["sensors_left_median"] == 0 and rows[6.0]["trusted_fraction"] <= 0.05
    kept = res["closed_loop"]["keep_upper_sensors"]
    assert kept["running_fraction"] > 0.3
