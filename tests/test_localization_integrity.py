"""Localization integrity: the residual test's thresholds, the covariance and protection level
against the scatter of fits to magpylib's field with known noise, re-acquisition after jumps,
and bad frames that never raise."""

from __future__ import annotations

import math

import numpy as np
import pytest

import magpylib as magpy  # noqa: E402  (a test dependency: no skip)
from firmware_io.localization import EstimatorSettings, SensorModel, make_estimator
from firmware_io.localization.integrity import chi2_quantile, chi2_sf, covariance_and_pl
from firmware_io.localization.integrity import fused_protection_level, ratio_quantiles

MOMENT = np.array([0.0, 0.0, 0.909])
NOISE = 1e-4


def _loc(model, method="model", *, calibration=None, learned=None, **settings):
    """The estimator of ``method`` with these settings (EstimatorSettings' keywords; no alert
    limits unless given: these tests check the fit and its residual test)."""
    settings = {"alert_limit_m": math.inf, "orientation_alert_limit_rad": math.inf, **settings}
    return make_estimator(method, model, EstimatorSettings(**settings), calibration=calibration,
                          learned=learned)


def _model(seed=0):
    """The thesis geometry: 3 x 3 coils at 50 mm pitch, sensors 14 mm above the tops and
    below the bottoms; a random coil field per ampere with the array's mirror symmetry."""
    rng = np.random.default_rng(seed)
    xy = np.array([[x, y] for y in (0.05, 0.0, -0.05) for x in (-0.05, 0.0, 0.05)])
    sp = np.stack([np.c_[xy, np.full(9, 0.014)], np.c_[xy, np.full(9, -0.114)]])
    up = rng.normal(scale=5e-3, size=(9, 3, 9))
    return SensorModel(sp.reshape(-1, 3),
                       np.concatenate([up, up * np.array([-1.0, -1.0, 1.0])[None, :, None]]),
                       MOMENT, "a" * 64, 0.0, None)


def _frame(model, p, currents, rng):
    """magpylib's dipole (independent of the code under test) + coils + Gaussian noise."""
    b = magpy.misc.Dipole(moment=MOMENT, position=p).getB(
        model.sensor_positions_m) + model.coil_field_t_per_a @ currents
    b = b.reshape(2, 9, 3)
    return b + rng.normal(scale=NOISE, size=b.shape)


def test_chi2_thresholds_match_scipy():
    from scipy.stats import chi2

    for dof in (1, 2, 3, 4, 7, 24, 51, 54):
        assert chi2_sf(20.0, dof) == pytest.approx(chi2.sf(20.0, dof), rel=1e-10)
        for p in (1e-2, 1e-3, 1e-4, 1e-6):
            assert chi2_quantile(p, dof) == pytest.approx(chi2.isf(p, dof), rel=1e-9)


def test_covariance_matches_the_scatter_and_the_protection_level_bounds_the_error():
    """Known Gaussian noise, an exact model: the squared Mahalanobis error e^T C^-1 e
    averages 3 (chi-square, 3 dof: a covariance off by 2x gives 1.5 or 6), no ok fix errs
    beyond its protection level (risk 1e-4, no bias term), the residual test passes ~all
    (false alarm 1e-3) and the normalized chi2 averages 1."""
    rng = np.random.default_rng(1)
    model = _model()
    loc = _loc(model, "model", cores=False, noise_t=NOISE, relative_error=0.0,
                    model_bias_m=0.0, integrity_risk=1e-4, false_alarm=1e-3)
    m2, over, oks, chi = [], 0, 0, []
    for _ in range(300):
        p = np.r_[rng.uniform(-0.025, 0.025, 2), rng.uniform(0.02, 0.07)]
        i = rng.uniform(-1, 1, 9)
        f = _frame(model, p, i, rng)
        loc.reset()
        est = loc.estimate(np.r_[f[0], f[1]], i)
        e = est.position_m - p
        m2.append(float(e @ np.linalg.solve(est.position_covariance_m2, e)))
        chi.append(est.chi2 / est.dof)
        oks += est.ok
        over += est.ok and np.linalg.norm(e) > est.protection_level_m
    assert 2.5 < np.mean(m2) < 3.5
    assert 0.9 < np.mean(chi) < 1.1
    assert over == 0
    assert oks >= 297


def test_noise_larger_than_modelled_fails_the_residual_test():
    """Readings 3x noisier than the localizer's noise model: chi2 / dof ~ 9, far beyond the
    threshold at 51 dof (~1.7): not ok, the reason names the test."""
    rng = np.random.default_rng(2)
    model = _model()
    loc = _loc(model, "model", cores=False, noise_t=NOISE / 3, relative_error=0.0)
    p = np.array([0.0, 0.01, 0.04])
    f = _frame(model, p, np.zeros(9), rng)
    est = loc.estimate(np.r_[f[0], f[1]], np.zeros(9))
    assert not est.ok and "chi2" in est.reason


