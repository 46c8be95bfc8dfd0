"""The drive chain: the driver the design names (firmware_io.hw.driver), the drive record
(firmware_io.mapfile.drive) designkit writes, the map stores and the runner uses, and the one
supply rule: the coils get the design's supply; a supply outside the named driver's rating is a
rule `check` reports, the hardware entry point refuses and the simulator runs and lists.

Expected numbers by hand: R = rho l / (pi d^2 / 4) with l = N 2 pi r_mean, alpha of annealed
copper (IEC 60028), duty = V / Vs (sign-magnitude driver), the MD10C's datasheet ratings."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from designkit.design import default_design
from designkit.model.electrical import driver_rating
from designkit.optimize import device_problem_for, rule_table
from designkit.sim import drive_data
from designkit.sim.device import SimulatedDevice
from firmware_io.errors import BadInputError
from firmware_io.hw.driver import MD10C, CoilDrive, DriverRating, voltage_to_command
from firmware_io.mapfile import SaturationTable
from firmware_io.mapfile.drive import DriveRecord
from firmware_io.runner import RunnerConfig

D24 = default_design().replace(**{"drive.supply_voltage_v": 24.0})
D48 = default_design().replace(**{"drive.supply_voltage_v": 48.0,
                                  "drive.driver_max_voltage_v": 50.0})


def _r_ref(design) -> float:
    """The default coil's R at 20 C by hand, ohm."""
    c, w = design.coil, design.wire
    r_mean = (c.inner_radius_m + c.outer_radius_m) / 2
    return w.resistivity_ohm_m * c.turns * 2 * math.pi * r_mean / (math.pi * w.diameter_m ** 2 / 4)


# ---------------------------------------------------------------------------------------------
# the driver
def test_md10c_preset_is_the_default_and_its_datasheet_ratings():
    assert MD10C == DriverRating() == driver_rating(default_design().drive)
    assert (MD10C.min_voltage_v, MD10C.max_voltage_v, MD10C.continuous_current_a,
            MD10C.max_pwm_frequency_hz) == (5.0, 30.0, 13.0, 20e3)


def test_supply_rule_names_the_keys_and_the_driver():
    assert MD10C.supply_violation(24.0) == MD10C.supply_violation(30.0) == ""
    high = MD10C.supply_violation(36.0)
    assert "drive.supply_voltage_v = 36 V is above" in high and "Cytron MD10C" in high
    assert "drive.driver_max_voltage_v" in high and "30 V" in high
    assert "below" in MD10C.supply_violation(3.0)
    big = DriverRating("48 V bridge", 10.0, 50.0, 20.0, 25e3)
    assert big.supply_violation(48.0) == "" and "above" in big.supply_violation(51.0)
    # the supply a coil may be designed for: the design's own within the rating, else the rating
    assert MD10C.usable_supply_v(24.0) == 24.0 and MD10C.usable_supply_v(36.0) == 30.0
    # what the supply pushes through R, at most the continuous rating
    assert MD10C.max_current_a(24.0, 6.0) == 4.0 and MD10C.max_current_a(30.0, 1.0) == 13.0
    assert big.max_current_a(30.0, 1.0) == 20.0


@pytest.mark.parametrize("kw", [{"name": ""}, {"min_voltage_v": -1.0},
                                {"max_voltage_v": 4.0}, {"continuous_current_a": 0.0},
                                {"max_pwm_frequency_hz": float("nan")}])
def test_driver_rating_refuses_a_bad_rating(kw):
    with pytest.raises(BadInputError):
        DriverRating(**kw)


def test_coil_drive_duty_is_from_its_own_supply_and_driver():
    # a 48 V supply on a 50 V driver: 24 V average is duty 1/2 of 48 V (2048 counts), not of the
    # MD10C's 30 V; the driver's 20 A continuous rating caps the current, not the MD10C's 13 A
    big = DriverRating("48 V bridge", 10.0, 50.0, 20.0, 25e3)
    d = CoilDrive.supply_limited(48.0, 2.0, 0.05, big)
    assert d.current_limit_a == 20.0 and d.max_voltage_v == 40.0
    c = voltage_to_command(24.0, d)
    assert c.duty_counts == 2048 and c.voltage_v == pytest.approx(24.0)
    assert voltage_to_command(45.0, d).clamped
    with pytest.raises(BadInputError, match="48 V bridge continuous"):
        CoilDrive(48.0, 2.0, 21.0, 0.05, big)


