"""Question: does the pose estimator keep its integrity and accuracy as a finger really moves
the magnet -- tilted 0-45 degrees, one sensor lying with an ok status, a uniform ambient field,
a steel object nearby -- on data its model did not produce, and at what availability?

Data: magpylib's finite cylinder (the design's magnet, tilted 0-45 degrees from its axis, any
azimuth) at the sensors' true, displaced poses; the coils' field from designkit at the frame's
currents; the cores' field of the tilted magnet (designkit's rod model); the TLV493D chain
(``--noise-mt``, 0.098 mT LSB, NaN beyond 130 mT) with the device's sensor errors. The
estimator (``ModelEstimator``, default settings) knows the nominal poses, designkit's forward
model (the map's numbers) and the start-up calibration (1000 coil-only frames).
Positions |x|, |y| <= 25 mm, 20-70 mm up; thesis cases 1-3 currents. Conditions (the same
frames): 'tilt'; 'zeros', 'frozen' (the reading for the magnet 2-20 mm away), 'offset' (+-2 mT,
one axis), 'gain' (5 %) on sensor k mod 18 of fix k, ok status; 'ambient' (uniform 0-1 mT);
'steel' (a dipole 150 mm from the array's centre, 0.5 mT there). Modes: 'cold' (one frame
alone), 'prior' (a tracker's prediction: the true pose displaced by N(0, 0.5 mm) per axis and
N(0, 2 degrees) per tangent axis, with that covariance).
Printed per condition and mode: availability, trusted fixes beyond their protection levels or
> 5 mm off, trusted MAE against the 5-DOF Cramer-Rao bound's, the direction's median error, the
force error of least-norm currents for 1 N on the estimated pose applied to the true magnet
(designkit's F = (grad B)^T m), the faulty sensor named. Writes pose_integrity.json/.txt.

    nice -n 10 python studies/pose_integrity.py OUT [--n 300] [--full] [--conditions ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import magpylib as magpy
import numpy as np
from scipy.spatial.transform import Rotation

from designkit.design import default_design
from designkit.sim.readings import (InducedCoreModel, SensorSimulator, case_currents,
                                    forward_model, random_positions)
from firmware_io.constants import MU0
from firmware_io.localization import EstimatorSettings, ModelEstimator, Pose, SensorModel
from firmware_io.localization.pose import tangent_axes
from firmware_io.localization.pose_fit import State
from firmware_io.mapfile import gradient_tensor
from studies._common import finish, load_average, run_interruptible
from studies.localization import _calibrate, with_coil_gradient

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "pose_integrity"
CONDITIONS = ("tilt", "zeros", "frozen", "offset", "gain", "ambient", "steel")
FAULTS = ("zeros", "frozen", "offset", "gain")
MODES = ("cold", "prior")
PRIOR_SD = (0.5e-3, math.radians(2.0))
"""The 'prior' mode's tracker prediction: sd per position axis (m) and tangent axis (rad)."""
FORCE_CHECKS = 2000
"""Trusted fixes per condition whose force error is evaluated (designkit's field is slow)."""


def _device(seed: int, noise_t: float):
    """(simulator with the device's sensor errors, the estimator's model with the exact
    cylinder, its calibration, the rod model of the cores at the true sensor poses)."""
    design = default_design()
    sim = SensorSimulator(design, errors="default", seed=seed, induced="rod", noise_t=noise_t)
    mg = design.magnet
    model = dataclasses.replace(with_coil_gradient(sim, SensorModel.from_operator(
        **forward_model(sim))), magnet_size_m=(mg.radius_m, mg.length_m))
    cal, _ = _calibrate(sim, model, seed + 1000, 1000)
    cores = InducedCoreModel(design, sim.true_m.reshape(-1, 3))
    return sim, model, cal, cores


