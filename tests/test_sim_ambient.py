"""The simulated run's ambient field and sensor-side fix counts: --background-mt is checked
(three finite values within the range, one line naming the option), and summary.json's fix rows
count the trusted fixes more than 5 mm from the truth."""

from __future__ import annotations

import math

import pytest

from designkit.cli import main
from designkit.errors import BadInputError
from designkit.sim.report import fix_summary
from designkit.sim.run import MAX_BACKGROUND_T, RunSettings, run_simulation


@pytest.mark.parametrize("text", ["1,2", "a,b,c", "1,2,3,4", "0,0,20"])
def test_background_option_refuses_in_one_line(text, tmp_path, capsys):
    code = main(["run", "--simulate", "--background-mt", text, "--out", str(tmp_path / "o"),
                 "--no-progress"])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert code != 0 and len(err) == 1 and "--background-mt" in err[0]
    assert "Traceback" not in err[0] and not (tmp_path / "o").exists()


@pytest.mark.parametrize("bg", [(0.0, 0.0, 2 * MAX_BACKGROUND_T), (math.nan, 0.0, 0.0),
                                (0.0, math.inf, 0.0)])
def test_run_refuses_a_background_out_of_range_before_computing(bg, tmp_path):
    with pytest.raises(BadInputError, match="--background-mt"):
        run_simulation(RunSettings(background_t=bg), out=tmp_path / "o")


def test_fix_summary_counts_trusted_fixes_beyond_5mm():
    fixes = [(0.0, True, 1e-3), (0.01, True, 6e-3), (0.02, False, 40e-3), (0.03, True, 4.9e-3)]
    s = fix_summary(fixes)
    assert s == {"fixes": 4, "fixes_trusted_fraction": 0.75, "trusted_fixes_beyond_5mm": 1}
    assert fix_summary([])["fixes"] == 0