# ---------------------------------------------------------------------------------------------
# the record
def _record(**kw) -> DriveRecord:
    base = dict(resistance_ref_ohm=(5.0, 6.0), inductance_h=(0.1, 0.12), supply_voltage_v=24.0,
                current_limit_a=4.0, total_current_a=7.0, driver=MD10C, pwm_frequency_hz=1000.0,
                reference_temperature_c=20.0, temperature_coefficient_per_k=0.004,
                operating_temperature_c=45.0, hot_temperature_c=100.0,
                thermal_continuous_current_a=2.0, thermal_time_constant_s=600.0)
    base.update(kw)
    return DriveRecord(**base)


def test_record_round_trips_every_field():
    rec = _record()
    back = DriveRecord.from_dict(rec.to_dict(), n_coils=2)
    assert back == rec
    for f in dataclasses.fields(DriveRecord):
        if f.init:
            assert getattr(back, f.name) == getattr(rec, f.name), f.name
    # the resistance model: R(T) = R(20 C) (1 + alpha (T - 20 C)); the runner's R at 45 C
    np.testing.assert_allclose(rec.resistance_ohm, [5.0 * 1.1, 6.0 * 1.1])
    np.testing.assert_allclose(rec.resistance_at(100.0), [5.0 * 1.32, 6.0 * 1.32])
    np.testing.assert_allclose(rec.time_constant_s, [0.1 / 5.5, 0.12 / 6.6])
    # the per-coil drives: each coil's R, L, the supply and the driver
    assert [d.resistance_ohm for d in rec.drives] == pytest.approx([5.5, 6.6])
    assert all(d.supply_voltage_v == 24.0 and d.driver is MD10C for d in rec.drives)


@pytest.mark.parametrize("name", [f.name for f in dataclasses.fields(DriveRecord) if f.init]
                         + [f"driver.{f.name}" for f in dataclasses.fields(DriverRating)])
def test_a_record_missing_any_field_is_refused_with_the_rebuild_command(name):
    d = _record().to_dict()
    if name.startswith("driver."):
        del d["driver"][name.split(".")[1]]
    else:
        del d[name]
    with pytest.raises(BadInputError, match="designkit map") as e:
        DriveRecord.from_dict(d)
    assert name in str(e.value)


def test_a_record_with_an_unknown_field_or_another_coil_count_is_refused():
    with pytest.raises(BadInputError, match="supply_v"):
        DriveRecord.from_dict({**_record().to_dict(), "supply_v": 30.0})
    with pytest.raises(BadInputError, match="one per coil"):
        DriveRecord.from_dict(_record().to_dict(), n_coils=9)


@pytest.mark.parametrize("kw, name", [
    ({"resistance_ref_ohm": (5.0, -1.0)}, "resistance_ref_ohm"),
    ({"inductance_h": (0.1,)}, "inductance_h"),
    ({"supply_voltage_v": float("inf")}, "supply_voltage_v"),
    ({"current_limit_a": 13.5}, "current_limit_a"),        # above the MD10C's 13 A
    ({"total_current_a": -1.0}, "total_current_a"),
    ({"pwm_frequency_hz": 0.0}, "pwm_frequency_hz"),
    ({"hot_temperature_c": -400.0}, "hot_temperature_c"),  # R(T) would be negative
    ({"thermal_time_constant_s": float("nan")}, "thermal_time_constant_s"),
])
def test_record_refuses_a_bad_field_naming_it(kw, name):
    with pytest.raises(BadInputError, match=name):
        _record(**kw)


def test_rating_violations_are_the_records_own_and_the_runner_accepts_them():
    assert _record().violations() == []
    bad = _record(supply_voltage_v=36.0, pwm_frequency_hz=25e3)
    v = bad.violations()
    assert len(v) == 2 and "drive.supply_voltage_v" in v[0]
    assert "drive.driver_max_pwm_frequency_hz" in v[1]
    with pytest.raises(BadInputError, match="drive.supply_voltage_v = 36 V"):
        bad.check_ratings()
    # the configuration holds the record whole: the simulator may run it, the hardware
    # entry point calls check_ratings first
    assert RunnerConfig(bad).drive is bad


