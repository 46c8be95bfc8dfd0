"""Sweeps and the optimize/sweep CLI, in-process; Dask on a local in-process cluster."""

import csv
import json
import math
import sys
from pathlib import Path

import pytest

from designkit import Coil, default_design
from designkit.model import electrical as el
from designkit.cli import main
from designkit.errors import BadInputError
from designkit.optimize.sweep import parse_param

ROOT = Path(__file__).resolve().parents[1]


def test_parse_param_errors_name_the_problem():
    assert parse_param("inner_radius_m=0.005:0.01:3").values.tolist() == [0.005, 0.0075, 0.01]
    with pytest.raises(BadInputError, match="one of"):
        parse_param("radius=0.005:0.01:3")
    with pytest.raises(BadInputError, match="empty"):
        parse_param("length_m=0.01:0.1:0")
    with pytest.raises(BadInputError, match="wire_diameter_m START"):
        parse_param("wire_diameter_m=-0.0007:0.001:4")


def _read(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


def test_sweep_cli_serial_writes_csv_and_png(tmp_path, capsys):
    out = tmp_path / "sw"
    assert main(["sweep", "--param", "inner_radius_m=0.006:0.014:3",
                 "--param", "length_m=0.03:0.1:4", "--workers", "1", "--out", str(out),
                 "--no-progress"]) == 0
    rows = _read(out / "sweep.csv")
    assert len(rows) == 12
    assert (out / "sweep.png").stat().st_size > 1000
    d = default_design()
    for r in rows:
        coil = Coil(float(r["inner_radius_m"]), float(r["outer_radius_m"]),
                    float(r["length_m"]), int(r["turns"]))
        # independent path: turns from the section, R from the electrical module
        # (at most the layered winding fit of the rule book)
        assert int(r["turns"]) == min(math.floor(el.turns_continuous(
            coil.inner_radius, coil.outer_radius, coil.length, 0.7e-3) + 1e-9),
            el.turns_from_geometry(coil.inner_radius, coil.outer_radius, coil.length, 0.7e-3,
                                   d.wire.packing))
        # the resistance the limit applies to: hot (100 C) with a core, where the device
        # constraints hold; the cold one (20 C) beside it for L/R and the power
        assert float(r["resistance_temperature_c"]) == 100.0
        assert float(r["resistance_ohm"]) == pytest.approx(
            el.resistance(coil, d.wire, temperature_c=100.0), rel=1e-12)
        assert float(r["resistance_cold_ohm"]) == pytest.approx(el.resistance(coil, d.wire),
                                                                rel=1e-12)
        # the thesis supply (36 V) is above the MD10C's 30 V rating: a rule-book violation of
        # every row, so no row is feasible however R and 5 L/R come out
        assert "rule design_supply_voltage_v" in r["reason"] and r["feasible"] == "0"
        assert ("resistance_ohm limit" in r["reason"]) == (float(r["resistance_ohm"]) > 6.0)
        if float(r["resistance_cold_ohm"]) > 6.0:
            assert "R(20 C) > 6 ohm" in r["reason"]
    out = capsys.readouterr()
    assert "no feasible design" in out.out
    # said at once, before any row: the rule and the key the sweep does not vary
    assert out.out.index("planned: 12 designs") < out.out.index("core model")
    note = [ln for ln in out.err.splitlines() if "note:" in ln]
    assert len(note) == 1 and "design_supply_voltage_v" in note[0]
    assert "drive.supply_voltage_v" in note[0] and "not varied" in note[0] and "36 V" in note[0]


def test_sweep_cli_processes_match_serial(tmp_path):
    # 6 designs: the chunks start at one design, so two workers share them whatever the size
    args = ["sweep", "--param", "outer_radius_m=0.015:0.025:3", "--param",
            "length_m=0.02:0.1:2", "--no-progress"]
    assert main(args + ["--workers", "1", "--out", str(tmp_path / "a")]) == 0
    assert main(args + ["--workers", "2", "--out", str(tmp_path / "b")]) == 0
    assert _read(tmp_path / "a" / "sweep.csv") == _read(tmp_path / "b" / "sweep.csv")


def test_sweep_on_a_local_dask_cluster(tmp_path):
    import dask.distributed as distributed

    args = ["sweep", "--param", "inner_radius_m=0.005:0.015:2", "--param",
            "length_m=0.02:0.1:2", "--no-progress"]
    assert main(args + ["--workers", "1", "--out", str(tmp_path / "serial")]) == 0
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        assert main(args + ["--scheduler", cluster.scheduler_address,
                            "--out", str(tmp_path / "dask")]) == 0
    assert _read(tmp_path / "dask" / "sweep.csv") == _read(tmp_path / "serial" / "sweep.csv")


@pytest.mark.parametrize("bad", [
    ["--param", "bogus_m=0.01:0.02:3"],
    ["--param", "length_m=0.01:0.1:0"],
    ["--param", "wire_diameter_m=-0.0007:0.001:3"],
    ["--param", "length_m=0.01:0.1"],
    [],
])
def test_sweep_bad_input_fails_cleanly(tmp_path, capsys, bad):
    out = tmp_path / "bad"
    assert main(["sweep", *bad, "--out", str(out), "--no-progress"]) != 0
    assert "error" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())


