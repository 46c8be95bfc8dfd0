"""As-built designs and the calibration fit (docs/calibration.md).

Default tests use air-coil arrays (no coupled core solve: the forward model is exact, so the
fit must find the truth within its standard errors); the cored 2 x 2 check is marked slow.
"""

from __future__ import annotations

import dataclasses
import json
import sys

import numpy as np
import pytest

from designkit import calibration as cal
from designkit.model.array import CoilArray, force_matrix
from designkit.design.asbuilt import (PARAMETERS, AsBuilt, BuildTolerances, CoilDeviation,
                                      random_asbuilt)
from designkit.calibration.model import ForwardModel
from designkit.cli import main
from designkit.design import default_design, design_to_toml, load_design


def _air(rows=1, columns=3):
    return dataclasses.replace(default_design(), core=None, name="air").replace(
        **{"array.rows": rows, "array.columns": columns})


def _measured(design, seed=3, probe=24):
    nom = CoilArray.from_design(design)
    rng = np.random.default_rng(seed)
    ab = random_asbuilt(nom.coils, BuildTolerances(), rng)
    truth = CoilArray.from_design(design.replace(asbuilt=ab))
    plan = cal.onboard_plan(nom.sensor_positions_m(), nom.n_coils).concat(
        cal.probe_plan(cal.workspace_points(design, probe, rng), nom.n_coils))
    return nom, ab, cal.simulate(truth, plan, rng)


def test_asbuilt_round_trips_and_a_nominal_design_keeps_its_hash(tmp_path):
    d = default_design()
    assert "asbuilt" not in d.to_dict()
    nom = CoilArray.from_design(d)
    ab = random_asbuilt(nom.coils, BuildTolerances(), np.random.default_rng(1), mu_r=450.0)
    built = d.replace(asbuilt=ab)
    path = tmp_path / "asbuilt.toml"
    path.write_text(design_to_toml(built))
    again = load_design(path)
    assert again == built and again.spec_hash() == built.spec_hash() != d.spec_hash()


def test_from_design_builds_the_deviations():
    d = default_design().replace(**{"array.rows": 1, "array.columns": 2})
    dev = CoilDeviation(dx_m=4e-4, dy_m=-3e-4, dz_m=2e-4, tilt_x_rad=0.01, turns=1400,
                        core_relative_permeability=450.0, core_offset_m=5e-4)
    arr = CoilArray.from_design(d.replace(asbuilt=AsBuilt((dev, CoilDeviation()))))
    nominal = CoilArray.from_design(d)
    c, c0 = arr.coils[0], nominal.coils[0]
    np.testing.assert_allclose(np.subtract(c.pose.position, c0.pose.position),
                               [4e-4, -3e-4, 2e-4], atol=1e-15)
    # a rotation by 0.01 rad about x: the axis tips towards -y
    np.testing.assert_allclose(c.pose.matrix[:, 2], [0.0, -np.sin(0.01), np.cos(0.01)],
                               atol=1e-15)
    assert c.turns == 1400 and c.core.relative_permeability == 450.0
    assert c.core.offset == pytest.approx(c0.core.offset + 5e-4, abs=1e-15)
    assert arr.coils[1] == nominal.coils[1]


def test_a_moved_coil_field_is_the_nominal_field_translated():
    """Independent of the model: translation invariance of the field."""
    d = _air(1, 1)
    shift = np.array([3e-4, -2e-4, 5e-4])
    moved = CoilArray.from_design(d.replace(asbuilt=AsBuilt((CoilDeviation(*shift),))))
    nominal = CoilArray.from_design(d)
    p = np.array([[0.01, 0.02, 0.03], [-0.02, 0.0, 0.05]])
    np.testing.assert_allclose(moved.actuation_matrix(p), nominal.actuation_matrix(p - shift),
                               rtol=1e-9, atol=1e-15)


