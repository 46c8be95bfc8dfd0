"""studies/runner_stale.py on the small-box map: after a 40 mm jump and a removal the runner
never renders with a position more than 5 mm from where the finger was at the frame time of
its newest fix, and runs again within 50 ms of the finger's arrival (issue acceptance)."""

import pytest

from conftest import load_study, small_box_design

pytestmark = pytest.mark.slow


def test_runner_stale_study(small_map, thesis_array, tmp_path):
    res = load_study("runner_stale").run(tmp_path, map_path=small_map, seeds=1,
                                         design=small_box_design(), array=thesis_array,
                                         progress=False)
    assert (tmp_path / "runner_stale.json").is_file()
    [run] = res["runs"]
    assert run["running_steps"] > 500
    assert res["off_at_frame_steps_total"] == 0
    assert res["running_again_max_ms"] is not None and res["running_again_max_ms"] <= 50
    for name in ("jump", "removed"):
        # at the old position at most the sensing latency (two bus passes and a fit)
        assert run["events"][name]["rendered_old_position_ms"] <= 15
