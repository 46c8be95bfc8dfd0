"""firmware_io.runner and designkit.sim: the closed loop on the simulated device, its fault
handling and its current dynamics, checked against independent references (an ODE solver, the
PCA9685 register file, the bounds)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from designkit.design import default_design
from designkit.errors import BadInputError
from designkit.sim import (FAULT_TYPES, FaultSchedule, SimulatedDevice, Trajectory, simulate,
                           slide_trajectory, time_to_safe)
from firmware_io.errors import FirmwareIOError
from firmware_io.hw.tlv493d import FrameChecks
from firmware_io.mapfile.drive import DriveRecord
from firmware_io.runner import (Fix, PoseTracker, Runner, RunnerConfig, RunnerIO, ThermalGuard,
                                feedforward_voltage, rl_step)

from _runner_fakes import (HoldTracker, PlaneScene, TruthEstimator, clipped_lstsq, device_map,
                           md10c_drive)

BOX = (np.array([-0.075, -0.075, 0.010]), np.array([0.075, 0.075, 0.080]))


# ---------------------------------------------------------------------------------------------
# current dynamics vs an ODE solver


def _ode_current(i0, v, r, ind, period):
    sol = solve_ivp(lambda t, i: (v - r * i) / ind, (0.0, period), [i0], rtol=1e-12, atol=1e-14,
                    method="DOP853")
    return sol.y[0, -1]


def test_rl_step_matches_an_ode_solver():
    rng = np.random.default_rng(1)
    for _ in range(40):
        r, ind = rng.uniform(0.5, 10), rng.uniform(1e-3, 0.5)
        i0, v, period = rng.uniform(-6, 6), rng.uniform(-30, 30), rng.uniform(1e-4, 5e-2)
        got = rl_step(np.array([i0]), np.array([v]), r, ind, period)[0]
        assert got == pytest.approx(_ode_current(i0, v, r, ind, period), rel=1e-9, abs=1e-12)


def test_feedforward_reaches_the_target_in_one_period_or_saturates_without_overshoot():
    rng = np.random.default_rng(2)
    reached = clipped = 0
    for _ in range(200):
        r, ind = rng.uniform(1, 8), rng.uniform(5e-3, 0.3)
        period, vs = rng.choice([1e-3, 2e-3, 1e-2]), rng.uniform(5, 30)
        i0, target = rng.uniform(-vs / r, vs / r, 2) * 0.9
        v = feedforward_voltage(np.array([target]), np.array([i0]), r, ind, period, vs)[0]
        end = _ode_current(i0, v, r, ind, period)
        assert abs(v) <= vs * (1 + 1e-12)
        if abs(v) < vs * (1 - 1e-9):
            reached += 1
            assert end == pytest.approx(target, abs=1e-9 * max(1.0, abs(target)))
        else:
            clipped += 1
            # saturated drive: moves toward the target, never past it
            assert (end - i0) * (target - i0) >= 0 and abs(end - i0) <= abs(target - i0) + 1e-12
    assert reached > 20 and clipped > 20


def test_thermal_guard_matches_the_closed_form_of_first_order_heating():
    g = ThermalGuard(1, continuous_current_a=2.0, time_constant_s=10.0)
    dt, i = 1e-2, 3.0
    for _ in range(1000):                       # 10 s at 3 A
        g.update(np.array([i]), dt)
    # E(t) = I^2 tau (1 - exp(-t/tau)) for the exact discrete sum with E += I^2 dt after decay
    n = 1000
    q = np.exp(-dt / 10.0)
    exact = i * i * dt * (1 - q ** n) / (1 - q)
    assert g.energy_a2s[0] == pytest.approx(exact, rel=1e-12)
    assert g.exceeded() == (exact > 4.0 * 10.0)


# ---------------------------------------------------------------------------------------------
# the loop on the simulated device


@pytest.fixture(scope="module")
def device_and_a(thesis_array):
    design = default_design()
    array = thesis_array                       # one coupled solve for the session
    a = array.actuation_matrix(np.array([0.0, 0.0, 0.04]))
    return design, array, a


class RefusingEstimator(TruthEstimator):
    """Never trusts a fix: the runner never locates the finger."""

    def estimate(self, readings_t, currents_a=None, *, usable=None, seed=None, time_s=None):
        est = super().estimate(readings_t, currents_a)
        return dataclasses.replace(est, ok=False, reason="refused")


def _run(device_and_a, faults: str, duration_s: float, *, limit=4.8, total=20.0,
         resume_after_s=0.1, estimator=TruthEstimator):
    design, array, a = device_and_a
    drive = md10c_drive(design, limit, total)
    dev = SimulatedDevice(design, array, seed=4, drive=drive)
    traj = slide_trajectory(lambda x, y: np.full_like(x, 0.05), duration_s=duration_s,
                            samples=401)
    fmap = device_map(a, BOX, dev)
    holder = {}

    def factory(source, clock, hook):
        cfg = RunnerConfig(drive, resume_after_s=resume_after_s)
        r = Runner(fmap, PlaneScene(0.05, 6.0),
                   estimator(lambda: source.frame_truth_m, dev.moment),
                   RunnerIO(dev.coils, source, lambda line: None, clock), cfg,
                   tracker=HoldTracker(), allocate=hook(clipped_lstsq))
        r.start()
        holder["runner"] = r
        return r

    res = simulate(dev, factory, traj, duration_s=duration_s,
                   faults=FaultSchedule.parse(faults, duration_s), progress=False)
    return dev, holder["runner"], res


def _check_fault(res, fault, entry):
    c = res.columns
    st = c["state"]
    assert entry["state"] == fault
    # from the step that can see the fault (a sensor fault needs the frame that shows it)
    detected = [t for t, name, _ in res.fault_log if name == fault]
    assert detected, f"{fault} was never detected"
    k = int(np.argmin(np.abs(c["t_s"] - detected[0])))
    assert st[k] == fault
    # coils off from that step: every command zero while in the fault
    assert np.all(np.stack([c[f"cmd{j + 1}_a"] for j in range(9)], 1)[st == fault] == 0)
    # sensors see the frame within a few passes of the bus (a frozen value needs its
    # FrameChecks.frozen_reads repeats first); nothing else may wait
    latency = entry["time_to_safe_s"]
    bound = 0.03 if fault.startswith("sensor") or fault == "out_of_box" else 1e-3
    if fault == "sensor_value":
        frames = c["t_s"][np.asarray(c["new_frame"], bool)]
        bound += FrameChecks().frozen_reads * float(np.median(np.diff(frames)))
    assert latency <= bound + 1e-12


@pytest.mark.slow
@pytest.mark.parametrize("fault", FAULT_TYPES)
def test_each_fault_ends_in_the_safe_state(device_and_a, fault):
    dev, runner, res = _run(device_and_a, f"{fault}@0.3", 0.5)
    assert (res.columns["state"] == "running").sum() > 100, "the loop never ran"
    [entry] = time_to_safe(res.columns, res.faults, 1e-3)
    _check_fault(res, fault, entry)


def test_three_faults_in_one_short_run_each_end_in_the_safe_state(device_and_a):
    faults = ("pwm_nack", "sensor_stuck", "over_limit")
    dev, runner, res = _run(device_and_a, "pwm_nack@0.15,sensor_stuck@0.45,over_limit@0.75",
                            0.9)
    entries = time_to_safe(res.columns, res.faults, 1e-3)
    assert [e["fault"] for e in entries] == list(faults)
    for fault, entry in zip(faults, entries):
        _check_fault(res, fault, entry)


def test_safe_state_is_one_all_off_write_per_board(device_and_a):
    design, array, a = device_and_a
    drive = md10c_drive(design)
    dev = SimulatedDevice(design, array, drive=drive)
    cfg = RunnerConfig(drive)
    truth = {"p": np.array([0.0, 0.0, 0.03])}

    class Source:
        def __call__(self, t):
            from firmware_io.runner import SensorFrame
            return SensorFrame(np.zeros((18, 3)), ("ok",) * 18, t)

    r = Runner(device_map(a, BOX, dev), PlaneScene(0.05, 6.0),
               TruthEstimator(lambda: truth["p"], dev.moment),
               RunnerIO(dev.coils, Source(), lambda line: None, lambda: 0.0), cfg,
               tracker=HoldTracker(), allocate=clipped_lstsq)
    r.start()
    rec = r.step(0.0)
    assert rec.state == "running" and np.any(rec.command_a != 0)
    assert any(b.duty(ch) > 0 for b in dev.sim_boards for ch in range(16))
    dev.coil_bus.clear_log()
    truth["p"] = np.array([0.0, 0.0, 0.2])          # leaves the box
    rec = r.step(1e-3)
    assert rec.state == "out_of_box"
    writes = [(tr.messages[0].addr, bytes(tr.messages[0].data)) for tr in dev.coil_bus.log]
    # ALL_LED_OFF_H (0xFD) with the full-off bit, once per board, nothing else
    assert sorted(writes) == [(0x40, bytes([0xFD, 0x10])), (0x41, bytes([0xFD, 0x10]))]
    assert all(b.duty(ch) == 0 for b in dev.sim_boards for ch in range(16))


def test_commands_never_exceed_the_limits_even_when_a_defect_asks_for_more(device_and_a):
    dev, runner, res = _run(device_and_a, "over_limit@0.2,over_limit@0.35", 0.5, limit=2.0,
                            total=6.0)
    c = res.columns
    cmd = np.stack([c[f"cmd{j + 1}_a"] for j in range(9)], 1)
    assert np.abs(cmd).max() <= 2.0 + 1e-9
    assert np.abs(cmd).sum(axis=1).max() <= 6.0 + 1e-9
    assert (c["state"] == "over_limit").sum() > 0


def test_thermal_fault_is_detected_while_the_finger_is_not_located(device_and_a):
    _, runner, res = _run(device_and_a, "thermal@0.2", 0.3, estimator=RefusingEstimator)
    st, t = res.columns["state"], res.columns["t_s"]
    assert np.all(st[(t > 0.05) & (t < 0.2)] == "lost")
    assert np.all(st[t >= 0.2] == "thermal")
    assert [name for _, name, _ in runner.fault_log][-1] == "thermal"


def test_thermal_fault_stays_off_until_cooled(device_and_a):
    dev, runner, res = _run(device_and_a, "thermal@0.2", 0.5)
    st = res.columns["state"]
    t = res.columns["t_s"]
    assert np.all(st[t >= 0.2] == "thermal")          # 300 s thermal time constant: no resume
    # the I^2 t model cools with the closed form E(t) = E0 exp(-t / tau) at zero current and
    # reports cooled exactly when E < resume_fraction x budget: t* = tau ln(E0 / (f budget))
    th = runner.thermal
    e0 = 1.05 * th.budget_a2s
    th.energy_a2s[:] = e0
    tau, dt = th.time_constant_s, 1.0
    t_star = tau * np.log(e0 / (th.resume_fraction * th.budget_a2s))
    n = int(np.floor(t_star / dt))
    for _ in range(n):
        th.update(np.zeros(9), dt)
    np.testing.assert_allclose(th.energy_a2s, e0 * np.exp(-n * dt / tau), rtol=1e-9)
    assert not th.cooled()
    th.update(np.zeros(9), dt)
    assert th.cooled()


def test_pwm_nack_is_latched_after_repeated_failures(device_and_a):
    design, array, a = device_and_a
    drive = md10c_drive(design)
    dev = SimulatedDevice(design, array, drive=drive)
    cfg = RunnerConfig(drive, resume_after_s=0.01, max_pwm_retries=2)

    class Source:
        def __call__(self, t):
            from firmware_io.runner import SensorFrame
            return SensorFrame(np.zeros((18, 3)), ("ok",) * 18, t)

    r = Runner(device_map(a, BOX, dev), PlaneScene(0.05, 6.0),
               TruthEstimator(lambda: np.array([0.0, 0.0, 0.03]), dev.moment),
               RunnerIO(dev.coils, Source(), lambda line: None, lambda: 0.0), cfg,
               tracker=HoldTracker(), allocate=clipped_lstsq)
    r.start()
    assert r.step(0.0).state == "running"
    dev.sim_boards[0].nack_always = True
    assert r.step(1e-3).state == "pwm_nack"
    states = [r.step(k * 1e-3).state for k in range(2, 80)]
    assert r.latched and states[-1] == "pwm_nack"
    dev.sim_boards[0].nack_always = False           # latched: a good bus does not bring it back
    assert r.step(0.1).state == "pwm_nack"


# ---------------------------------------------------------------------------------------------
# bad input, before anything is energized


def test_scene_for_another_design_is_refused(tmp_path):
    from designkit.render.laws import ConstraintLaw
    from designkit.render.scenefile import compile_scene, make_object
    from firmware_io.scene import Scene

    path = compile_scene(make_object("plane"), tmp_path / "s.npz", lam_n_per_m=6.0,
                         law=ConstraintLaw(6.0), map_design_sha256="a" * 64)
    with pytest.raises(ValueError, match="Recompile"):
        Scene.load(path, expected_design_sha256="b" * 64)


def test_hardware_entry_refuses_a_bus_that_does_not_exist(tmp_path, capsys):
    from firmware_io import run

    rc = run.main(["--bus", "97", "--map", str(tmp_path / "m.npz"),
                   "--scene", str(tmp_path / "s.npz")])
    err = capsys.readouterr().err
    assert rc == 2 and "i2c-97" in err and "does not exist" in err
    assert "Traceback" not in err


def test_hardware_entry_refuses_a_missing_sensor_array():
    from firmware_io.errors import FirmwareIOError
    from firmware_io.run import check_sensor_arrays
    from firmware_io.hw.sensors import SensorArrays
    from firmware_io.hw.sim import SimBus, SimClock, SimTCA9548A, SimTLV493D

    clock = SimClock()
    bus = SimBus(clock=clock)
    muxes = [bus.attach(SimTCA9548A(0x71 + k)) for k in range(3)]
    for i in range(9):                       # the upper array only: the lower cable is off
        muxes[i // 8].attach(i % 8, SimTLV493D())
    status = SensorArrays(bus, sleep=clock.sleep).configure()
    with pytest.raises(FirmwareIOError, match="9 of 18 sensors answer.*sensors \\[9, 10"):
        check_sensor_arrays(status)


def test_trajectory_file_with_wrong_columns(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("time,x,y,z\n0,0,0,0.03\n1,0,0,0.04\n")
    with pytest.raises(BadInputError, match="t_s, x_m, y_m, z_m"):
        Trajectory.from_csv(p)
    p.write_text("t_s,x_m,y_m,z_m\n0,0,0,0.03\n0,0,0,0.04\n")
    with pytest.raises(BadInputError, match="strictly increasing"):
        Trajectory.from_csv(p)


@pytest.mark.parametrize("text", ["melt@1", "pwm_nack@x", "pwm_nack@99"])
def test_fault_schedule_errors(text):
    with pytest.raises(BadInputError):
        FaultSchedule.parse(text, 5.0)


def test_default_schedule_has_every_fault_once_inside_the_run():
    s = FaultSchedule.parse("default", 10.0)
    assert sorted(name for _, name in s.events) == sorted(FAULT_TYPES)
    assert all(0.1 * 10 < t < 0.9 * 10 for t, _ in s.events)


@pytest.mark.parametrize("kw, name", [
    ({"supply_voltage_v": -1.0}, "supply_voltage_v"),
    ({"current_limit_a": -1.0}, "current_limit_a"),
    ({"current_limit_a": 14.0}, "current_limit_a"),          # above the MD10C's 13 A
    ({"resistance_ref_ohm": (0.0,) * 9}, "resistance_ref_ohm"),
    ({"inductance_h": (0.18,) * 8}, "inductance_h"),
    ({"force_axes": "q"}, "force_axes"),
])
def test_runner_config_errors_name_the_value(kw, name):
    base = dict(resistance_ref_ohm=(6.0,) * 9, inductance_h=(0.18,) * 9, supply_voltage_v=30.0,
                current_limit_a=4.8, total_current_a=20.0)
    base.update(kw)
    with pytest.raises(ValueError, match=name):
        axes = base.pop("force_axes", "z")
        RunnerConfig(DriveRecord(**base), force_axes=axes)


def test_runner_imports_numpy_only():
    code = ("import sys, firmware_io.runner, firmware_io.run; "
            "bad = [m for m in sys.modules if m.split('.')[0] in "
            "('designkit', 'scipy', 'matplotlib', 'pyvista')]; print(bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_start_up_calibration_through_the_firmware_recovers_the_sensor_errors(device_and_a):
    from designkit.sim.readings import analog_reading
    from firmware_io.localization import SensorModel

    design, array, a = device_and_a
    dev = SimulatedDevice(design, array, seed=3)
    sim = dev.sensor_sim
    # what the controller knows: the nominal sensor poses' coil field per ampere (exact here, so
    # that only the sensor errors remain to be learned)
    g = np.stack([sim.coil_part(np.eye(9)[k][None])[0] for k in range(9)], -1)
    model = SensorModel(sim.nominal_m.reshape(-1, 3), g.reshape(18, 3, 9), dev.moment, "x" * 64)
    cal = dev.calibrate_sensors(model)
    gi, off = cal if isinstance(cal, tuple) else (cal.gain_inverse, cal.offsets_t)
    assert np.all(dev.current_a == 0) and all(b.duty(ch) == 0 for b in dev.sim_boards
                                               for ch in range(16))
    rng = np.random.default_rng(11)
    for _ in range(5):
        i = rng.uniform(-1.5, 1.5, 9)
        field = sim.coil_part(i[None])                     # (1, 2, 9, 3) T, exact
        truth = field[0]
        raw = analog_reading(field, sim.errors, 0.0, rng)[0]
        fixed = np.einsum("asij,asj->asi", gi.reshape(2, 9, 3, 3), raw - off.reshape(2, 9, 3))
        before = np.abs(raw - truth).max()
        after = np.abs(fixed - truth).max()
        # 1 % gains, 1 degree mountings of fields up to ~50 mT: ~1 mT before; the 0.1 mT noise
        # and 0.1 mT quantization of 40 calibration frames leave ~0.1 mT
        assert before > 3e-4 and after < 0.25 * before


def _scripted_runner(device_and_a, script):
    """A runner on the simulated PWM boards whose sensor side hands over one fix per 1 ms step
    at a fixed position: ok without problems, except the steps in ``script`` (step -> (ok,
    problems)). Returns (runner, device)."""
    design, array, a = device_and_a
    drive = md10c_drive(design)
    dev = SimulatedDevice(design, array, drive=drive)
    cfg = RunnerConfig(drive, resume_fixes=3)
    p = np.array([0.0, 0.0, 0.04])

    def source(t):
        ok, problems = script.get(int(round(t / 1e-3)), (True, ()))
        return Fix(p.copy(), dev.moment.copy(), ok, t, problems, np.zeros(18, bool), 0.0,
                   (0.3e-3) ** 2 * np.eye(3), 1e-3)

    r = Runner(device_map(a, BOX, dev), PlaneScene(0.05, 6.0), TruthEstimator(lambda: p),
               RunnerIO(dev.coils, source, lambda line: None, lambda: 0.0), cfg,
               tracker=PoseTracker(), allocate=clipped_lstsq)
    r.start()
    return r, dev


def test_localization_faults_resume_after_resume_fixes_accepted_fixes_in_a_row(device_and_a):
    """A sensor fault, then a not-ok fix: the runner runs again at exactly the
    ``resume_fixes``-th accepted fix after the last problem (the count restarts at each
    problem), not after a hold time."""
    script = {5: (True, (("sensor_dead", "sensor 3 reports 'nack'; excluded"),)),
              8: (False, (("lost", "the localizer flagged its estimate"),))}
    r, _ = _scripted_runner(device_and_a, script)
    states = [r.step(k * 1e-3).state for k in range(14)]
    assert states == ["running"] * 5 + ["sensor_dead"] * 3 + ["lost"] * 3 + ["running"] * 3
    assert r.cfg.resume_after_s > 0.1        # a hold time would have kept them off far longer


def test_a_nack_superseded_by_a_localization_fault_still_reinitialises_the_boards(
        device_and_a):
    """A PWM NACK, then a lost fix before the NACK's hold time is over: the runner resumes
    only through a re-initialisation of the boards (the NACK is not forgotten)."""
    r, dev = _scripted_runner(device_and_a, {3: (False, (("lost", "flagged"),))})
    calls = []
    init = dev.coils.initialize
    dev.coils.initialize = lambda *a, **k: (calls.append(1), init(*a, **k))[1]
    assert r.step(0.0).state == "running"
    dev.sim_boards[0].inject_nack(count=1)
    states = [r.step(k * 1e-3).state for k in range(1, 8)]
    assert states[:3] == ["pwm_nack", "pwm_nack", "lost"]
    assert calls and states[-1] == "running" and r.pwm_reinit_needed is False


def test_trajectory_tilt_columns_are_read_and_checked(tmp_path):
    """tilt_deg / azimuth_deg columns give the moment direction: tilt 30 towards azimuth 90
    is (0, sin 30, cos 30) from an upright design; a tilt out of [0, 180] is refused naming
    the column, the value, its line and the range."""
    p = tmp_path / "t.csv"
    p.write_text("t_s,x_m,y_m,z_m,tilt_deg,azimuth_deg\n0,0,0,0.03,0,0\n1,0,0,0.04,30,90\n")
    t = Trajectory.from_csv(p)
    assert t.tilted
    u = t.moment_direction([0.0, 1.0, 2.0], [0.0, 0.0, 0.909])
    np.testing.assert_allclose(u[1], [0.0, 0.5, np.sqrt(3) / 2], atol=1e-15)
    np.testing.assert_allclose(u[0], [0.0, 0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(u[2], u[1], atol=1e-15)         # held after the last sample
    p.write_text("t_s,x_m,y_m,z_m,tilt_deg\n0,0,0,0.03,0\n1,0,0,0.04,195\n")
    with pytest.raises(BadInputError) as err:
        Trajectory.from_csv(p)
    msg = str(err.value)
    assert "tilt_deg" in msg and "195" in msg and "[0, 180]" in msg and "line 3" in msg
    assert "\n" not in msg
    p.write_text("t_s,x_m,y_m,z_m,tilt_deg\n0,0,0,0.03,0\n1,0,0,0.04,nan\n")
    with pytest.raises(BadInputError, match="tilt_deg"):
        Trajectory.from_csv(p)


def test_cli_refuses_a_tilt_out_of_range_in_one_line(tmp_path, capsys):
    from designkit.cli import main

    p = tmp_path / "t.csv"
    p.write_text("t_s,x_m,y_m,z_m,tilt_deg\n0,0,0,0.03,0\n1,0,0,0.04,-5\n")
    rc = main(["run", "--simulate", "--trajectory", str(p), "--out", str(tmp_path / "o"),
               "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc != 0 and len(err.splitlines()) == 1 and "Traceback" not in err
    assert "tilt_deg" in err and "-5" in err and "[0, 180]" in err
    assert not (tmp_path / "o").exists()
