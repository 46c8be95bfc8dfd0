"""The runner on a board that is not 3 x 3: an air-core 1 x 2 design (two coils, two sensors per
array) runs end to end on the simulated device -- the start-up calibration through the
firmware's path, the sensor pipeline, the localizer and the allocator -- and its sensor side
sizes itself from the map, not from the coil count."""

from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest

from designkit import fieldmap
from designkit.design import default_design
from designkit.sim.run import RunSettings, run_simulation
from firmware_io.localization import Estimate
from firmware_io.runner import SensorFrame, SensorLayout, SensorPipeline

BOX = (np.array([-0.07, -0.03, 0.015]), np.array([0.07, 0.03, 0.06]))


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    d0 = default_design()
    design = dataclasses.replace(d0, array=dataclasses.replace(d0.array, rows=1, columns=2),
                                 core=None)
    path = tmp_path_factory.mktemp("map") / "map.npz"
    fieldmap.write(path, fieldmap.build(design, box=BOX, spacing=0.02, n_check=20,
                                        progress=False))
    return design, path


def test_one_by_two_air_core_board_runs(small, tmp_path):
    design, path = small
    out = tmp_path / "run"
    s = run_simulation(RunSettings(obj="plane", duration_s=0.4), design=design, map_path=path,
                       out=out, progress=False)
    rows = list(csv.DictReader((out / "run.csv").open()))
    assert len(rows) == 400
    # two coils: two current and two command columns, no third
    assert "cmd2_a" in rows[0] and "cmd3_a" not in rows[0]
    running = [r for r in rows if r["state"] == "running"]
    assert len(running) > 100, {r["state"] for r in rows}
    # the fixes are the magnet's (4 sensors, noise 0.1 mT): within a few mm of the truth
    assert s["localization_mae_m"] < 3e-3
    assert max(abs(float(r["cmd1_a"])) + abs(float(r["cmd2_a"])) for r in running) > 0


class _Estimator:
    def __init__(self):
        self.shapes = []

    def reset(self):
        pass

    def estimate(self, readings_t, currents_a=None, *, usable=None, seed=None, time_s=None):
        self.shapes.append((np.shape(readings_t), np.shape(currents_a)))
        return Estimate(np.zeros(3), np.array([0.0, 0.0, 1.0]), True)


class _Map:
    sensor_positions_m = np.zeros((2, 4, 3))

    def sensor_coil_field(self):
        return np.zeros((2, 4, 3, 2))


def test_pipeline_sizes_from_the_map_not_the_coil_count():
    est = _Estimator()
    p = SensorPipeline(est, SensorLayout.of_map(_Map()), lambda t: np.zeros(2),
                       np.array([0.0, 0.0, 1.0]))
    assert p.n == 8 and p.excluded.shape == (8,)
    fix = p.process(SensorFrame(np.zeros((8, 3)), ("ok",) * 8, 0.0))
    assert fix.ok and est.shapes == [((8, 3), (2,))]
    # a frame of the wrong size: not ok, with the reason, no exception
    bad = p.process(SensorFrame(np.zeros((4, 3)), ("ok",) * 4, 0.0))
    assert not bad.ok and "expected (8, 3)" in bad.problems[0][1]