def test_jacobian_matches_central_differences():
    nom = CoilArray.from_design(_air(1, 2))
    pts = np.array([[0.01, 0.02, 0.03], [-0.03, 0.01, 0.02], [0.0, -0.02, -0.114]])
    model = ForwardModel(nom.coils, pts, np.zeros((3, 3, 2)))
    th = np.array([[2e-4, -1e-4, 3e-4, 0.004, -0.003, 0.01, 0.0, 0.0]] * 2)
    _, jac, _ = model.columns(th, True)
    for j, h in enumerate([1e-6, 1e-6, 1e-6, 1e-5, 1e-5, 1e-4]):
        up, dn = th.copy(), th.copy()
        up[0, j] += h
        dn[0, j] -= h
        fd = (model.columns(up) - model.columns(dn))[:, :, 0] / (2 * h)
        # tilts: the small rotation is composed on the left, exact to O(tilt)
        tol = 1e-5 if j < 3 or j == 5 else 1e-2
        np.testing.assert_allclose(jac[:, :, 0, j], fd, rtol=0, atol=tol * np.abs(fd).max(),
                                   err_msg=PARAMETERS[j])


def _cored_pair():
    d = default_design().replace(**{"array.rows": 1, "array.columns": 2})
    return d, CoilArray.from_design(d)


def _built(nom, th):
    return CoilArray(AsBuilt.from_parameters(nom.coils, th).apply(nom.coils),
                     sensor_offset_m=nom.sensor_offset_m)


def test_the_coupling_slope_is_the_exact_coupled_models_derivative():
    """Column k of the fit's Jacobian by core j's ln(mu_r) (its own core's difference plus the
    coupling's slope from the adjoint) against central differences of the exact coupled solve
    (an independent route: two more coupled solves per core). Dropping the coupling's slope
    (the single-core difference alone) misses more than 10 % of it, the neighbour's column
    entirely."""
    from designkit.calibration.model import coupled_forward_model

    d, nom = _cored_pair()
    pts = np.array([[0.01, 0.02, 0.03], [-0.03, 0.01, 0.02], [0.025, 0.0, -0.01],
                    [0.0, 0.0, 0.01]])
    th = np.zeros((2, 8))
    th[:, 6] = np.log(0.45)
    th[0, 7], th[1, 0] = 3e-4, 4e-4
    th[0, 5] = round(nom.coils[0].turns * 1.01) / nom.coils[0].turns - 1  # whole turns
    built = _built(nom, th)
    model = coupled_forward_model(nom.coils, built, th, pts)
    b, jac, cross = model.columns(th, True)
    exact = built.actuation_matrix(pts)[:, :3]
    np.testing.assert_allclose(b, exact, rtol=0, atol=1e-9 * np.abs(exact).max())
    h, j = 0.02, 0  # core 0: its own column and its neighbour's
    up, dn = th.copy(), th.copy()
    up[j, 6] += h
    dn[j, 6] -= h
    fd = (_built(nom, up).actuation_matrix(pts)[:, :3]
          - _built(nom, dn).actuation_matrix(pts)[:, :3]) / (2 * h)
    got = cross[:, :, :, j].copy()
    got[:, :, j] += jac[:, :, j, 6]
    np.testing.assert_allclose(got, fd, rtol=0, atol=2e-3 * np.abs(fd).max())
    own_only = np.zeros_like(got)
    own_only[:, :, j] = jac[:, :, j, 6] - cross[:, :, j, j]
    assert np.abs(own_only - fd).max() > 0.1 * np.abs(fd).max()


def _cored_device(design, seed, probe):
    """A random as-built device of the cored ``design`` (mu_r 450), its onboard + ``probe``-point
    plan; returns nominal array, as-built, true array, plan, tolerances and the generator."""
    nom = CoilArray.from_design(design)
    rng = np.random.default_rng(seed)
    tol = BuildTolerances()
    ab = random_asbuilt(nom.coils, tol, rng, mu_r=450.0)
    truth = CoilArray.from_design(design.replace(asbuilt=ab))
    plan = cal.onboard_plan(nom.sensor_positions_m(), nom.n_coils).concat(
        cal.probe_plan(cal.workspace_points(design, probe, rng), nom.n_coils))
    return nom, ab, truth, plan, tol, rng


