"""Question: how well do the estimators of firmware_io.localization locate the finger magnet from
the two simulated Hall arrays, against the thesis (0.80 / 1.26 / 0.91 / 0.86 mm MAE in its field
cases 1-4) and against the noise limit -- and how much does the cores' magnetization by the magnet
spoil the thesis' subtraction?

Simulation (designkit.localize): exact 10 x 10 mm cylinder magnet (moment from the design, +z),
coupled coil field at the currents, field of the cores magnetized by the magnet (coupled solve),
TLV493D chain (0.1 mT rms noise, 0.098 mT LSB, flagged beyond +-130 mT), per-sensor errors
(offset 0.01 mT, gain 1 %, mounting 0.5 mm / 1 degree; fixed draw, seed).

Positions: ``n`` uniform random in the thesis' 50 mm cube (|x|, |y| <= 25 mm, 20-70 mm above the
coil tops) and ``n`` in the rendering workspace (|x|, |y| <= 75 mm, 20-80 mm: the magnet cannot
go below the upper sensor board at 14 mm). Field cases: the thesis' four (off, static 0.65 A,
sinusoidal 0.65 A, time-varying 1 A peak) and full rendering currents (6 A peak, time-varying);
each frame takes the currents at a random time.

Methods: 'learned' (thesis: subtraction + nearest-sensor MLP), 'dipole-naive' (subtraction +
dipole fit ignoring the cores), 'dipole' (subtraction + fit with the map's core term), 'model'
(model-based cancellation), 'model-cal' ('model' after the per-sensor affine calibration from
coil-only frames, firmware_io.localization.calibrate), and 'noise-limit': the same readings
fitted with the exact forward model (true sensor poses, gains and offsets; exact cylinder field;
induced field linearized about the truth), which only noise and quantization limit. Every fit
starts cold (global search), as when lost. Kalman: one smooth finger trajectory per case
(100 Hz), error of 'model' alone and filtered. Benchmark: the per-estimate cost of the warm-started
subtraction + dipole fit (median, p99) on this machine (shared, loaded: relative numbers).

Writes ``localization.json``, ``localization_table.txt``, ``localization.png`` (errors) and
``subtraction_error.png`` under ``out_dir``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit.design import default_design
from designkit.localize import (THESIS_MAE_MM, SensorSimulator, case_currents, forward_model,
                                magnet_field, random_positions, train_learned_inverse)
from firmware_io.localization import (ConstantVelocityKalman, LearnedInverse, Localizer,
                                      SensorModel, calibrate)

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "localization"
"""Default output folder (git-ignored), whatever the working directory."""


CASES = ("off", "static", "sinusoidal", "time-varying", "rendering")
METHODS = ("learned", "dipole-naive", "dipole", "model", "model-cal", "noise-limit")


def _progress(it, desc):
    from tqdm import tqdm

    return tqdm(it, desc=desc, mininterval=2.0, file=sys.stderr)


def _noise_limited(sim, readings, k, p_true, currents, ind_true, ind_jac):
    """Fit with the exact forward model to frame k; returns the position (3,)."""
    from scipy.optimize import least_squares

    e = sim.errors
    meas = np.stack([readings.top_t[k], readings.bottom_t[k]])
    use = np.all(np.isfinite(meas), axis=-1)
    mg = sim.design.magnet
    pts = sim.true_m.reshape(-1, 3)
    coil = np.einsum("asdc,c->asd", sim.coil_field_t_per_a, currents)

    def model(p):
        b = magnet_field(pts, p, sim.moment_a_m2, mg.radius_m, mg.length_m).reshape(2, sim.n, 3)
        b = b + coil + ind_true + np.einsum("asdj,j->asd", ind_jac, p - p_true)
        return e.gains * np.einsum("asji,asj->asi", e.rotations, b) + e.offsets_t

    def res(p):
        return ((meas - model(p))[use] / sim.noise_t).ravel()

    return least_squares(res, p_true, x_scale=1e-3, method="lm").x


def run(out_dir=DEFAULT_OUT, n: int = 1000, seed: int = 0, *, map_path=None,
        quick: bool = False, n_workspace: int | None = None) -> dict:
    """Run the study; returns a dict of numbers (also written as JSON)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    design = default_design()
    rng = np.random.default_rng(seed)
    t_all = time.perf_counter()
    sim = SensorSimulator(design, errors="default", seed=seed,
                          induced="rod" if quick else "coupled")
    # the estimators' knowledge: the v2 map if given, else the same numbers from designkit
    if map_path is not None and Path(map_path).is_file():
        mg = design.magnet
        base = Localizer.from_map(map_path, "dipole",
                                  octupole_m2=(mg.length_m / 2) ** 2 - 0.75 * mg.radius_m**2)
        model = base.model
        source = f"map {map_path}"
    else:
        model = SensorModel.from_operator(**forward_model(sim))
        source = "designkit.localize.forward_model (rod induced model)"
    naive_model = SensorModel(model.sensor_positions_m, model.coil_field_t_per_a,
                              model.moment_a_m2, model.design_sha256, model.octupole_m2, None,
                              model.box_lower_m, model.box_upper_m)
    t0 = time.perf_counter()
    learned = train_learned_inverse(model, n_samples=800 if quick else 4000, hidden=16,
                                    max_iterations=100 if quick else 600, seed=seed)
    learned.save(out / "learned_inverse.npz")
    learned = LearnedInverse.load(out / "learned_inverse.npz")
    t_train = time.perf_counter() - t0
    # calibration: coil-only frames (no magnet), random currents <= 2 A
    cal_i = rng.uniform(-2, 2, (60, model.n_coils))
    zero = np.zeros((len(cal_i), 2, sim.n, 3))
    cal = sim.read(np.zeros((len(cal_i), 3)) + [0, 0, 1.0], cal_i, parts=(zero, zero))
    calibration = calibrate(cal.top_t, cal.bottom_t, cal_i, model)

    locs = {"learned": Localizer(model, "learned", learned=learned),
            "dipole-naive": Localizer(naive_model, "dipole"),
            "dipole": Localizer(model, "dipole"),
            "model": Localizer(model, "model"),
            "model-cal": Localizer(model, "model", calibration=calibration,
                                   relative_error=0.005)}
    regions = {"cube": dict(z_range_m=(0.020, 0.070), half_width_m=0.025),
               "workspace": dict(z_range_m=(0.020, 0.080), half_width_m=0.075)}
    counts = {"cube": n, "workspace": n if n_workspace is None else n_workspace}
    results: dict = {"n": counts, "model_source": source, "train_s": t_train, "rows": []}
    errors_store = {}
    for region, box in regions.items():
        n = counts[region]
        pos = random_positions(n, rng, **box)
        mag = sim.magnet_part(pos)
        ind = np.empty_like(mag)
        for k in _progress(range(n), f"induced field ({region})"):
            ind[k] = sim.induced_part(pos[k:k + 1])[0]
        # Jacobian of the induced term (for the noise-limited reference), from the model
        h = 0.5e-3
        ind_jac = np.zeros((n, 2, sim.n, 3, 3))
        if model.induced is not None:
            for k in range(n):
                for j in range(3):
                    dp = np.eye(3)[j] * h
                    ind_jac[k, ..., j] = (model.induced(pos[k] + dp)
                                          - model.induced(pos[k] - dp)) / (2 * h)
        if region == "cube":
            # subtraction error from the cores' magnetization by the magnet, per position
            sub = ind[:, 0] - np.einsum("sij,ksj->ksi", locs["dipole"]._mirror, ind[:, 1])
            results["subtraction_core_error_t"] = {
                "max_over_sensors_median": float(np.median(np.abs(sub).max(axis=(1, 2)))),
                "max_over_sensors_max": float(np.abs(sub).max())}
            # what that error does to the position: noise-free readings (coils off, ideal chain)
            clean = mag + ind
            clean[np.any(np.abs(clean) > 0.130, axis=-1)] = np.nan  # saturated, as read
            e_naive, e_cores = np.empty(n), np.empty(n)
            for k in range(n):
                for loc, out_e in ((locs["dipole-naive"], e_naive), (locs["dipole"], e_cores)):
                    loc.reset()
                    est = loc.locate(clean[k, 0], clean[k, 1])
                    out_e[k] = np.linalg.norm(est.position_m - pos[k])
            results["subtraction_core_error_t"]["position_error_naive_mae_mm"] = float(
                e_naive.mean() * 1e3)
            results["subtraction_core_error_t"]["position_error_with_cores_mae_mm"] = float(
                e_cores.mean() * 1e3)
            errors_store["sub"] = (pos, np.linalg.norm(sub, axis=-1).max(axis=1), e_naive, e_cores)
        for case in CASES:
            cur = case_currents(case, rng.uniform(0, 20, n), model.n_coils, seed=seed + 7)
            rd = sim.read(pos, cur, parts=(mag, ind))
            errs = {m: np.empty(n) for m in METHODS}
            oks = {m: np.empty(n, bool) for m in METHODS}
            for k in _progress(range(n), f"{region} {case}"):
                for name, loc in locs.items():
                    loc.reset()
                    e = loc.locate(rd.top_t[k], rd.bottom_t[k], cur[k])
                    errs[name][k] = np.linalg.norm(e.position_m - pos[k])
                    oks[name][k] = e.ok
                p = _noise_limited(sim, rd, k, pos[k], cur[k], ind[k], ind_jac[k])
                errs["noise-limit"][k] = np.linalg.norm(p - pos[k])
                oks["noise-limit"][k] = True
            low = pos[:, 2] <= 0.045
            for m in METHODS:
                e_mm = errs[m] * 1e3
                results["rows"].append({
                    "region": region, "case": case, "method": m,
                    "mae_mm": float(e_mm.mean()), "p95_mm": float(np.percentile(e_mm, 95)),
                    "median_mm": float(np.median(e_mm)),
                    "mae_lower_half_ok_mm": float(e_mm[low & oks[m]].mean())
                    if (low & oks[m]).any() else float("nan"),
                    "mae_lower_half_mm": float(e_mm[low].mean()),
                    "mae_upper_half_mm": float(e_mm[~low].mean()),
                    "ok_fraction": float(oks[m].mean()),
                    "mae_ok_mm": float(e_mm[oks[m]].mean()) if oks[m].any() else float("nan"),
                    "saturated_sensor_fraction": float(rd.saturated.mean()),
                    "thesis_mae_mm": THESIS_MAE_MM.get(case)})
            errors_store[(region, case)] = (pos, errs)
    results["kalman"] = _kalman(sim, model, rng, quick)
    results["benchmark"] = _benchmark(sim, model, locs, rng, quick)
    results["total_s"] = time.perf_counter() - t_all
    _write(out, results, errors_store)
    return results