# ---------------------------------------------------------------------------------------------
# designkit writes it
def test_drive_data_gives_the_design_supply_and_driver():
    r = _r_ref(D24)
    rec = drive_data(D24)
    assert isinstance(rec, DriveRecord) and rec.n_coils == 9
    np.testing.assert_allclose(rec.resistance_ref_ohm, [r] * 9, rtol=1e-12)
    assert rec.supply_voltage_v == 24.0 and rec.violations() == []
    assert rec.current_limit_a == pytest.approx(min(6.0, 24.0 / r))
    assert rec.hot_temperature_c == 100.0 and rec.temperature_coefficient_per_k == 0.00393
    rec48 = drive_data(D48)
    assert rec48.supply_voltage_v == 48.0 and rec48.driver.max_voltage_v == 50.0
    assert rec48.violations() == [] and rec48.current_limit_a == 6.0
    # the thesis' 36 V on the MD10C: the coils get 36 V, and the record says it is over-rated
    rec36 = drive_data(default_design())
    assert rec36.supply_voltage_v == 36.0
    assert rec36.current_limit_a == pytest.approx(min(6.0, 36.0 / r))
    assert len(rec36.violations()) == 1


def test_simulated_coils_see_the_record_supply_not_the_driver_rating(thesis_array):
    # duty 1/2 on every coil: the simulated driver applies half the record's supply (36 V: the
    # design's, above the MD10C's 30 V rating; 48 V on a 50 V driver); the drive does not move
    # the array's physics, so the session's coupled array serves all three
    for design, volts in ((default_design(), 36.0), (D48, 48.0), (D24, 24.0)):
        dev = SimulatedDevice(design, thesis_array, seed=0)
        assert dev.drive.supply_voltage_v == volts
        dev.coils.initialize()
        dev.coils.command_voltage(np.full(9, volts / 2))
        np.testing.assert_allclose(dev.applied_voltage_v(), volts / 2, rtol=1e-12)


# ---------------------------------------------------------------------------------------------
# check and optimize use the same supply
def test_check_compares_i_r_hot_with_the_design_supply():
    r_hot = _r_ref(D24) * (1 + 0.00393 * 80)
    for design, supply in ((D24, 24.0), (D48, 48.0), (default_design(), 30.0)):
        row = rule_table(design)["supply_voltage_v"]
        # the thesis' 36 V is above the MD10C: the coil must work from the 30 V it may take
        assert row["limit"] == supply and device_problem_for(design).supply_voltage_v == supply
        air = rule_table(design.replace(core=None))["supply_voltage_v"]
        assert air["limit"] == supply
        assert air["value"] == pytest.approx(design.drive.max_current_a * r_hot, rel=1e-9)
    rules24 = rule_table(D24)
    assert rules24["design_supply_voltage_v"]["met"]
    assert rule_table(D48)["design_supply_voltage_v"]["met"]
    over = rule_table(default_design())["design_supply_voltage_v"]
    assert not over["met"] and "drive.driver_max_voltage_v" in over["keys"]


def test_air_core_design_gets_its_electrical_checks():
    # R, I R, 5 L/R and heating of the 2 x 3 air-core array's coil, against closed forms: R by
    # hand at 100 C (hot) and 20 C (cold), L by Wheeler's multilayer formula (~1 %)
    d = default_design().replace(**{"core": None, "array.rows": 2, "array.columns": 3})
    table = rule_table(d)
    c = d.coil
    r20 = _r_ref(d)
    assert table["resistance_ohm"]["value"] == pytest.approx(r20 * (1 + 0.00393 * 80), rel=1e-9)
    r_mean = (c.inner_radius_m + c.outer_radius_m) / 2
    wheeler = 31.6e-6 * c.turns ** 2 * r_mean ** 2 / (
        6 * r_mean + 9 * c.length_m + 10 * (c.outer_radius_m - c.inner_radius_m))
    assert table["settling_time_s"]["value"] == pytest.approx(5 * wheeler / r20, rel=0.02)
    # adiabatic heating from 20 C to 100 C at half duty and 6 A: m c ln(1 + a 80) / (P0 a)
    mass = 8960 * c.turns * 2 * math.pi * r_mean * math.pi * d.wire.diameter_m ** 2 / 4
    t_hot = mass * 385 * math.log1p(0.00393 * 80) / (0.5 * 36 * r20 * 0.00393)
    assert table["time_to_max_temperature_s"]["value"] == pytest.approx(t_hot, rel=1e-9)
    for name in ("resistance_ohm", "supply_voltage_v", "settling_time_s",
                 "time_to_max_temperature_s"):
        assert table[name]["group"] == "device" and table[name]["keys"]