def test_a_cored_fit_has_calibrated_standard_errors():
    """1 x 2 cored device (mu_r 450), onboard arrays + 12 probe points, readings from the exact
    coupled model: the 16 parameters' z = (fit - truth) / standard error have rms within
    [0.5, 1.6] (16 unit normals: 95 % within [0.66, 1.3]) and none beyond 3.5. Without the
    coupling's slope in the Jacobian a coil's turns come out ~23 standard errors off (rms ~8)."""
    d, _ = _cored_pair()
    nom, ab, truth, plan, tol, _ = _cored_device(d, 5, 12)
    res = cal.fit(nom, cal.simulate(truth, plan, np.random.default_rng(100)), tol,
                  progress=False)
    z = ((res.params - ab.parameters(nom.coils)) / res.std_error)[res.fitted]
    assert len(z) == 16 and 0.5 <= np.sqrt(np.mean(z * z)) <= 1.6 and np.abs(z).max() < 3.5


def test_a_nearly_collinear_pair_is_one_combined_quantity():
    """Whitened covariance [[1, -0.98], [-0.98, 1]] * v: the best-determined combination is the
    sum (eigenvalue v (1 - 0.98), closed form), its standard error adds the model-error shift
    along it; the pair is not separately identifiable."""
    from designkit.calibration.fit import CORRELATION_LIMIT, _combined

    mask = np.zeros((1, 8), bool)
    mask[0, 5:7] = True
    sig = np.array([[1, 1, 1, 1, 1, 0.02, 1.0, 1]])
    v, rho = 0.5, -0.98
    cov = v * np.array([[1.0, rho], [rho, 1.0]])
    corr = np.array([[0.0, rho], [rho, 0.0]])
    theta = np.zeros((1, 8))
    theta[0, 5:7] = [0.01, -0.3]
    shift = np.array([0.03, 0.04])
    [c] = _combined(theta, cov, shift, mask, sig, np.array([5, 6]), corr)
    assert abs(rho) >= CORRELATION_LIMIT and c["correlation"] == rho
    vec = np.array(c["coefficients"]) * [0.02, 1.0]
    assert abs(vec @ vec - 1) < 1e-12 and abs(abs(vec @ [1, 1]) - np.sqrt(2)) < 1e-9
    model_err = (vec @ shift) ** 2
    assert c["std_error"] == pytest.approx(np.sqrt(v * (1 + rho) + model_err), rel=1e-9)
    assert c["value"] == pytest.approx(np.dot(c["coefficients"], [0.01, -0.3]), rel=1e-12)
    assert c["identifiable"] == (c["std_error"] < 0.5)


def test_fit_finds_an_air_array_within_three_standard_errors():
    nom, ab, meas = _measured(_air())
    res = cal.fit(nom, meas, BuildTolerances(), progress=False)
    true = ab.parameters(nom.coils)
    z = (res.params - true)[res.fitted] / res.std_error[res.fitted]
    assert np.abs(z).max() < 3.5  # turns are whole numbers in the truth: +-0.5 turn extra
    assert res.identifiable[res.fitted].all()
    # the readings are fitted to their noise
    assert res.cost_after / (3 * len(meas)) < 1.3 < res.cost_before / (3 * len(meas))


