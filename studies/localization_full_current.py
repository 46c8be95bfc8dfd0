"""Question: at full rendering currents (random +-6 A per coil, time-varying), how close does the
calibrated model-based fit come to the noise-limited error, and what limits it?

Simulation as in studies/localization.py (designkit.sim.readings: exact 10 x 10 mm cylinder,
coils' field at the sensors' true, displaced poses, the cores' induced field ('rod' model), the
TLV493D chain with the device's sensor errors, --noise-mt rms noise); positions in the lower half
of the thesis cube (|x|, |y| <= 25 mm, 20-45 mm). The noise limit: the same readings fitted
with the exact forward model (true poses, gains, offsets; localization._noise_limited). The
estimator: ModelEstimator ('model') with the exact magnet and the start-up calibration (1000 coil-only
frames), its forward model with and without the coils' field gradient at the sensors (the v2
map carries it; without it the calibration cannot recover the sensors' position errors).
Cold fixes. Prints one table row per variant (MAE, ratio to the noise limit, ok share) and
writes them to OUT_DIR/localization_full_current.json.

    python studies/localization_full_current.py [OUT_DIR] [--n 200] [--noise-mt 0.1] [--seed 0]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit.design import default_design
from designkit.sim.readings import SensorSimulator, case_currents, forward_model, random_positions
from firmware_io.localization import POSITION_ONLY, ModelEstimator, SensorModel
from studies._common import finish
from studies.localization import _calibrate, _noise_limited, with_coil_gradient

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "localization_full_current"


def _induced_jacobian(model, pos, h=0.5e-3):
    """(k, 2, n, 3, 3) T/m: the model's induced field's Jacobian at each position (central
    differences), for the noise-limited reference's linearization."""
    out = np.zeros((len(pos), 2, model.n_sensors // 2, 3, 3))
    for k, p in enumerate(pos):
        for j in range(3):
            dp = np.eye(3)[j] * h
            out[k, ..., j] = ((model.induced_field(p + dp) - model.induced_field(p - dp))
                              / (2 * h)).reshape(2, -1, 3)
    return out


def run(n: int = 200, seed: int = 0, noise_t: float = 0.1e-3, out_dir=DEFAULT_OUT) -> dict:
    """The table (module docs); writes ``localization_full_current.json`` under ``out_dir``."""
    design = default_design()
    sim = SensorSimulator(design, errors="default", seed=seed, induced="rod", noise_t=noise_t)
    size = (design.magnet.radius_m, design.magnet.length_m)
    plain = dataclasses.replace(SensorModel.from_operator(**forward_model(sim)),
                                magnet_size_m=size)
    rng = np.random.default_rng(seed + 3)
    pos = random_positions(n, rng, z_range_m=(0.020, 0.045))
    mag, ind = sim.magnet_part(pos), sim.induced_part(pos)
    jac = _induced_jacobian(plain, pos)
    cur = case_currents("rendering", rng.uniform(0, 20, n), sim.array.n_coils, seed=seed + 7)
    rd = sim.read(pos, cur, parts=(mag, ind), rng=rng)
    limit = np.array([np.linalg.norm(_noise_limited(sim, rd, k, pos[k], cur[k], ind[k], jac[k])
                                     - pos[k]) for k in range(n)])
    rows = [("noise limit", limit.mean(), 1.0, 1.0)]
    for label, model in (("model-cal, no coil gradient", plain),
                         ("model-cal, coil gradient (as from_map)",
                          with_coil_gradient(sim, plain))):
        cal, _ = _calibrate(sim, model, seed + 1000, 1000)
        loc = ModelEstimator(model, dataclasses.replace(POSITION_ONLY, noise_t=noise_t),
                             calibration=cal)
        err, ok = np.empty(n), np.empty(n, bool)
        for k in range(n):
            loc.reset()
            e = loc.estimate(np.r_[rd.top_t[k], rd.bottom_t[k]], cur[k])
            err[k], ok[k] = np.linalg.norm(e.position_m - pos[k]), e.ok
        rows.append((label, err.mean(), err.mean() / limit.mean(), ok.mean()))
    res = {"n": n, "seed": seed, "noise_t": noise_t,
           "saturated_fraction": float(rd.saturated.mean()),
           "rows": [{"estimator": label, "mae_m": float(mae), "over_limit": float(ratio),
                     "ok_fraction": float(ok)} for label, mae, ratio, ok in rows]}
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    return finish(Path(out_dir) / "localization_full_current.json", res, _print)


def _print(res: dict) -> None:
    print(f"+-6 A random currents, 20-45 mm, n = {res['n']}, noise {res['noise_t'] * 1e3:.3g} mT, "
          f"saturated sensors {res['saturated_fraction']:.3f}")
    print(f"{'estimator':40s} {'MAE mm':>7s} {'/ limit':>8s} {'ok':>6s}")
    for r in res["rows"]:
        print(f"{r['estimator']:40s} {r['mae_m'] * 1e3:7.3f} {r['over_limit']:8.2f} "
              f"{r['ok_fraction']:6.3f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(DEFAULT_OUT), help="output folder")
    ap.add_argument("--n", type=int, default=200, help="positions (lower half of the cube)")
    ap.add_argument("--seed", type=int, default=0, help="device (sensor errors) and noise seed")
    ap.add_argument("--noise-mt", type=float, default=0.1,
                    help="sensor noise, mT rms per axis (simulated and assumed)")
    a = ap.parse_args(argv)
    if a.n < 1 or not 0 < a.noise_mt < 10:
        print(f"error: --n {a.n} / --noise-mt {a.noise_mt}: n >= 1, noise in (0, 10) mT")
        return 2
    run(a.n, a.seed, a.noise_mt * 1e-3, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