def test_jumps_between_frames_are_reacquired():
    """Warm starts from the previous frame 10-60 mm away (a jump, a lost frame): the global
    search finds the right basin (every estimate within 5 mm or its protection level, ok or
    not: the not-ok ones high above the array, where the protection level exceeds the 5 mm
    alert limit) and every fix flagged ok is within 5 mm."""
    rng = np.random.default_rng(3)
    model = _model()
    loc = _loc(model, "model", cores=False, noise_t=NOISE, relative_error=0.0,
                    alert_limit_m=5e-3)
    p = np.array([0.0, 0.0, 0.04])
    bad, found, reasons = 0, 0, set()
    for _ in range(60):
        while True:
            d = rng.normal(size=3)
            q = p + d / np.linalg.norm(d) * rng.uniform(0.010, 0.060)
            if np.all(np.abs(q[:2]) <= 0.025) and 0.02 <= q[2] <= 0.07:
                break
        p = q
        i = rng.uniform(-2, 2, 9)
        f = _frame(model, p, i, rng)
        est = loc.estimate(np.r_[f[0], f[1]], i)
        err = np.linalg.norm(est.position_m - p)
        found += err < max(5e-3, est.protection_level_m)
        bad += est.ok and err > 5e-3
        if not est.ok:
            reasons.add(est.reason.split(" ")[0])
    assert bad == 0
    assert found == 60
    assert reasons <= {"protection"}


def test_alert_limit_and_bad_frames_give_not_ok_with_a_reason_never_an_exception():
    rng = np.random.default_rng(4)
    model = _model()
    p = np.array([0.01, 0.0, 0.05])
    f = _frame(model, p, np.zeros(9), rng)
    est = _loc(model, "model", cores=False, alert_limit_m=1e-5).estimate(np.r_[f[0], f[1]], np.zeros(9))
    assert not est.ok and "alert limit" in est.reason
    assert est.protection_level_m > 1e-5 and math.isfinite(est.protection_level_m)
    loc = _loc(model, "model", cores=False)
    nan = np.full((9, 3), np.nan)
    good = np.r_[f[0], f[1]]
    frames = {"shape": (good[:17], np.zeros(9)),
              "Inf": (np.where(np.arange(18)[:, None] == 11, np.inf, good), np.zeros(9)),
              "currents": (good, np.r_[np.zeros(8), np.nan]),
              "currents ": (good, None),
              "usable": (np.r_[nan, nan], np.zeros(9)),
              "usable ": (np.r_[np.where(np.arange(9)[:, None] < 2, f[0], np.nan), nan],
                          np.zeros(9)),
              "readings": ("not a frame", np.zeros(9)),
              "readings ": ([[0.0, 0.0], [0.0]], np.zeros(9)),
              "readings  ": (good[:, :2], np.zeros(9)),
              "tesla": (good * 1e3, np.zeros(9)),
              "currents  ": (good, ["a"] * 9),
              "currents   ": (good, np.zeros(8)),
              "currents    ": (good, np.r_[np.zeros(8), np.inf])}
    for word, (readings, i) in frames.items():
        est = loc.estimate(readings, i)
        assert not est.ok and word.strip() in est.reason, (word, est.reason)
        assert np.all(np.isfinite(est.position_m))
    # a good frame after the bad ones: found again
    est = loc.estimate(np.r_[f[0], f[1]], np.zeros(9))
    assert est.ok and np.linalg.norm(est.position_m - p) < est.protection_level_m