def test_optimize_cli_coil_problem_writes_json_with_si_keys(tmp_path, capsys):
    out = tmp_path / "opt"
    assert main(["optimize", "--problem", "coil", "--out", str(out), "--starts", "4"]) == 0
    data = json.loads((out / "optimize.json").read_text())
    for key in ("inner_radius_m", "outer_radius_m", "length_m", "turns", "resistance_ohm",
                "inductance_h", "time_constant_s", "current_a", "force_n", "constraints",
                "evaluations", "seconds"):
        assert key in data
    assert data["resistance_ohm"] <= 6.0 and 5 * data["time_constant_s"] <= 0.1
    assert all(c["margin"] >= -1e-12 for c in data["constraints"].values())
    assert "thesis 24/38/100" in capsys.readouterr().out


@pytest.fixture(scope="module")
def device_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("device") / "opt"
    code = main(["optimize", "--out", str(out), "--starts", "2"])
    return code, out


def test_optimize_cli_device_writes_the_issue_keys_and_a_loadable_design(device_run, tmp_path):
    from designkit.design import load_design

    code, out = device_run
    assert code == 0
    data = json.loads((out / "optimize.json").read_text())
    for key in ("inner_radius_m", "outer_radius_m", "length_m", "turns", "wire_diameter_m",
                "core_radius_m", "core_length_m", "resistance_ohm", "inductance_h",
                "time_constant_s", "supply_voltage_v", "current_a", "force_n", "core_model",
                "temperature_c", "seconds", "margins", "constraints"):
        assert key in data, key
    assert data["feasible"] and all(m >= -1e-12 for m in data["margins"].values())
    assert data["supply_voltage_v"] <= 30.0 and data["resistance_ohm"] < 6.0
    assert data["settling_time_s"] < 0.1
    d = load_design(out / "design.toml")
    # the design file carries the optimum (independent path: the Design's own fields)
    assert d.coil.turns == data["turns"] and d.core.bh == "steel1010"
    assert d.coil.inner_radius_m == pytest.approx(data["inner_radius_m"], rel=1e-12)
    assert d.drive.supply_voltage_v == 30.0
    # the thesis device is evaluated alongside and fails the constraints it should
    assert "settling_time_s" in data["base_design"]["violated"]
    # --design accepts the written file
    assert main(["optimize", "--problem", "coil", "--design", str(out / "design.toml"),
                 "--starts", "1", "--out", str(tmp_path / "again")]) == 0


def test_optimize_cli_infeasible_device_says_which_constraint(tmp_path, capsys):
    toml = tmp_path / "d.toml"
    toml.write_text("[optimize]\nheight_m = 0.015\n")
    out = tmp_path / "opt"
    assert main(["optimize", "--design", str(toml), "--out", str(out)]) != 0
    err = capsys.readouterr().err
    assert "magnet_bottom_m" in err and "0.0048 m" in err
    assert not out.exists()


def test_optimize_cli_bad_design_file(tmp_path, capsys):
    toml = tmp_path / "d.toml"
    toml.write_text("[optimize]\nmin_inner_radius_m = 0.0248\n")
    out = tmp_path / "opt"
    assert main(["optimize", "--problem", "coil", "--design", str(toml), "--out",
                 str(out)]) != 0
    assert "outer_radius_m" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow  # a benchmark's smoke test (CI runs it); the optimum: test_optimize.py
