"""Spec fields that used to be dead are read: core.saturation_t sets the saturation warning,
drive.pwm_frequency_hz the PWM current ripple, render.stiffness_n_per_m the run's force constant
(sensors.range_t and lsb_t: tests/test_sensing.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from designkit import Coil, default_design
from designkit.model import electrical as el
from designkit.cores.material import KNEE_T
from designkit.cores.saturation import SaturationWarning


def _warns(design) -> bool:
    coil = Coil.from_design(design)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        coil.field(np.array([[0.0, 0.0, 0.03]]), design.drive.max_current_a)
    return any(issubclass(w.category, SaturationWarning) for w in caught)


def test_core_saturation_t_is_the_warning_threshold():
    d = default_design()
    assert d.core.saturation_t == KNEE_T  # one value, not 1.6 in the spec and 1.5 in the code
    peak = Coil.from_design(d).core.peak_flux_density(Coil.from_design(d), 6.0)
    assert _warns(d.replace(**{"core.saturation_t": 0.9 * peak}))
    assert not _warns(d.replace(**{"core.saturation_t": 1.1 * peak}))
    assert Coil.from_design(d.replace(**{"core.saturation_t": 1.9})).core.knee_t == 1.9


@pytest.mark.parametrize("seed", range(4))
def test_pwm_ripple_matches_a_simulated_rl_load(seed):
    rng = np.random.default_rng(seed)
    v, r = rng.uniform(5, 40), rng.uniform(1, 10)
    tau = rng.uniform(5e-4, 5e-3)
    f = rng.uniform(200, 1500)
    period = 1 / f
    # integrate L di/dt = V s(t) - R i from the mean current for 12 tau: the transient is gone
    n_periods = int(12 * tau * f) + 2
    sol = solve_ivp(lambda t, i: [(v * (t % period < period / 2) - r * i[0]) / (r * tau)],
                    (0, period * n_periods), [v / r / 2], max_step=period / 200,
                    rtol=1e-9, atol=1e-12)
    last = sol.t > sol.t[-1] - period
    ripple = np.ptp(sol.y[0, last])
    assert el.pwm_ripple(v, r, tau, f) == pytest.approx(ripple, rel=5e-3)


def test_electrical_report_uses_the_design_pwm_frequency():
    d = default_design()
    coil = Coil.from_design(d)
    a = el.electrical_report(d, coil)
    b = el.electrical_report(d.replace(**{"drive.pwm_frequency_hz": 10 * d.drive.pwm_frequency_hz}),
                             coil)
    assert a.pwm_frequency_hz == d.drive.pwm_frequency_hz
    assert b.pwm_ripple_a == pytest.approx(a.pwm_ripple_a / 10, rel=1e-3)  # tau >> period


def test_run_takes_lambda_from_the_design_render_stiffness(monkeypatch, tmp_path):
    """render.stiffness_n_per_m is the force constant of ``designkit run`` without --lambda,
    capped at what the device renders over the object (designkit.sim.run.choose_lambda)."""
    from types import SimpleNamespace

    import designkit.render.scenefile as scenefile
    import firmware_io.mapfile as mapfile
    from designkit.sim import RunSettings, run_simulation
    from designkit.sim import run as sim_run

    class Stop(Exception):
        pass

    seen = {}

    def compile_scene(obj, path, *, lam_n_per_m, **kwargs):
        seen["lam"] = lam_n_per_m
        raise Stop  # what follows (the run itself) is the runner tests' business

    def force_constant(*args, **kwargs):
        return SimpleNamespace(lam_where_renderable=lambda: seen["device"],
                               limiting_point_where_renderable=lambda: np.zeros(3),
                               unrenderable_points=0, points_m=np.zeros((4, 3)))

    monkeypatch.setattr(mapfile.MapFile, "load",
                        classmethod(lambda cls, *a, **k: SimpleNamespace(design_sha256="x")))
    monkeypatch.setattr(scenefile, "compile_scene", compile_scene)
    monkeypatch.setattr(sim_run.render, "force_constant", force_constant)
    drive = SimpleNamespace(current_limit_a=6.0, total_current_a=54.0)
    monkeypatch.setattr(sim_run, "config_from_map",
                        lambda fmap, **kw: SimpleNamespace(drive=drive))
    d = default_design().replace(**{"render.stiffness_n_per_m": 4.25})
    for lam, device, want in ((None, 10.0, 4.25), (None, 3.0, 3.0), (7.0, 3.0, 7.0)):
        seen["device"] = device
        with pytest.raises(Stop):
            run_simulation(RunSettings(duration_s=0.1, lam_n_per_m=lam), design=d,
                           map_path=tmp_path / "m.npz", out=tmp_path / "o",
                           array=SimpleNamespace(sensor_positions_m=lambda: np.zeros((2, 9, 3))))
        assert seen["lam"] == want