def _trajectory(n_frames, rate_hz, rng):
    t = np.arange(n_frames) / rate_hz
    f = rng.uniform(0.1, 0.6, (3, 3))
    ph = rng.uniform(0, 2 * np.pi, (3, 3))
    amp = np.array([0.012, 0.012, 0.012])
    wave = np.sin(2 * np.pi * f[None] * t[:, None, None] + ph[None]).sum(-1) / 3
    return t, np.array([0.0, 0.0, 0.045]) + amp * wave


def _kalman(sim, model, rng, quick):
    rate = 100.0
    t, path = _trajectory(60 if quick else 400, rate, rng)
    mag = sim.magnet_part(path)
    ind = np.stack([sim.induced_part(p[None])[0] for p in path])
    out = {}
    for case in ("time-varying", "rendering"):
        cur = case_currents(case, t, model.n_coils, seed=3)
        rd = sim.read(path, cur, parts=(mag, ind))
        raw = Localizer(model, "model")
        kf = Localizer(model, "kalman", kalman=ConstantVelocityKalman(2.0, 1.0e-3))
        e_raw, e_kf = [], []
        for k in range(len(t)):
            a = raw.locate(rd.top_t[k], rd.bottom_t[k], cur[k])
            b = kf.locate(rd.top_t[k], rd.bottom_t[k], cur[k], time_s=t[k])
            e_raw.append(np.linalg.norm(a.position_m - path[k]))
            e_kf.append(np.linalg.norm(b.position_m - path[k]))
        skip = 20  # filter settling
        out[case] = {"model_mae_mm": float(np.mean(e_raw[skip:]) * 1e3),
                     "kalman_mae_mm": float(np.mean(e_kf[skip:]) * 1e3)}
    return out