def test_hardware_entry_refuses_a_map_over_its_driver_rating(tmp_path, monkeypatch, capsys):
    # before any device is opened: the map's record says 36 V on a 30 V driver
    from firmware_io import run

    class Map:
        meta = {"drive": drive_data(default_design()).to_dict()}
        n_coils = 9

        def saturation_table(self):
            return SaturationTable([0.0, 6.0], np.ones((2, 9)))

    class Scene:
        meta = {"rows": "force"}

    def no_device(*args):
        raise AssertionError("the device was opened")

    monkeypatch.setattr(run, "_bus_number", lambda text, what: 1)
    monkeypatch.setattr(run, "load_inputs", lambda *a: (Map(), Scene(), None))
    monkeypatch.setattr(run, "open_device", no_device)
    rc = run.main(["--bus", "1", "--map", "m.npz", "--scene", "s.npz"])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err
    assert "drive.supply_voltage_v = 36 V" in err and "drive.driver_max_voltage_v" in err


# ---------------------------------------------------------------------------------------------
# end to end: a 48 V driver named in the design runs in the simulator
BOX = (np.array([-0.07, -0.03, 0.015]), np.array([0.07, 0.03, 0.06]))


@pytest.fixture(scope="module")
def small48(tmp_path_factory):
    """A 1 x 2 air-core board on a 48 V supply with a driver rated 50 V (a small, quick map)."""
    from designkit import fieldmap

    design = D48.replace(**{"array.rows": 1, "array.columns": 2, "core": None})
    path = tmp_path_factory.mktemp("map48") / "map.npz"
    fieldmap.write(path, fieldmap.build(design, box=BOX, spacing=0.02, n_check=20,
                                        progress=False))
    return design, path


def test_a_48_v_design_runs_in_the_simulator_at_48_v(small48, tmp_path):
    from designkit.sim.run import RunSettings, run_simulation
    from firmware_io.mapfile import MapFile
    from firmware_io.runner import config_from_map

    design, path = small48
    cfg = config_from_map(MapFile.load(path))
    assert cfg.drive.supply_voltage_v == 48.0 and cfg.drive.driver.max_voltage_v == 50.0
    assert all(d.supply_voltage_v == 48.0 for d in cfg.drive.drives)
    s = run_simulation(RunSettings(obj="plane", duration_s=0.3), design=design, map_path=path,
                       out=tmp_path / "run", progress=False)
    assert s["drive"]["supply_voltage_v"] == 48.0 and s["drive_violations"] == []
    assert s["drive"] == cfg.drive.to_dict()
    # and check passes the supply against the driver it names
    table = rule_table(design)
    assert table["design_supply_voltage_v"]["met"] and table["supply_voltage_v"]["limit"] == 48.0


def test_simulated_coils_of_two_sizes_each_follow_their_own_r_and_l():
    # a 1 x 2 air-core array whose second coil has 900 turns, not 1020: a step of 12 V on both
    # gives each coil its own exact R-L response, I(t) = V/R_k (1 - exp(-t R_k / L_k)) (a plant
    # driving every coil with the first coil's R and L fails)
    import tomllib

    from designkit.design import design_from_dict

    design = design_from_dict(tomllib.loads('[array]\nrows = 1\ncolumns = 2\n[core]\nenabled = false\n'
                              '[[groups]]\ncoils = [1]\n[groups.coil]\nturns = 900\n'))
    dev = SimulatedDevice(design, seed=0, sensor_errors="ideal")
    r = np.asarray(dev.drive.resistance_ohm)
    ind = np.asarray(dev.drive.inductance_h)
    assert r[1] < 0.95 * r[0] and ind[1] < 0.85 * ind[0]   # the record's per-coil values
    dev.coils.initialize()
    dev.coils.command_voltage(np.full(2, 12.0))
    volts = dev.applied_voltage_v()             # 12 V to the PWM's 12-bit step
    np.testing.assert_allclose(volts, 12.0, rtol=2e-3)
    t = 0.0
    for dt in (1e-3, 2e-3, 5e-3):
        dev.advance_currents(dt)
        t += dt
        want = volts / r * (1.0 - np.exp(-t * r / ind))
        np.testing.assert_allclose(dev.current_a, want, rtol=1e-9)
