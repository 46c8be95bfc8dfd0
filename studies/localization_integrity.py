"""Question: does the localizer's integrity hold -- how often is a fix flagged ok while its
error exceeds its protection level (PL) or 5 mm, how available are ok fixes, how large are the
PLs, and what do a cold and a warm fix cost?

Data the model did not produce: the magnet's field from magpylib's exact cylinder (10 x 10 mm,
moment from the design) at the sensors' true, displaced poses; the coils' coupled field at the
currents; the cores' field induced by the magnet (designkit.sim.readings, each core solved at the
true sensor poses); the TLV493D chain (``--noise-mt`` rms noise, 0.098 mT LSB, NaN beyond
+-130 mT) with the device's sensor errors (offset, 1 % gain, 1 degree and 0.5 mm mounting). The
localizer knows the nominal poses, the map's (the forward model's) coil field, its gradient at
the sensors and core operator, and -- except in 'uncalibrated' -- the start-up calibration (1000
coil-only frames).

Conditions (``n`` fixes each, positions 20-70 mm above the coils, |x|, |y| <= 25 mm unless
stated; currents of the thesis cases 1-3 drawn per frame unless stated; the localizer without an
alert limit, as under the runner; ok at an alert limit = passed its tests and PL within it):
'cold' (no warm start), 'jump' (warm start from the previous fix, 10-60 mm away), 'sensor dead'
(one random sensor NaN per frame, tracking), 'two saturated' (the two strongest sensors NaN,
20-35 mm), '6 A' (random currents of 6 A peak), 'uncalibrated' (mounting errors left). Thesis
cases 1-3 at 20-60 mm, cold: availability. Alert limits 5 mm (the acceptance) and 10 mm (the
runner's default), integrity risk 1e-4 per fix. Counts carry a two-sided 95 % Clopper-Pearson
interval; timings also as a ratio to one multipole field evaluation in the same process.

    python studies/localization_integrity.py OUT [--n 10000] [--noise-mt 0.05]  # json, table
    python studies/localization_integrity.py --bench   # cold / warm fix time, median of 3
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
from scipy.stats import beta

from designkit.design import default_design
from designkit.sim.readings import SensorSimulator, case_currents, forward_model, random_positions
from firmware_io.constants import MU0
from firmware_io.localization import POSITION_ONLY, ModelEstimator, SensorModel, multipole_field
from firmware_io.localization.integrity import fused_protection_level, ratio_quantiles
from firmware_io.runner import PoseTracker
from studies.localization import _calibrate, with_coil_gradient

ALERT_LIMIT_M = 5e-3
ALERT_LIMIT_RUNNER_M = 10e-3
RISK = 1e-4
FRAME_S = 2e-3
"""Sensor frame period of the tracked thesis paths, s (one bus pass over both arrays)."""
NOISE_T = 0.05e-3
"""Sensor noise of the issue's independent check, T rms per axis (plus the 0.098 mT LSB)."""
CONDITIONS = ("cold", "jump", "sensor dead", "two saturated", "6 A", "uncalibrated")


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple:
    """Two-sided exact binomial interval of k / n."""
    a = 1 - level
    lo = 0.0 if k == 0 else float(beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def magnet_field_magpylib(sim, positions_m) -> np.ndarray:
    """(k, 2, n, 3) T: magpylib's exact cylinder at the true sensor poses, one path."""
    import magpylib as magpy

    mg = sim.design.magnet
    vol = np.pi * mg.radius_m ** 2 * mg.length_m
    cyl = magpy.magnet.Cylinder(polarization=MU0 * sim.moment_a_m2 / vol,
                                dimension=(2 * mg.radius_m, mg.length_m),
                                position=np.asarray(positions_m))
    b = cyl.getB(sim.true_m.reshape(-1, 3))
    return np.asarray(b).reshape(len(positions_m), 2, sim.n, 3)


def _positions(cond, n, rng):
    if cond == "two saturated":
        return random_positions(n, rng, z_range_m=(0.020, 0.035))
    if cond != "jump":
        return random_positions(n, rng)
    out = [random_positions(1, rng)[0]]
    while len(out) < n:
        d = rng.normal(size=3)
        q = out[-1] + d / np.linalg.norm(d) * rng.uniform(0.010, 0.060)
        if np.all(np.abs(q[:2]) <= 0.025) and 0.020 <= q[2] <= 0.070:
            out.append(q)
    return np.array(out)


def _tracking(n, rng):
    """A slow random walk (0.1-3 mm a frame) in the cube: the warm path."""
    p = [random_positions(1, rng)[0]]
    while len(p) < n:
        q = p[-1] + rng.normal(scale=1e-3, size=3)
        p.append(np.clip(q, [-0.025, -0.025, 0.020], [0.025, 0.025, 0.070]))
    return np.array(p)


def _frames(sim, cond, n, rng):
    pos = _tracking(n, rng) if cond == "sensor dead" else _positions(cond, n, rng)
    t = rng.uniform(0, 20, n)
    if cond == "6 A":
        cur = case_currents("rendering", t, sim.array.n_coils, seed=int(rng.integers(1 << 30)))
    else:
        cases = rng.integers(0, 3, n)
        cur = np.stack([case_currents(("off", "static", "sinusoidal")[c], t[k:k + 1],
                                      sim.array.n_coils)[0] for k, c in enumerate(cases)])
    mag = magnet_field_magpylib(sim, pos)
    ind = sim.induced_part(pos)
    rd = sim.read(pos, cur, parts=(mag, ind), rng=rng)
    top, bot = rd.top_t.copy(), rd.bottom_t.copy()
    if cond == "sensor dead":
        j = rng.integers(0, 2 * sim.n, n)
        for k in range(n):
            (top if j[k] < sim.n else bot)[k, j[k] % sim.n] = np.nan
    if cond == "two saturated":
        strength = np.linalg.norm(rd.true_field_t[:, 0], axis=-1)
        for k in range(n):
            top[k, np.argsort(strength[k])[-2:]] = np.nan
    return pos, cur, top, bot


def run_condition(loc, sim, cond, n, rng) -> dict:
    pos, cur, top, bot = _frames(sim, cond, n, rng)
    loc.reset()
    err, pl, ok, ts = np.empty(n), np.empty(n), np.zeros(n, bool), np.empty(n)
    for k in range(n):
        if cond in ("cold", "two saturated", "6 A", "uncalibrated"):
            loc.reset()
        t0 = time.perf_counter()
        e = loc.estimate(np.r_[top[k], bot[k]], cur[k])
        ts[k] = time.perf_counter() - t0
        err[k] = np.linalg.norm(e.position_m - pos[k])
        pl[k], ok[k] = e.protection_level_m, e.ok
    # the localizer runs without an alert limit (as under the runner, which applies its own):
    # ok at an alert limit = passed the tests and PL within it
    ok10 = ok & (pl <= ALERT_LIMIT_RUNNER_M)
    ok = ok & (pl <= ALERT_LIMIT_M)
    big, over = int(np.sum(ok & (err > 5e-3))), int(np.sum(ok & (err > pl)))
    n_ok = int(ok.sum())
    return {"condition": cond, "n": n, "ok": n_ok, "availability": n_ok / n,
            "availability_al10": float(ok10.mean()),
            "al10_ok_error_above_5mm": int(np.sum(ok10 & (err > 5e-3))),
            "al10_ok_error_above_pl": int(np.sum(ok10 & (err > pl))),
            "ok_error_above_5mm": big, "ok_error_above_5mm_ci": clopper_pearson(big, n),
            "ok_error_above_pl": over, "ok_error_above_pl_ci": clopper_pearson(over, n),
            "pl_mm_p50_p90_p99": [float(x) for x in np.percentile(pl[ok] * 1e3, [50, 90, 99])]
            if n_ok else None,
            "mae_ok_mm": float(err[ok].mean() * 1e3) if n_ok else None,
            "fix_ms_median": float(np.median(ts) * 1e3), "fix_ms_p99": float(
                np.percentile(ts, 99) * 1e3)}


def _smooth_path(m, rng, speed_m_s=0.05, lo=(-0.025, -0.025, 0.020), hi=(0.025, 0.025, 0.060)):
    """A finger exploring the box along a Lissajous curve (peak speed ~``speed_m_s`` per axis,
    accelerations ~0.1 m/s^2, within the tracker's model): one position per FRAME_S, (m, 3) m."""
    lo, hi = np.array(lo), np.array(hi)
    amp = (hi - lo) / 2
    w = speed_m_s / amp * rng.uniform(0.5, 1.0, 3)
    t = np.arange(m)[:, None] * FRAME_S
    return (lo + hi) / 2 + amp * np.sin(w * t + rng.uniform(0, 2 * np.pi, 3))


def thesis_tracked(loc, sim, case, m, rng) -> dict:
    """The runner's availability along a path (warm fixes, the tracker, the multi-frame
    protection level of the tracker's filtered position, as the runner computes it): share of
    frames whose fix is ok with a protection level within ALERT_LIMIT_M, and of those whose
    rendered position (the tracker's, else the fix) is > 5 mm off or beyond the PL."""
    pos = _smooth_path(m, rng)
    cur = case_currents(case, np.arange(m) * FRAME_S, sim.array.n_coils)
    rd = sim.read(pos, cur, parts=(magnet_field_magpylib(sim, pos), sim.induced_part(pos)),
                  rng=rng)
    loc.reset()
    trk, acquired = PoseTracker(), False
    ok = np.zeros(m, bool)
    err, pls = np.empty(m), np.empty(m)
    for k in range(m):
        e = loc.estimate(np.r_[rd.top_t[k], rd.bottom_t[k]], cur[k])
        pl, tracked = e.protection_level_m, trk.x is not None
        if e.ok and tracked:
            _, var = trk.innovation(e.position_m, k * FRAME_S)
            pl = fused_protection_level(pl, e.position_covariance_m2, var - trk.r, loc.model_bias_m,
                                        (var - trk.r) / var, ratio_quantiles(loc.integrity_risk))
        ok[k], pls[k] = e.ok and pl <= ALERT_LIMIT_M, pl
        if ok[k] or e.ok and not acquired:   # acquisition: the runner's tracker takes it
            trk.update(e.position_m, k * FRAME_S, True)
        acquired |= ok[k]
        err[k] = np.linalg.norm((trk.x[0] if ok[k] and tracked else e.position_m) - pos[k])
    return {"n": m, "availability": float(ok.mean()),
            "ok_error_above_5mm": int(np.sum(ok & (err > 5e-3))),
            "ok_error_above_pl": int(np.sum(ok & (err > pls))),
            "pl_mm_p50_p90": [float(x) for x in np.percentile(pls[ok] * 1e3, [50, 90])]
            if ok.any() else None}


def _reference_s(model) -> float:
    """One multipole field evaluation at the 2n sensors: the timings' same-process unit."""
    pts = model.sensor_positions_m.reshape(-1, 3)
    p = np.array([0.0, 0.0, 0.04])
    t0 = time.perf_counter()
    for _ in range(2000):
        multipole_field(pts, p, model.moment_a_m2, model.octupole_m2)
    return (time.perf_counter() - t0) / 2000


def _device(seed: int, noise_t: float):
    """(simulator with the device's sensor errors, the localizer's model with the exact
    cylinder, the start-up calibration from 1000 coil-only frames)."""
    design = default_design()
    sim = SensorSimulator(design, errors="default", seed=seed, induced="rod", noise_t=noise_t)
    mg = design.magnet
    model = dataclasses.replace(with_coil_gradient(sim, SensorModel.from_operator(
        **forward_model(sim))), magnet_size_m=(mg.radius_m, mg.length_m))
    cal, _ = _calibrate(sim, model, seed + 1000, 1000)
    return sim, model, cal


def bench(n: int = 100, seed: int = 0, repeats: int = 3, noise_t: float = NOISE_T) -> dict:
    """Cold (global search) and warm (a 0.5 mm-per-axis random walk) fix times, s: the median
    and p99 of each of ``repeats`` runs over ``n`` frames (calibrated localizer, thesis case 3
    currents), with the same-process multipole reference."""
    rng = np.random.default_rng(seed)
    sim, model, cal = _device(seed, noise_t)
    loc = ModelEstimator(model, dataclasses.replace(POSITION_ONLY, noise_t=noise_t),
                         calibration=cal)
    cur = case_currents("sinusoidal", rng.uniform(0, 20, n), sim.array.n_coils)
    cold = sim.read(random_positions(n, rng), cur, rng=rng)
    walk = np.cumsum(rng.normal(scale=0.5e-3, size=(n, 3)), 0) + [0.0, 0.0, 0.04]
    warm = sim.read(walk, cur, rng=rng)
    out = []
    for _ in range(repeats):
        tc, tw = [], []
        for k in range(n):
            loc.reset()
            t0 = time.perf_counter()
            loc.estimate(np.r_[cold.top_t[k], cold.bottom_t[k]], cur[k])
            tc.append(time.perf_counter() - t0)
        for k in range(n):
            t0 = time.perf_counter()
            loc.estimate(np.r_[warm.top_t[k], warm.bottom_t[k]], cur[k])
            tw.append(time.perf_counter() - t0)
        ref = _reference_s(model)
        out.append({"cold_ms_median": float(np.median(tc) * 1e3),
                    "cold_ms_p99": float(np.percentile(tc, 99) * 1e3),
                    "warm_us_median": float(np.median(tw[1:]) * 1e6),
                    "reference_us": ref * 1e6})
        print(f"cold {out[-1]['cold_ms_median']:.2f} ms median, {out[-1]['cold_ms_p99']:.2f} ms "
              f"p99 ({np.median(tc) / ref:.0f}x ref); warm {out[-1]['warm_us_median']:.0f} us "
              f"median ({np.median(tw[1:]) / ref:.1f}x ref); ref {ref * 1e6:.1f} us", flush=True)
    med = {k: float(np.median([r[k] for r in out])) for k in out[0]}
    print(f"median of {repeats} runs: cold {med['cold_ms_median']:.2f} ms (target <= 2), warm "
          f"{med['warm_us_median']:.0f} us (target <= 200); reference {med['reference_us']:.1f} "
          f"us; cold / ref {med['cold_ms_median'] * 1e3 / med['reference_us']:.0f}x, warm / ref "
          f"{med['warm_us_median'] / med['reference_us']:.1f}x", flush=True)
    return {"runs": out, "median": med}


def run(out_dir, n: int = 10000, seed: int = 0, conditions=CONDITIONS,
        thesis_cases=("off", "static", "sinusoidal"), noise_t: float = NOISE_T,
        model_bias_m: float | None = None) -> dict:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    sim, model, cal = _device(seed, noise_t)
    kw = dict(integrity_risk=RISK, noise_t=noise_t)
    if model_bias_m is not None:
        kw["model_bias_m"] = model_bias_m
    loc_cal = ModelEstimator(model, dataclasses.replace(POSITION_ONLY, **kw), calibration=cal)
    loc_uncal = ModelEstimator(model, dataclasses.replace(POSITION_ONLY, **kw))
    rows = []
    for c in conditions:
        rows.append(run_condition(loc_uncal if c == "uncalibrated" else loc_cal, sim, c, n, rng))
        print(json.dumps(rows[-1]), flush=True)
    thesis = {}
    for case in thesis_cases:
        m = max(n // 10, 50)
        pos = random_positions(m, rng, z_range_m=(0.020, 0.060))
        cur = case_currents(case, rng.uniform(0, 20, m), sim.array.n_coils)
        rd = sim.read(pos, cur, parts=(magnet_field_magpylib(sim, pos), sim.induced_part(pos)),
                      rng=rng)
        oks = []
        for k in range(m):
            loc_cal.reset()
            e = loc_cal.estimate(np.r_[rd.top_t[k], rd.bottom_t[k]], cur[k])
            oks.append((e.ok and e.protection_level_m <= ALERT_LIMIT_M,
                        e.ok and e.protection_level_m <= ALERT_LIMIT_RUNNER_M))
        a5, a10 = np.mean(oks, axis=0)
        thesis[case] = {"n": m, "availability": float(a5), "availability_al10": float(a10),
                        "tracked": thesis_tracked(loc_cal, sim, case, 10 * m, rng)}
        print(json.dumps({case: thesis[case]}), flush=True)
    ref = _reference_s(model)
    res = {"n_per_condition": n, "alert_limit_m": ALERT_LIMIT_M, "integrity_risk": RISK,
           "noise_t": noise_t, "model_bias_m": loc_cal.model_bias_m,
           "rows": rows, "thesis_availability_20_60mm": thesis,
           "reference_multipole_us": ref * 1e6,
           "total_ok_error_above_5mm": sum(r["ok_error_above_5mm"] for r in rows),
           "total_fixes": n * len(rows)}
    (out / "integrity.json").write_text(json.dumps(res, indent=1))
    table = _table(res)
    (out / "integrity_table.txt").write_text(table + "\n")
    print(table)
    return res


def _table(res) -> str:
    ref_ms = res["reference_multipole_us"] * 1e-3
    lines = [f"{'condition':14s} {'n':>6s} {'avail':>6s} {'>5mm ok (95% CI)':>22s} "
             f"{'>PL ok (95% CI)':>24s} {'PL p50/p90/p99 mm':>18s} {'MAE':>5s} "
             f"{'ms med/p99 (x ref)':>22s} {'AL 10 mm: avail, >5mm, >PL':>28s}"]
    for r in res["rows"]:
        ci5, cip = r["ok_error_above_5mm_ci"], r["ok_error_above_pl_ci"]
        pl = r["pl_mm_p50_p90_p99"] or [float("nan")] * 3
        lines.append(
            f"{r['condition']:14s} {r['n']:6d} {r['availability']:6.3f} "
            f"{r['ok_error_above_5mm']:4d} ({ci5[0]:.1e}-{ci5[1]:.1e}) "
            f"{r['ok_error_above_pl']:5d} ({cip[0]:.1e}-{cip[1]:.1e}) "
            f"{pl[0]:5.2f}/{pl[1]:5.2f}/{pl[2]:5.2f} {r['mae_ok_mm'] or float('nan'):5.2f} "
            f"{r['fix_ms_median']:5.2f}/{r['fix_ms_p99']:5.2f} "
            f"({r['fix_ms_median'] / ref_ms:.0f}x) {r['availability_al10']:6.3f} "
            f"{r['al10_ok_error_above_5mm']:4d} {r['al10_ok_error_above_pl']:4d}")
    lines.append("thesis cases 1-3, 20-60 mm, cold, availability: " + ", ".join(
        f"{k} {v['availability']:.3f} (AL 10 mm: {v['availability_al10']:.3f}, n={v['n']})"
        for k, v in res["thesis_availability_20_60mm"].items()))
    lines.append("thesis cases 1-3, 20-60 mm, tracked (<= 50 mm/s, multi-frame PL): " + ", ".join(
        f"{k} {v['tracked']['availability']:.4f} (n={v['tracked']['n']}, > 5 mm ok "
        f"{v['tracked']['ok_error_above_5mm']}, > PL ok {v['tracked']['ok_error_above_pl']})"
        for k, v in res["thesis_availability_20_60mm"].items()))
    lines.append(f"total: {res['total_ok_error_above_5mm']} of {res['total_fixes']} fixes > 5 mm "
                 f"off flagged ok; reference multipole evaluation "
                 f"{res['reference_multipole_us']:.1f} us")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?",
                    default=Path(__file__).resolve().parents[1] / "out" / "localization_integrity")
    ap.add_argument("--n", type=int, default=10000, help="fixes per condition")
    ap.add_argument("--seed", type=int, default=0, help="device (sensor errors) and noise seed")
    ap.add_argument("--conditions", default=",".join(CONDITIONS),
                    help="comma-separated subset of: " + ", ".join(CONDITIONS))
    ap.add_argument("--no-thesis", action="store_true", help="skip the thesis-case availability")
    ap.add_argument("--bench", action="store_true", help="only the cold / warm fix timing")
    ap.add_argument("--noise-mt", type=float, default=NOISE_T * 1e3,
                    help="sensor noise, mT rms per axis, simulated and assumed by the localizer "
                         "(default: the issue's independent check)")
    ap.add_argument("--model-bias-mm", type=float, default=None,
                    help="the localizer's model-bias bound, mm (default: the localizer's)")
    a = ap.parse_args(argv)
    conds = tuple(c.strip() for c in a.conditions.split(",") if c.strip())
    bad = [c for c in conds if c not in CONDITIONS]
    if bad or a.n < 1 or not 0 <= a.noise_mt < 10:
        print(f"error: --conditions {bad} / --n {a.n} / --noise-mt {a.noise_mt}: conditions "
              f"from {CONDITIONS}, n >= 1, noise in [0, 10) mT")
        return 2
    if a.bench:
        bench(seed=a.seed, noise_t=a.noise_mt * 1e-3)
        return 0
    run(a.out, a.n, a.seed, conds, () if a.no_thesis else ("off", "static", "sinusoidal"),
        a.noise_mt * 1e-3, None if a.model_bias_mm is None else a.model_bias_mm * 1e-3)
    return 0


if __name__ == "__main__":
    sys.exit(main())