def _benchmark(sim, model, locs, rng, quick):
    """Warm-started fits along a trajectory; per-call times."""
    t, path = _trajectory(60 if quick else 300, 100.0, rng)
    mag = sim.magnet_part(path)
    ind = np.stack([sim.induced_part(p[None])[0] for p in path])
    cur = np.zeros((len(t), model.n_coils))
    rd = sim.read(path, cur, parts=(mag, ind))
    out = {}
    for name in ("dipole-naive", "dipole", "model"):
        loc = locs[name]
        loc.reset()
        loc.locate(rd.top_t[0], rd.bottom_t[0], cur[0])
        dt = []
        for k in range(1, len(t)):
            t0 = time.perf_counter_ns()
            loc.locate(rd.top_t[k], rd.bottom_t[k], cur[k])
            dt.append((time.perf_counter_ns() - t0) * 1e-3)
        out[name] = {"median_us": float(np.median(dt)), "p99_us": float(np.percentile(dt, 99))}
    # reference in the same process: one numpy 18 x 3 dipole field evaluation
    from firmware_io.localization import multipole_field

    pts = model.sensor_positions_m.reshape(-1, 3)
    dt = []
    for _ in range(300):
        t0 = time.perf_counter_ns()
        multipole_field(pts, path[0], model.moment_a_m2, model.octupole_m2, jacobian=True)
        dt.append((time.perf_counter_ns() - t0) * 1e-3)
    out["reference_one_field_and_jacobian_us"] = float(np.median(dt))
    return out


