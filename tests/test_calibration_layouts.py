"""Calibration of any layout and any sensor layout, and ``calibrate --simulate``.

Independent references: the exact model of the as-built device (designkit.CoilArray) for the
simulated readings; the truth of a random as-built device for the fit; the workspace region's
own membership test for the plan's candidates.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from designkit import calibration as cal
from designkit.calibration.plan import candidate_points
from designkit.cli import main
from designkit.design import (BuildTolerances, default_design, design_from_dict, design_to_toml,
                              random_asbuilt)
from designkit.model.array import CoilArray


def _tilted_air_ring():
    return design_from_dict({"name": "air-ring", "array": {
        "layout": "ring", "count": 4, "radius_m": 0.06, "tilt_deg": 20.0},
        "core": {"enabled": False}})


def _true(design, seed=3):
    nom = CoilArray.from_design(design)
    ab = random_asbuilt(nom.coils, BuildTolerances(), np.random.default_rng(seed))
    return nom, dataclasses.replace(design, name="air-ring-built", asbuilt=ab)


def test_plan_candidates_lie_in_the_workspace_region():
    d = _tilted_air_ring()
    pts = candidate_points(d)
    region = d.workspace_region()
    assert region.contains(pts).all()
    # the ring's workspace is the square through its four top centres (tilted 45 degrees):
    # of the 7 x 7 grid over its bounding box, the 25 in the diamond, at 3 heights
    assert len(pts) == 25 * 3
    # the thesis' box: the whole 7 x 7 grid, as before
    assert len(candidate_points(default_design())) == 49 * 3


def test_rows_read_at_free_sensors_are_onboard():
    d = design_from_dict({"sensors": {"layout": "free",
                                      "positions_m": [[0.0, 0.0, 0.02], [0.05, 0.0, 0.02]]}})
    pos = d.sensor_poses()[0]
    plan = cal.onboard_plan(pos, d.n_coils).concat(cal.probe_plan([[0.01, 0.02, 0.04]],
                                                                  d.n_coils))
    groups = plan.groups(pos, cal.sensor_groups(d))
    assert set(groups[:-d.n_coils]) == {"onboard"} and set(groups[-d.n_coils:]) == {"probe"}
    assert cal.sensor_groups(default_design())[:9] == ["onboard-upper"] * 9


def test_simulate_writes_the_as_built_devices_readings(tmp_path, capsys):
    nom, true = _true(_tilted_air_ring())
    (tmp_path / "true.toml").write_text(design_to_toml(true))
    rng = np.random.default_rng(1)
    plan = cal.probe_plan(cal.workspace_points(true, 6, rng), nom.n_coils, 1.0, 2e-5)
    cal.write_csv(tmp_path / "plan.csv", plan, readings=False)
    args = ["calibrate", "--simulate", str(tmp_path / "plan.csv"), "--as-built",
            str(tmp_path / "true.toml")]
    assert main(args + ["--noise-t", "0", "--out", str(tmp_path / "m0.csv")]) == 0
    m0 = cal.read_csv(tmp_path / "m0.csv", nom.n_coils, 0.13)
    built = CoilArray.from_design(true)
    at = np.round(m0.points_m, 9)  # a reading's point is known to 1 nm (unique_points)
    exact = np.einsum("nik,nk->ni", built.actuation_matrix(at)[:, :3, :], m0.currents_a)
    np.testing.assert_allclose(m0.b_t, exact, rtol=1e-8, atol=1e-12)  # 9 digits in the file
    # the nominal device reads differently (that is what the fit finds)
    nominal = np.einsum("nik,nk->ni", nom.actuation_matrix(at)[:, :3, :],
                        m0.currents_a)
    assert np.abs(nominal - exact).max() > 1e-6
    # noise: the plan's sigma by default, reproducible by seed
    for name, seed in (("a", 7), ("b", 7), ("c", 8)):
        assert main(args + ["--seed", str(seed), "--out", str(tmp_path / f"{name}.csv")]) == 0
    a, b, c = ((tmp_path / f"{n}.csv").read_text() for n in "abc")
    assert a == b != c
    noisy = cal.read_csv(tmp_path / "a.csv", nom.n_coils, 0.13)
    z = (noisy.b_t - exact) / 2e-5
    assert 0.5 < z.std() < 1.6
    capsys.readouterr()


def test_simulate_refuses_bad_input_in_one_line_and_writes_nothing(tmp_path, capsys):
    nom, true = _true(_tilted_air_ring())
    (tmp_path / "true.toml").write_text(design_to_toml(true))
    plan = cal.probe_plan([[0.0, 0.0, 0.03]], nom.n_coils, 1.0)
    cal.write_csv(tmp_path / "plan.csv", plan, readings=False)
    out = tmp_path / "m.csv"
    cases = [
        (["--simulate", str(tmp_path / "plan.csv"), "--out", str(out)], "--as-built"),
        (["--simulate", str(tmp_path / "plan.csv"), "--as-built", str(tmp_path / "true.toml"),
          "--noise-t", "-1", "--out", str(out)], "--noise-t"),
        (["--simulate", str(tmp_path / "plan.csv"), "--as-built", "thesis", "--out", str(out)],
         "current columns"),
        (["--measurements", str(tmp_path / "plan.csv"), "--noise-t", "0", "--out", str(out)],
         "--noise-t"),
    ]
    for extra, word in cases:
        assert main(["calibrate", *extra]) == 1
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and word in err, err
    # a reading at the sensor range would be clipped: refused
    big = cal.probe_plan([[0.0, 0.0, 0.03]], nom.n_coils, 5000.0)
    cal.write_csv(tmp_path / "big.csv", big, readings=False)
    assert main(["calibrate", "--simulate", str(tmp_path / "big.csv"), "--as-built",
                 str(tmp_path / "true.toml"), "--out", str(out)]) == 1
    assert "sensor range" in capsys.readouterr().err
    assert not out.exists()


def test_a_tilted_air_ring_is_calibrated_within_its_standard_errors():
    """Onboard sensors (tilted with their coils) and a probe over the ring's workspace: the fit
    finds the as-built offsets, tilts and turns within 3.5 standard errors."""
    nom, true = _true(_tilted_air_ring(), seed=11)
    rng = np.random.default_rng(2)
    plan = cal.onboard_plan(nom.sensor_poses()[0], nom.n_coils).concat(
        cal.probe_plan(cal.workspace_points(true, 24, rng), nom.n_coils))
    meas = cal.simulate(CoilArray.from_design(true), plan, rng)
    res = cal.fit(nom, meas, BuildTolerances(), progress=False)
    truth = true.asbuilt.parameters(nom.coils)
    z = (res.params - truth)[res.fitted] / res.std_error[res.fitted]
    assert np.abs(z).max() < 3.5
    assert res.cost_after / (3 * len(meas)) < 1.3 < res.cost_before / (3 * len(meas))