def test_bench_optimize_smoke(tmp_path):
    sys.path.insert(0, str(ROOT / "studies"))
    import bench_optimize

    r = bench_optimize.run(tmp_path, quick=True)
    assert r["quick"] and r["feasible"] and r["device_median_seconds"] > 0
    assert (tmp_path / "bench_optimize.json").exists()


def test_array_sweep_on_a_local_dask_cluster_matches_serial_and_the_rendering_lp(tmp_path):
    """Whole arrays with the rendering objective: Dask (LocalCluster, 2 workers) = serial."""
    import dask.distributed as distributed
    args = ["sweep", "--array", "--design", "optimized", "--param", "pitch_m=0.05:0.06:2",
            "--param", "wire_diameter_m=0.0008:0.0009:2", "--no-progress"]
    assert main(args + ["--workers", "1", "--out", str(tmp_path / "serial")]) == 0
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        assert main(args + ["--scheduler", cluster.scheduler_address,
                            "--out", str(tmp_path / "dask")]) == 0
    a = _read(tmp_path / "dask" / "sweep.csv")
    assert a == _read(tmp_path / "serial" / "sweep.csv")
    assert len(a) == 4 and any(r["feasible"] == "1" for r in a)
    for r in a:
        assert float(r["force_n"]) > 0


def test_rendering_lp_is_bracketed_by_two_independent_allocations():
    """At the centre axis point the centre coil alone (|I| = limit) pushes with no lateral
    force, so the LP optimum is at least that; dropping Fx = Fy = 0 (closed-form knapsack) can
    only raise it."""
    import numpy as np

    from designkit.model.metrics import max_vertical_force
    from designkit.design import load_design
    from designkit.optimize import RodCoil, array_force_per_amp, rendering_force

    d = load_design("optimized")
    pts = np.array([[0.0, 0.0, 0.03], [0.02, -0.01, 0.025]])
    r = rendering_force(d, points_m=pts)
    c, k = d.coil, d.core
    x = [c.inner_radius_m, c.outer_radius_m, c.length_m, k.radius_m, k.length_m,
         k.offset_m + k.length_m / 2 - c.length_m / 2, d.wire.diameter_m]
    f = array_force_per_amp(RodCoil(tuple(x), c.turns, d.drive.max_current_a), d.array, pts,
                            d.magnet.moment_a_m2)
    centre_alone = abs(f[0, 2, 4]) * d.drive.max_current_a
    assert abs(f[0, 0, 4]) < 1e-12 and abs(f[0, 1, 4]) < 1e-12
    free = max_vertical_force(f[:, 2, :], d.drive.max_current_a, d.drive.total_current_a)
    lp = np.array(r["upward_force_n"])
    assert lp[0] >= centre_alone * (1 - 1e-9)
    assert np.all(lp <= free * (1 + 1e-9))


def test_rendering_winding_part_matches_the_coil_array_field_engine():
    """array_force_per_amp with the core switched off (ratio 0) against designkit.CoilArray of
    air coils (independent assembly: poses, frames, F = G^T m)."""
    import numpy as np

    from designkit.model.array import CoilArray, force_matrix
    from designkit.optimize import RodCoil, array_force_per_amp

    d = default_design().replace(core=None)
    arr = CoilArray.from_design(d)
    rng = np.random.default_rng(2)
    pts = np.c_[rng.uniform(-0.06, 0.06, (6, 2)), rng.uniform(0.015, 0.06, 6)]
    a = arr.actuation_matrix(pts)
    m = np.array([0.0, 0.0, d.magnet.moment_a_m2])
    ref = np.einsum("jk,nkc->njc", force_matrix(m), a[:, 3:, :])
    x = (0.012, 0.019, 0.1, 0.006, 0.05, 0.0, 0.7e-3)
    got = array_force_per_amp(RodCoil(x, 1429, 6.0, core_force_ratio=0.0), d.array, pts,
                              d.magnet.moment_a_m2)
    np.testing.assert_allclose(got, ref, rtol=1e-7, atol=1e-9)


@pytest.mark.slow  # a benchmark's smoke test (CI runs it); the dask sweeps: the tests above
def test_bench_sweep_smoke(tmp_path):
    import dask.distributed  # noqa: F401  (a test dependency: no skip)
    sys.path.insert(0, str(ROOT / "studies"))
    import bench_sweep

    r = bench_sweep.run(tmp_path, quick=True)
    assert r["quick"] and r["runs"]["dask_2"]["designs_per_s"] > 0
    assert (tmp_path / "bench_sweep.json").exists()