def _write(out: Path, res: dict, store: dict) -> None:
    lines = [f"localization study: positions per region {res['n']}, model: {res['model_source']}",
             f"{'region':10s} {'case':13s} " + " ".join(f"{m:>13s}" for m in METHODS)
             + "   thesis   (MAE mm / p95 mm; lower half MAE)"]
    rows = res["rows"]
    for region in ("cube", "workspace"):
        for case in CASES:
            rs = {r["method"]: r for r in rows if r["region"] == region and r["case"] == case}
            if not rs:
                continue
            th = rs[METHODS[0]]["thesis_mae_mm"]
            lines.append(f"{region:10s} {case:13s} " + " ".join(
                f"{rs[m]['mae_mm']:6.2f}/{rs[m]['p95_mm']:6.2f}" for m in METHODS)
                + (f"   {th:.2f}" if th else "      -"))
            lines.append(f"{'':10s} {'  lower half':13s} " + " ".join(
                f"{rs[m]['mae_lower_half_mm']:13.2f}" for m in METHODS))
            lines.append(f"{'':10s} {'  ok fraction':13s} " + " ".join(
                f"{rs[m]['ok_fraction']:13.3f}" for m in METHODS))
            lines.append(f"{'':10s} {'  MAE if ok':13s} " + " ".join(
                f"{rs[m]['mae_ok_mm']:13.2f}" for m in METHODS))
            lines.append(f"{'':10s} {'  median':13s} " + " ".join(
                f"{rs[m]['median_mm']:13.2f}" for m in METHODS))
    lines.append(f"Kalman: {json.dumps(res['kalman'])}")
    lines.append(f"benchmark (loaded machine): {json.dumps(res['benchmark'])}")
    lines.append(f"subtraction error from the magnet-magnetized cores: "
                 f"{json.dumps(res['subtraction_core_error_t'])}")
    text = "\n".join(lines)
    print(text)
    (out / "localization_table.txt").write_text(text + "\n")
    (out / "localization.json").write_text(json.dumps(res, indent=1, default=float))
    _plots(out, res, store)