def test_a_calibrated_device_gives_the_runner_what_the_true_device_would():
    """What a run takes from the map besides A(p): where the Hall boards' sensors are and the
    coils' field there (the localizer subtracts it). The boards do not move with a displaced
    coil (the onboard readings are taken at their nominal places), and the calibrated model's
    coil field at its sensors and force per ampere along a path are within 1/5 of the nominal
    model's error of the true device's."""
    d = _air()
    nom, ab, meas = _measured(d)
    truth = CoilArray.from_design(d.replace(asbuilt=ab))
    np.testing.assert_array_equal(truth.sensor_positions_m(), nom.sensor_positions_m())
    res = cal.fit(nom, meas, BuildTolerances(), progress=False)
    calib = CoilArray.from_design(d.replace(asbuilt=AsBuilt.from_parameters(nom.coils,
                                                                           res.params)))
    path = np.c_[np.linspace(-0.04, 0.04, 9), np.zeros(9), np.linspace(0.03, 0.06, 9)]
    moment = np.array([0.0, 0.0, 1.0])

    def runtime(arr):  # coils' field at the sensors (T/A), force per ampere on the path (N/A)
        s = arr.actuation_matrix(arr.sensor_positions_m().reshape(-1, 3))[:, :3, :]
        f = np.einsum("ij,kjl->kil", force_matrix(moment), arr.actuation_matrix(path)[:, 3:])
        return s, f

    for true, got, base in zip(runtime(truth), runtime(calib), runtime(nom)):
        assert np.abs(got - true).max() <= np.abs(base - true).max() / 5


def test_calibrate_command_writes_a_design_and_the_report(tmp_path):
    d = _air()
    (tmp_path / "d.toml").write_text(design_to_toml(d))
    nom, ab, meas = _measured(d)
    cal.write_csv(tmp_path / "m.csv", meas)
    out = tmp_path / "cal"
    assert main(["calibrate", "--measurements", str(tmp_path / "m.csv"), "--design",
                 str(tmp_path / "d.toml"), "--magnet-moment", "0,0,-0.88", "--out", str(out),
                 "--no-progress"]) == 0
    built = load_design(out / "asbuilt.toml")
    assert built.magnet.moment_vector_a_m2 == pytest.approx((0.0, 0.0, -0.88))
    rep = json.loads((out / "calibration.json").read_text())
    assert rep["n_parameters"] == 18 and rep["unidentifiable"] == [] and rep["combined"] == []
    assert set(rep["residual_by_group"]) == {"onboard-upper", "onboard-lower", "probe"}
    up = rep["residual_by_group"]["onboard-upper"]
    assert up["chi2_per_reading_after"] < 1.5 < up["chi2_per_reading_before"]
    # the written design carries the fit, within the reported standard errors of the truth
    fitted, true = built.asbuilt.parameters(nom.coils), ab.parameters(nom.coils)
    for p in rep["parameters"]:
        k, j = p["coil"] - 1, PARAMETERS.index(p["parameter"])
        assert fitted[k, j] == pytest.approx(p["value"], abs=0.51 / nom.coils[k].turns)
        assert abs(p["value"] - true[k, j]) < 3.5 * p["std_error"]


def _csv(path, header, rows):
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(r) for r in rows) + "\n")
    return path


HEAD = ["x_m", "y_m", "z_m", "i1_a", "i2_a", "i3_a", "bx_t", "by_t", "bz_t"]
ROW = ["0.01", "0.0", "0.03", "1", "0", "0", "1e-4", "0", "2e-3"]