def _tilted(axis0: np.ndarray, tilt: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    """(k, 3) unit vectors tilted by ``tilt`` rad from ``axis0`` towards ``azimuth`` rad."""
    e1, e2 = tangent_axes(axis0)
    side = np.cos(azimuth)[:, None] * e1 + np.sin(azimuth)[:, None] * e2
    return np.cos(tilt)[:, None] * axis0 + np.sin(tilt)[:, None] * side


def _magnet_field(sim, positions, dirs) -> np.ndarray:
    """(k, n, 3) T: magpylib's tilted cylinders at the true sensor poses."""
    mg = sim.design.magnet
    size = float(np.linalg.norm(sim.moment_a_m2))
    pol = MU0 * size / (math.pi * mg.radius_m ** 2 * mg.length_m)
    rot = Rotation.align_vectors(dirs, np.tile([0.0, 0.0, 1.0], (len(dirs), 1)))[0] \
        if len(dirs) == 1 else Rotation.from_rotvec(_rotvecs(dirs))
    cyl = magpy.magnet.Cylinder(polarization=(0.0, 0.0, pol),
                                dimension=(2 * mg.radius_m, mg.length_m),
                                position=positions, orientation=rot)
    return np.asarray(cyl.getB(sim.true_m.reshape(-1, 3))).reshape(len(positions), -1, 3)


def _rotvecs(dirs: np.ndarray) -> np.ndarray:
    """Rotation vectors taking +z onto each unit vector (k, 3)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, dirs)
    s = np.linalg.norm(axis, axis=1)
    ang = np.arctan2(s, dirs @ z)
    safe = np.where(s > 1e-12, s, 1.0)
    out = axis / safe[:, None] * ang[:, None]
    flip = (s <= 1e-12) & (dirs @ z < 0)
    out[flip] = [math.pi, 0.0, 0.0]
    return out


def _frames(sim, cores, n: int, rng):
    """The fault-free frames' truth: positions, directions, currents, the true field at the
    sensors (k, n, 3) T, and the field for the 'frozen' fault (the magnet 2-20 mm away)."""
    pos = random_positions(n, rng, z_range_m=(0.020, 0.070))
    axis0 = sim.moment_a_m2 / np.linalg.norm(sim.moment_a_m2)
    dirs = _tilted(axis0, np.radians(rng.uniform(0, 45, n)), rng.uniform(0, 2 * np.pi, n))
    cases = rng.integers(0, 3, n)
    t = rng.uniform(0, 20, n)
    cur = np.stack([case_currents(("off", "static", "sinusoidal")[c], t[k:k + 1],
                                  sim.array.n_coils)[0] for k, c in enumerate(cases)])
    mg, size = sim.design.magnet, float(np.linalg.norm(sim.moment_a_m2))
    ind = np.stack([cores.field_of_magnet(pos[k:k + 1], size * dirs[k], mg.radius_m,
                                          mg.length_m)[0] for k in range(n)])
    coil = sim.coil_part(cur).reshape(n, -1, 3)
    field = _magnet_field(sim, pos, dirs) + ind + coil
    away = rng.normal(size=(n, 3))
    away *= rng.uniform(0.002, 0.020, (n, 1)) / np.linalg.norm(away, axis=1)[:, None]
    frozen = _magnet_field(sim, pos + away, dirs) + ind + coil
    return {"pos": pos, "dirs": dirs, "cur": cur, "field": field, "frozen": frozen,
            "cases": cases}


def _steel_field(sim, rng, n: int) -> np.ndarray:
    """(k, n, 3) T: a dipole 150 mm from the array's centre (random direction, not below the
    lower board), scaled to 0.5 mT at the centre."""
    pts = sim.true_m.reshape(-1, 3)
    centre = pts.mean(axis=0)
    out = np.empty((n, len(pts), 3))
    for k in range(n):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        c = centre + 0.15 * d
        m = rng.normal(size=3)
        m /= np.linalg.norm(m)
        r = pts - c
        r0 = centre - c
        b = _dipole(r, m)
        out[k] = b * 0.5e-3 / np.linalg.norm(_dipole(r0[None], m)[0])
    return out


def _dipole(r: np.ndarray, m: np.ndarray) -> np.ndarray:
    rr = np.linalg.norm(r, axis=1)[:, None]
    return MU0 / (4 * math.pi) * (3 * r * (r @ m)[:, None] / rr ** 5 - m / rr ** 3)


def _readings(sim, truth, cond: str, rng) -> np.ndarray:
    """(k, n, 3) T as reported for ``cond`` (sensor errors, noise, quantization; NaN where
    saturated), the fault applied after the readout with an ok status."""
    n = len(truth["pos"])
    field = truth["field"].copy()
    if cond == "ambient":
        v = rng.normal(size=(n, 3))
        field += (v / np.linalg.norm(v, axis=1)[:, None] * rng.uniform(0, 1e-3, (n, 1)))[:, None]
    elif cond == "steel":
        field += _steel_field(sim, rng, n)
    rd = sim.readout(field.reshape(n, 2, -1, 3), rng=rng)
    out = np.concatenate([rd.top_t, rd.bottom_t], 1)
    if cond in FAULTS:
        s = np.arange(n) % out.shape[1]
        rows = np.arange(n)
        if cond == "zeros":
            out[rows, s] = 0.0
        elif cond == "frozen":
            fr = sim.readout(truth["frozen"].reshape(n, 2, -1, 3), rng=rng)
            old = np.concatenate([fr.top_t, fr.bottom_t], 1)[rows, s]
            out[rows, s] = np.where(np.isfinite(old), old, 0.13)
        elif cond == "offset":
            axis = rng.integers(0, 3, n)
            out[rows, s, axis] = np.nan_to_num(out[rows, s, axis], nan=0.13) \
                + rng.choice([-2e-3, 2e-3], n)
        else:
            out[rows, s] = np.nan_to_num(out[rows, s], nan=0.13) * 1.05
    return out


def _crb_mae(est, truth, readings, prior: bool) -> np.ndarray:
    """Per fix: E|e| of the position under the 5-DOF Cramer-Rao bound at the true pose (the
    noise and quantization only, the usable sensors of the frame; with ``prior``, plus the
    prior's information: the Bayesian bound), by 64 Gaussian draws."""
    fit = est.engine
    s = est.settings
    sig = math.sqrt(s.noise_t ** 2 + s.lsb_t ** 2 / 12)
    z = np.random.default_rng(123).normal(size=(64, 3))
    out = np.empty(len(truth["pos"]))
    for k, (p, u) in enumerate(zip(truth["pos"], truth["dirs"])):
        use = np.flatnonzero(np.isfinite(readings[k]).all(axis=1))
        st = State(p, u, 0.0, np.zeros(3), None)
        fit.corr.update(p, u)
        jac, _ = fit.rows(st, use, np.full(len(use), 1.0 / sig), np.zeros((len(use), 3)))
        info = jac[:, :5].T @ jac[:, :5]
        if prior:
            info += np.diag([PRIOR_SD[0] ** -2] * 3 + [PRIOR_SD[1] ** -2] * 2)
        cov = np.linalg.inv(info)[:3, :3]
        out[k] = np.linalg.norm(z @ np.linalg.cholesky(cov).T, axis=1).mean()
    return out


def _force_errors(sim, truth, est_pos, est_m, idx, rng) -> np.ndarray:
    """|F_true - F| / |F| for least-norm currents that give F (1 N, random direction) on the
    estimated pose, applied to the true one (designkit's actuation rows at both points)."""
    if not len(idx):
        return np.zeros(0)
    size = float(np.linalg.norm(sim.moment_a_m2))
    rows = sim.array.actuation_matrix(np.r_[truth["pos"][idx], est_pos[idx]])   # (2k, 8, N)
    g = gradient_tensor(np.moveaxis(rows[:, 3:8], 1, -1))                       # (2k, N, 3, 3)
    k = len(idx)
    m = np.r_[size * truth["dirs"][idx], est_m[idx]]
    a = np.einsum("pnji,pj->pin", g, m)            # F = (grad B)^T m per ampere: (2k, 3, N)
    target = rng.normal(size=(k, 3))
    target /= np.linalg.norm(target, axis=1)[:, None]
    cur = np.einsum("pnj,pj->pn", np.linalg.pinv(a[k:]), target)
    got = np.einsum("pin,pn->pi", a[:k], cur)
    return np.linalg.norm(got - target, axis=1)


def run_condition(est, sim, truth, cond: str, mode: str, seed: int) -> dict:
    """One condition in one mode: per-fix results and their summary (module docstring)."""
    rng = np.random.default_rng(seed)
    readings = _readings(sim, truth, cond, rng)
    n = len(readings)
    size = float(np.linalg.norm(sim.moment_a_m2))
    cov = np.diag([PRIOR_SD[0] ** 2] * 3 + [PRIOR_SD[1] ** 2] * 2)
    ok, err, ang, pl, plu = (np.zeros(n, bool), np.empty(n), np.empty(n), np.empty(n),
                             np.empty(n))
    named, excluded_any = np.zeros(n, bool), np.zeros(n, bool)
    est_pos, est_m, ts = np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    for k in range(n):
        p, u = truth["pos"][k], truth["dirs"][k]
        seed_pose = None
        if mode == "prior":
            e1, e2 = tangent_axes(u)
            a, b = rng.normal(scale=PRIOR_SD[1], size=2)
            up = u + a * e1 + b * e2
            seed_pose = Pose(p + rng.normal(scale=PRIOR_SD[0], size=3),
                             size * up / np.linalg.norm(up), cov)
        est.reset()
        t0 = time.thread_time()
        fix = est.estimate(readings[k], truth["cur"][k], seed=seed_pose)
        ts[k] = time.thread_time() - t0
        ok[k], pl[k], plu[k] = fix.ok, fix.protection_level_m, fix.orientation_protection_level_rad
        est_pos[k], est_m[k] = fix.position_m, fix.moment_a_m2
        err[k] = np.linalg.norm(fix.position_m - p)
        cos = fix.moment_a_m2 @ u / np.linalg.norm(fix.moment_a_m2)
        ang[k] = math.acos(min(1.0, max(-1.0, cos)))
        named[k] = (k % readings.shape[1]) in fix.excluded_sensors
        excluded_any[k] = bool(fix.excluded_sensors)
    trusted = np.flatnonzero(ok)
    crb = _crb_mae(est, {"pos": truth["pos"][trusted], "dirs": truth["dirs"][trusted]},
                   readings[trusted], mode == "prior") if len(trusted) else np.zeros(0)
    force = _force_errors(sim, truth, est_pos, est_m, trusted[:FORCE_CHECKS], rng)
    fixes = {"ok": ok, "err": err, "ang": ang, "pl": pl, "plu": plu, "named": named,
             "excluded_any": excluded_any, "ts": ts}
    return _summary(cond, mode, fixes, crb, force, truth["pos"][:, 2])


def _summary(cond, mode, fixes: dict, crb, force, z) -> dict:
    """One condition's row from its per-fix arrays ``fixes`` (ok, err m, ang rad, pl m, plu rad,
    named, excluded_any, ts s), the trusted fixes' Cramer-Rao MAE (m), the force errors and
    the true heights ``z`` (m)."""
    ok, err, ang, pl, plu, ts = (fixes[k] for k in ("ok", "err", "ang", "pl", "plu", "ts"))
    named, excluded_any = fixes["named"], fixes["excluded_any"]
    n, t = len(ok), ok
    bands = {f"{lo}-{hi} mm": float(ok[(z >= lo / 1e3) & (z < hi / 1e3)].mean())
             for lo, hi in ((20, 35), (35, 50), (50, 70))}
    out = {"condition": cond, "mode": mode, "n": n, "trusted": int(t.sum()),
           "availability": float(t.mean()), "availability_by_height": bands,
           "trusted_beyond_pl": int(np.sum(t & (err > pl))),
           "trusted_beyond_orientation_pl": int(np.sum(t & (ang > plu))),
           "trusted_above_5mm": int(np.sum(t & (err > 5e-3))),
           "mae_trusted_mm": float(err[t].mean() * 1e3) if t.any() else None,
           "crb_mae_trusted_mm": float(crb.mean() * 1e3) if len(crb) else None,
           "direction_median_deg": float(np.degrees(np.median(ang[t]))) if t.any() else None,
           "force_error_mean": float(force.mean()) if len(force) else None,
           "force_error_p95": float(np.percentile(force, 95)) if len(force) else None,
           "fix_ms_median": float(np.median(ts) * 1e3),
           "fix_ms_p99": float(np.percentile(ts, 99) * 1e3)}
    if cond in FAULTS:
        out["faulty_named"] = float(named.mean())
        out["exclusions_naming_another"] = int(np.sum(excluded_any & ~named))
        out["trusted_with_the_fault_kept"] = int(np.sum(t & ~named))
    return out


def run(out_dir=DEFAULT_OUT, n: int = 300, seed: int = 0, conditions=CONDITIONS, modes=MODES,
        noise_t: float = 0.1e-3) -> dict:
    """The study (module docstring); returns its numbers (also written as JSON)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sim, model, cal, cores = _device(seed, noise_t)
    est = ModelEstimator(model, EstimatorSettings(noise_t=noise_t), calibration=cal)
    truth = _frames(sim, cores, n, np.random.default_rng(seed + 1))
    rows = []
    for mode in modes:
        for j, cond in enumerate(conditions):
            rows.append(run_condition(est, sim, truth, cond, mode, seed + 10 + j))
            print(_line(rows[-1]), flush=True)
    res = {"n_per_condition": n, "seed": seed, "noise_t": noise_t,
           "settings": dataclasses.asdict(est.settings), "prior_sd": list(PRIOR_SD),
           "rows": rows, "relative": _relative(rows), "load_average": load_average()}
    (out / "pose_integrity.txt").write_text(_table(res) + "\n")
    return finish(out / "pose_integrity.json", res, lambda r: print(_table(r)))


def _relative(rows) -> dict:
    """Per mode: each condition's availability over the fault-free one ('tilt'), and the
    trusted MAE's ratio to it (ambient) and to the Cramer-Rao bound."""
    out = {}
    for r in rows:
        base = next((b for b in rows if b["mode"] == r["mode"] and b["condition"] == "tilt"),
                    None)
        key = f"{r['condition']} ({r['mode']})"
        out[key] = {
            "availability_over_fault_free": (r["availability"] / base["availability"]
                                             if base and base["availability"] else None),
            "mae_over_crb": (r["mae_trusted_mm"] / r["crb_mae_trusted_mm"]
                             if r["mae_trusted_mm"] and r["crb_mae_trusted_mm"] else None),
            "mae_over_fault_free": (r["mae_trusted_mm"] / base["mae_trusted_mm"]
                                    if base and r["mae_trusted_mm"] and base["mae_trusted_mm"]
                                    else None)}
    return out


def _fmt(x, f="{:.3f}"):
    return "-" if x is None else f.format(x)


def _line(r: dict) -> str:
    return (f"{r['condition']:8s} {r['mode']:5s} n {r['n']:6d} avail {r['availability']:.3f} "
            f"beyond PL {r['trusted_beyond_pl']:3d}/{r['trusted_beyond_orientation_pl']:3d} "
            f">5 mm {r['trusted_above_5mm']:3d} MAE {_fmt(r['mae_trusted_mm'])} "
            f"CRB {_fmt(r['crb_mae_trusted_mm'])} dir {_fmt(r['direction_median_deg'], '{:.2f}')}"
            f" force {_fmt(r['force_error_mean'])}/{_fmt(r['force_error_p95'])}"
            + (f" named {r['faulty_named']:.3f} wrong {r['exclusions_naming_another']} kept "
               f"{r['trusted_with_the_fault_kept']}" if "faulty_named" in r else ""))


def _table(res: dict) -> str:
    lines = [f"pose integrity: n = {res['n_per_condition']} per condition, noise "
             f"{res['noise_t'] * 1e3:.3g} mT, prior sd {res['prior_sd'][0] * 1e3:.2g} mm / "
             f"{math.degrees(res['prior_sd'][1]):.2g} deg (mode 'prior'), load "
             f"{_fmt(res['load_average'], '{:.1f}')}",
             "condition mode  availability, trusted beyond position/orientation PL, trusted > 5"
             " mm, trusted MAE mm, its 5-DOF Cramer-Rao bound (with the prior's information in "
             "mode 'prior') mm, direction median deg, force error mean/p95, faulty sensor "
             "named (share of fixes), exclusions of another sensor, trusted fixes that kept "
             "the faulty sensor (its fault too small to matter or to see)"]
    lines += [_line(r) for r in res["rows"]]
    lines.append("availability by height (20-35 / 35-50 / 50-70 mm):")
    for r in res["rows"]:
        lines.append(f"  {r['condition']:8s} {r['mode']:5s} " + " / ".join(
            f"{v:.3f}" for v in r["availability_by_height"].values()))
    lines.append("relative to the fault-free frames (availability ratio; MAE / CRB; MAE ratio):")
    for k, v in res["relative"].items():
        lines.append(f"  {k:18s} {_fmt(v['availability_over_fault_free'])} "
                     f"{_fmt(v['mae_over_crb'])} {_fmt(v['mae_over_fault_free'])}")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(DEFAULT_OUT), help="output folder")
    ap.add_argument("--n", type=int, default=300, help="fixes per condition and mode")
    ap.add_argument("--full", action="store_true", help="10 000 fixes per condition (the "
                    "acceptance run; ~an hour of CPU)")
    ap.add_argument("--seed", type=int, default=0, help="device (sensor errors) and noise seed")
    ap.add_argument("--conditions", default=",".join(CONDITIONS),
                    help="comma-separated subset of: " + ", ".join(CONDITIONS))
    ap.add_argument("--modes", default=",".join(MODES), help="subset of: " + ", ".join(MODES))
    ap.add_argument("--noise-mt", type=float, default=0.1, help="sensor noise, mT rms per axis")
    a = ap.parse_args(argv)
    conds = tuple(c.strip() for c in a.conditions.split(",") if c.strip())
    modes = tuple(c.strip() for c in a.modes.split(",") if c.strip())
    n = 10000 if a.full else a.n
    bad = [c for c in conds if c not in CONDITIONS] + [m for m in modes if m not in MODES]
    if bad or n < 1 or not 0 < a.noise_mt < 10:
        print(f"error: --conditions/--modes {bad}, --n {n}, --noise-mt {a.noise_mt}: conditions "
              f"from {CONDITIONS}, modes from {MODES}, n >= 1, noise in (0, 10) mT",
              file=sys.stderr)
        return 2
    return run_interruptible(run, a.out, n, a.seed, conds, modes, a.noise_mt * 1e-3)


if __name__ == "__main__":
    sys.exit(main())