def _plots(out: Path, res: dict, store: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    colors = dict(zip(METHODS, ["tab:gray", "tab:orange", "tab:red", "tab:blue", "tab:green",
                                "black"]))
    for ax, region in zip(axes, ("cube", "workspace")):
        x = np.arange(len(CASES))
        w = 0.8 / len(METHODS)
        for j, m in enumerate(METHODS):
            vals = [next(r["mae_mm"] for r in res["rows"] if r["region"] == region
                         and r["case"] == c and r["method"] == m) for c in CASES]
            ax.bar(x + (j - len(METHODS) / 2 + 0.5) * w, vals, w, label=m, color=colors[m])
        th = [THESIS_MAE_MM.get(c, np.nan) for c in CASES]
        ax.plot(x, th, "k*", ms=12, label="thesis (measured)")
        ax.set_xticks(x, CASES)
        ax.set_yscale("log")
        ax.set_ylabel("mean absolute error (mm)")
        ax.set_title(f"{region}: {res['n'][region]} random positions per case")
        ax.grid(axis="y", alpha=0.3, which="both")
    axes[0].legend(fontsize=8, loc="upper left")
    fig.tight_layout()
    fig.savefig(out / "localization.png", dpi=90)
    plt.close(fig)

    pos, sub, e_naive, e_cores = store["sub"]
    fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
    ax = axes[0]
    sc = ax.scatter(pos[:, 0] * 1e3, pos[:, 2] * 1e3, c=sub * 1e3, s=12, cmap="viridis",
                    norm=matplotlib.colors.LogNorm(vmin=0.1, vmax=10))
    cb = fig.colorbar(sc, ax=ax, ticks=[0.1, 0.2, 0.5, 1, 2, 5, 10])
    cb.ax.set_yticklabels(["0.1", "0.2", "0.5", "1", "2", "5", "10"])
    cb.set_label("largest |upper - mirrored lower| from the cores (mT)")
    ax.set_xlabel("magnet x (mm)")
    ax.set_ylabel("magnet height above the coil tops (mm)")
    ax.set_title("Field the subtraction leaves from the magnet-magnetized cores\n"
                 "(sensor noise after subtraction: 0.14 mT rms per axis)", fontsize=10)
    ax = axes[1]
    ax.semilogy(pos[:, 2] * 1e3, np.maximum(e_naive * 1e3, 1e-4), ".", color="tab:orange",
                ms=4, label="subtraction + dipole fit ignoring the cores")
    ax.semilogy(pos[:, 2] * 1e3, np.maximum(e_cores * 1e3, 1e-4), ".", color="tab:red", ms=4,
                label="subtraction + fit with the map's core term")
    ax.set_xlabel("magnet height above the coil tops (mm)")
    ax.set_ylabel("position error, noise-free readings (mm)")
    ax.set_title("What it costs in position (coils off, no noise, sensors > 130 mT excluded)",
                 fontsize=10)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(out / "subtraction_error.png", dpi=90)
    plt.close(fig)


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--n", type=int, default=1000, help="positions in the 50 mm cube")
    ap.add_argument("--n-workspace", type=int, default=None,
                    help="positions in the rendering workspace (default: --n)")
    ap.add_argument("--map", default=None, help="v2 map file for the estimators")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    run(a.out_dir, a.n, map_path=a.map, quick=a.quick, n_workspace=a.n_workspace)
