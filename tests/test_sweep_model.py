"""``designkit sweep`` evaluates a design with the design's own core model by default and
names the model in stdout, the CSV and the figure; the array sweep evaluates the default
device (whose core reaches below its winding) instead of marking it invalid."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from designkit.cli import main
from designkit.coil import Coil
from designkit.design import default_design


def _rows(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_sweep_default_model_is_the_designs_core(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["sweep", "--param", "length_m=0.1:0.1:1", "--out", str(out), "--workers", "1",
                 "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "core model: surface-current" in text
    (row,) = _rows(out / "sweep.csv")
    assert row["core_model"] == "surface-current"
    # independent reference: the field engine's cored coil (the report's single-coil force);
    # the air coil gives ~366 mN, 8x less
    d = default_design()
    _, g = Coil.from_design(d).field(np.array(d.design_point_m), d.drive.max_current_a,
                                     gradient=True)
    fz_ref = abs(d.magnet.moment_a_m2 * g[2, 2])
    n = int(row["turns"])
    assert float(row["force_n"]) == pytest.approx(fz_ref * n / d.coil.turns, rel=0.03)
    # a cheaper model is an explicit choice, and stdout says it is not the design's own
    assert main(["sweep", "--param", "length_m=0.1:0.1:1", "--out", str(tmp_path / "a"),
                 "--workers", "1", "--core-model", "air", "--no-progress"]) == 0
    assert "core model: air (not the design's own surface-current" in capsys.readouterr().out
    (air,) = _rows(tmp_path / "a" / "sweep.csv")
    assert air["core_model"] == "air" and float(air["force_n"]) < 0.3 * float(row["force_n"])


def test_array_sweep_evaluates_the_default_device(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["sweep", "--array", "--param", "pitch_m=0.05:0.05:1", "--out", str(out),
                 "--workers", "1", "--no-progress"]) == 0
    (row,) = _rows(out / "sweep.csv")
    assert row["valid"] == "1" and float(row["force_n"]) > 0
    assert "core longer" not in row["reason"]
    # what report says the thesis device misses, the sweep says too (same rule book)
    assert "rule design_supply_voltage_v" in row["reason"]
    assert "core model: steel1010 fast slice model" in capsys.readouterr().out