@pytest.mark.parametrize("header,rows,message", [
    (HEAD[:-1], [ROW[:-1]], "column bz_t"),
    (HEAD + ["temp_c"], [ROW + ["20"]], "column temp_c"),
    (HEAD[:5] + HEAD[6:], [ROW[:5] + ROW[6:]], "current columns"),
    (HEAD, [ROW, ROW[:3] + ["nan"] + ROW[4:]], "row 3, column i1_a"),
    (HEAD, [ROW], "distinct readings"),
    (HEAD, [ROW[:8] + ["0.2"]], "row 2, columns bx_t/by_t/bz_t"),
])
def test_bad_measurement_files_are_refused_before_the_fit(tmp_path, capsys, header, rows,
                                                          message):
    (tmp_path / "d.toml").write_text(design_to_toml(_air()))
    path = _csv(tmp_path / "m.csv", header, rows)
    out = tmp_path / "out"
    assert main(["calibrate", "--measurements", str(path), "--design", str(tmp_path / "d.toml"),
                 "--out", str(out), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and err.count("\n") == 1
    assert not out.exists()


def test_a_fit_that_does_not_converge_writes_nothing(tmp_path, capsys, monkeypatch):
    fit_module = sys.modules["designkit.calibration.fit"]  # the package re-exports fit()
    d = _air()
    (tmp_path / "d.toml").write_text(design_to_toml(d))
    cal.write_csv(tmp_path / "m.csv", _measured(d)[2])
    monkeypatch.setattr(fit_module, "MAX_ITERATIONS", 1)
    out = tmp_path / "out"
    assert main(["calibrate", "--measurements", str(tmp_path / "m.csv"), "--design",
                 str(tmp_path / "d.toml"), "--out", str(out), "--no-progress"]) == 1
    assert "did not converge" in capsys.readouterr().err and not out.exists()


def test_plan_command_writes_probe_rows_and_what_the_arrays_see(tmp_path, capsys):
    (tmp_path / "d.toml").write_text(design_to_toml(_air()))
    out = tmp_path / "plan.csv"
    assert main(["calibrate", "--plan", "--points", "5", "--design", str(tmp_path / "d.toml"),
                 "--out", str(out), "--no-progress"]) == 0
    lines = out.read_text().splitlines()
    assert lines[0] == "x_m,y_m,z_m,i1_a,i2_a,i3_a,sigma_t" and len(lines) == 1 + 5 * 3
    summary = json.loads(out.with_suffix(".json").read_text())
    assert summary["onboard"]["n_parameters"] == 18
    # added readings only add information: no posterior grows
    on, plan = (summary[k]["posterior_over_prior"] for k in ("onboard", "with_plan"))
    assert all(0 < plan[k] <= on[k] * (1 + 1e-9) <= 1 + 1e-9 for k in on)
    assert "onboard arrays alone identify" in capsys.readouterr().out


@pytest.mark.slow
def test_cored_array_calibration_meets_the_held_out_accuracy():
    """2 x 2 cored array, mu_r 450 steel: A(p) at 200 held-out points within 1 % of each row's
    largest value and at most 1/5 of the nominal model's error."""
    d = default_design().replace(**{"array.rows": 2, "array.columns": 2})
    nom, ab, truth, plan, tol, rng = _cored_device(d, 3, 48)
    res = cal.fit(nom, cal.simulate(truth, plan, rng), tol, progress=False)
    calib = CoilArray.from_design(d.replace(asbuilt=AsBuilt.from_parameters(nom.coils,
                                                                           res.params, tol)))
    ho = cal.workspace_points(d, 200, rng)
    a_true = truth.actuation_matrix(ho)
    e_cal = cal.actuation_error(calib.actuation_matrix(ho), a_true).max()
    e_nom = cal.actuation_error(nom.actuation_matrix(ho), a_true).max()
    assert e_cal <= 0.01 and e_cal <= e_nom / 5


@pytest.mark.slow
def test_run_simulate_as_built_uses_the_built_plant(tmp_path):
    """The plant is the as-built device, the runner the nominal map: the summary names both."""
    d = default_design()  # the start-up sensor calibration needs the 3 x 3 board
    nom = CoilArray.from_design(d)
    ab = random_asbuilt(nom.coils, BuildTolerances(), np.random.default_rng(2), mu_r=450.0)
    (tmp_path / "nominal.toml").write_text(design_to_toml(d))
    (tmp_path / "true.toml").write_text(design_to_toml(d.replace(asbuilt=ab, name="true")))
    out = tmp_path / "run"
    assert main(["run", "--simulate", "--object", "plane", "--duration", "0.3", "--design",
                 str(tmp_path / "nominal.toml"), "--as-built", str(tmp_path / "true.toml"),
                 "--out", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["as_built"]["plant"] == "true"
    assert summary["as_built"]["force_error_rms_n"] == summary["force_error_rms_n"] > 0


@pytest.mark.slow
def test_calibration_study_smoke(tmp_path):
    from conftest import load_study

    res = load_study("calibration").main(["--out", str(tmp_path), "--quick", "--plans",
                                          "onboard"])
    [row] = res["rows"]
    assert row["rows"] == 64 and row["calibrated_max"] < row["nominal_max"] / 5
    assert (tmp_path / "calibration.json").is_file()