def test_ratio_quantiles_match_the_closed_forms_and_a_monte_carlo():
    """k(r) with P(z1^2 + r (z2^2 + z3^2) > k) = risk: chi-square(1) at r = 0, chi-square(3)
    at r = 1 (z1^2 + chi-square(2)), rising in between; at r = 0.5 and risk 1e-2 against the
    empirical quantile of 4e6 draws (its sampling error ~0.3 %: a tail off by 2x in the
    conditional integral moves k by ~10 %). The protection level uses the bound, never below
    the exact generalized chi-square quantile."""
    from scipy.stats import chi2

    from firmware_io.localization.integrity import RATIO_STEPS, ratio_quantiles

    for risk in (1e-2, 1e-4, 1e-6):
        k = ratio_quantiles(risk)
        assert len(k) == RATIO_STEPS + 1
        assert k[0] == pytest.approx(chi2.isf(risk, 1), rel=1e-9)
        assert k[-1] == pytest.approx(chi2.isf(risk, 3), rel=1e-6)
        assert np.all(np.diff(k) > 0)
    z = np.random.default_rng(0).normal(size=(4_000_000, 3)) ** 2
    want = np.quantile(z[:, 0] + 0.5 * (z[:, 1] + z[:, 2]), 1 - 1e-2)
    assert ratio_quantiles(1e-2)[RATIO_STEPS // 2] == pytest.approx(want, rel=0.01)


@pytest.mark.slow
def test_integrity_study_smoke(tmp_path):
    from conftest import load_study

    res = load_study("localization_integrity").run(tmp_path, n=4)
    assert [r["condition"] for r in res["rows"]] == list(
        ("cold", "jump", "sensor dead", "two saturated", "6 A", "uncalibrated"))
    assert all(r["n"] == 4 and 0 <= r["availability"] <= 1 for r in res["rows"])
    assert (tmp_path / "integrity.json").is_file() and (tmp_path / "integrity_table.txt").is_file()


def test_calibrated_response_variance_matches_the_scatter_over_calibrations():
    """The measured coils' field plus offset at currents I (one sensor, least squares over
    noisy frames) scatters over repeated calibrations with the variance sigma^2 x^T D x, x =
    (I, 1), D = (X^T X)^-1 -- the term the localizer adds to each reading's variance; at 6 A
    per coil the coils' part dominates. A wrong scale (sigma instead of sigma^2, a missing
    factor of the frame count) moves the ratio far outside 0.85-1.15 (600 samples: the
    ratio's own scatter ~6 %)."""
    from firmware_io.localization.calibration import _measured_response

    rng = np.random.default_rng(7)
    k_true, off_true, noise = rng.normal(scale=5e-3, size=(3, 9)), rng.normal(size=3) * 1e-4, 1e-4
    cur = np.r_[np.kron(np.eye(9), [[3.0], [-3.0]]), rng.uniform(-1.5, 1.5, (100, 9))]
    x = np.r_[np.full(9, 6.0) * rng.choice([-1, 1], 9), 1.0]
    pred = []
    for _ in range(200):
        reads = cur @ k_true.T + off_true + rng.normal(scale=noise, size=(len(cur), 3))
        kk, off, _, d_inv = _measured_response(reads, cur, noise, "0:0")
        pred.append(kk @ x[:9] + off)
    err = np.array(pred) - (k_true @ x[:9] + off_true)
    want = noise ** 2 * x @ d_inv @ x
    assert np.mean(err ** 2) / want == pytest.approx(1.0, abs=0.15)


def test_fused_protection_level_holds_its_risk_for_a_rounder_filtered_covariance():
    """A fix with a needle-like covariance (l2 / l1 = 0.1) and its PL from the ratio table at
    risk 1e-2; filtered with a prediction of isotropic variance p, the error covariance is
    (1 - K)^2 p I + K^2 C (rounder). Drawn from it (4e5 samples), the share beyond the fused
    PL's noise part stays <= 1e-2 (a fused PL that kept the fix's needle quantile misses
    1.6 %) and above 0.5e-2 (the table, not the loose r' / r bound, sets it)."""
    from firmware_io.localization.integrity import covariance_and_pl, fused_protection_level
    from firmware_io.localization.integrity import ratio_quantiles

    table, bias, risk = ratio_quantiles(1e-2), 0.5e-3, 1e-2
    c = np.diag([0.1, 0.1, 1.0]) * (1e-3) ** 2
    fisher = np.linalg.inv(c).tolist()
    cov, pl = covariance_and_pl(fisher, 0.0, 10, table)
    assert pl == pytest.approx(np.sqrt(1e-6 * table[2]), rel=1e-9)
    p, gain = (0.7e-3) ** 2, 0.5
    fused = fused_protection_level(pl + bias, cov, p, bias, gain, table) - bias
    f = (1 - gain) ** 2 * p * np.eye(3) + gain ** 2 * cov
    e = np.random.default_rng(5).multivariate_normal(np.zeros(3), f, size=400_000)
    beyond = np.mean(np.linalg.norm(e, axis=1) > fused)
    assert 0.5 * risk < beyond <= risk * 1.05


def test_fused_protection_level_reads_the_fix_s_own_table():
    """The fix's quantile comes from the table it is given (the localizer's risk), at the
    index of its own covariance's ratio, whatever other tables exist: a fix at risk 1e-4 with
    l2 / l1 = 0.1 (index 2), filtered to r' = 0.55 (index 11): noise part sqrt(l1' k_11) of
    the 1e-4 table, not of the 1e-2 table; tighter than the table-free bound r' / r_j
    (k(r') <= k(r_j) r' / r_j), which applies without a table."""
    c = np.diag([0.1, 0.1, 1.0]) * (1e-3) ** 2
    p, gain, bias = 1e-6, 0.5, 0.5e-3          # filtered: 0.25 p + 0.25 c -> 0.275, 0.5 (um^2)
    want_l1, want_r = 0.25 * 1e-6 + 0.25 * 1e-6, (0.25 + 0.025) / 0.5
    assert math.ceil(want_r * 20) == 11
    for risk, other in ((1e-4, 1e-2), (1e-2, 1e-4)):
        table = ratio_quantiles(risk)
        ratio_quantiles(other)
        cov, pl = covariance_and_pl(np.linalg.inv(c).tolist(), 0.0, 10, table)
        got = fused_protection_level(pl + bias, cov, p, bias, gain, table)
        assert got == pytest.approx(bias + math.sqrt(want_l1 * table[11]), rel=1e-9)
        loose = fused_protection_level(pl + bias, cov, p, bias, gain)
        assert loose == pytest.approx(
            bias + math.sqrt(want_l1 * table[2] * want_r / 0.1), rel=1e-9)
        assert got < loose
