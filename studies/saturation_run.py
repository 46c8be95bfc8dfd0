"""Question: on a device whose cores saturate (the thesis device with 1010-steel cores,
``[core] bh = "steel1010"``), how close is the force the runner renders at the current limit
to the exact saturating-core force -- with the map's saturation factor applied, and without it
(the same map with its factor table set to 1, what the runner did before it applied it)?

``run --simulate`` (designkit.sim: firmware_io's Runner on the simulated device whose cores
saturate at the true currents, designkit.sim.saturation) with the finger pressed into the
hemisphere above the centre coil (the thesis object, the constraint law at ``--lambda``), held
at ``--height`` with a small circling motion, so that the centre coil runs near its limit
while the object's force stays within reach. Per run: summary.json's ``saturation`` (the
runner's model force F(m) Am(p) S(I*) I* against the plant's exact F(m) A(p, I*) I* at the
finger's true position, over the steps whose largest command is >= 90 % of the limit; and the
same without S), the delivered force against the object's at those steps (the sensing and
the coils' lag included), and the force error causes. ``--poke`` adds the scripted poke at
``--poke-lambda``: all nine coils at the limit in the pattern of an out-of-reach vertical force
above the centre, where one factor per coil is the coarsest (docs/coupling.md).

    python studies/saturation_run.py [OUT_DIR] [--map FILE] [--lambda N/m] [--height M]
                                      [--duration S] [--poke] [--quick]
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit import fieldmap
from designkit.design import default_design
from designkit.model.array import CoilArray
from designkit.sim import RunSettings, run_simulation
from studies._common import finish, load_average, without_saturation

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "saturation_run"
"""Default output folder (git-ignored), whatever the working directory."""


def steel_design():
    """The thesis device with 1010-steel cores."""
    return default_design().replace(**{"name": "thesis-steel1010", "core.bh": "steel1010"})


def hold_path(path: Path, height_m: float, duration_s: float) -> Path:
    """A CSV trajectory above the centre coil: ``height_m`` +- 2 mm (period 0.5 s) and x +- 3 mm
    (period 1 s)."""
    t = np.linspace(0.0, duration_s, max(2, int(round(duration_s * 100)) + 1))
    z = height_m + 0.002 * np.sin(2 * np.pi * t / 0.5)
    x = 0.003 * np.sin(2 * np.pi * t / 1.0)
    path.write_text("t_s,x_m,y_m,z_m\n" + "".join(f"{a:.6f},{b:.6f},0.0,{c:.6f}\n"
                                                   for a, b, c in zip(t, x, z)))
    return path


def delivered(run_dir: Path, limit_a: float) -> dict:
    """The delivered force against the rendered one at the steps whose largest command is >=
    90 % of ``limit_a``: mean and RMS of Fz (the plant's at the true position - the runner's
    reference at its estimate), N, and the mean reference."""
    rows = list(csv.DictReader((run_dir / "run.csv").open()))
    col = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]
           if k not in ("state", "fault_excluded")}
    running = np.array([r["state"] == "running" for r in rows])
    cmd = np.stack([v for k, v in col.items() if k.startswith("cmd")], 1)
    near = running & (np.abs(cmd).max(axis=1) >= 0.9 * limit_a)
    if not near.any():
        return {"steps": 0}
    err = col["fz_n"][near] - col["fz_ref_n"][near]
    return {"steps": int(near.sum()), "fz_error_mean_n": float(np.mean(err)),
            "fz_error_rms_n": float(np.sqrt(np.mean(err ** 2))),
            "fz_reference_mean_n": float(np.mean(col["fz_ref_n"][near]))}


def one_run(design, map_path, out: Path, settings: RunSettings, array) -> dict:
    s = run_simulation(settings, design=design, map_path=map_path, out=out, progress=False,
                       array=array)
    limit = s["drive"]["current_limit_a"]
    causes = s.get("force_error_causes", {})
    return {"saturation": s.get("saturation", {}), "delivered_near_limit": delivered(out, limit),
            "max_command_a": s["max_command_a"], "running_fraction": s["running_fraction"],
            "force_error_rms_n": s["force_error_rms_n"],
            "object_force_rms_n": s["object_force_rms_n"],
            "causes_norm_rms_n": {k: v["norm_rms_n"] for k, v in causes.items()
                                  if isinstance(v, dict)}}


def run(out_dir=DEFAULT_OUT, *, map_path=None, lam: float = 60.0, height_m: float = 0.030,
        duration_s: float = 1.0, poke: bool = False, poke_lam: float = 40.0,
        quick: bool = False) -> dict:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    design = steel_design()
    array = CoilArray.from_design(design)
    if map_path is None:
        map_path = fieldmap.write(out_dir / "map.npz",
                                  fieldmap.build(design, array=array, progress=not quick))
    map_path = Path(map_path)
    unapplied = without_saturation(map_path, out_dir / "map_factor_1.npz")
    duration_s = min(duration_s, 0.3) if quick else duration_s
    path = hold_path(out_dir / "hold.csv", height_m, duration_s)
    res: dict = {"load_average_1min": load_average(), "design": design.name, "lambda_n_per_m": lam,
                 "height_m": height_m, "duration_s": duration_s}
    hold = RunSettings(obj="hemisphere", trajectory=str(path), lam_n_per_m=lam)
    for name, mp in (("with_factor", map_path), ("factor_1", unapplied)):
        res[f"hold_{name}"] = one_run(design, mp, out_dir / f"hold-{name}", hold, array)
    if poke and not quick:
        pk = RunSettings(obj="hemisphere", trajectory="poke", lam_n_per_m=poke_lam)
        res["poke_lambda_n_per_m"] = poke_lam
        for name, mp in (("with_factor", map_path), ("factor_1", unapplied)):
            res[f"poke_{name}"] = one_run(design, mp, out_dir / f"poke-{name}", pk, array)
    return finish(out_dir / "saturation_run.json", res, _print)


def _print(res: dict) -> None:
    print(f"saturating device ({res['design']}), load average {res['load_average_1min']}")
    for key in [k for k, v in res.items() if isinstance(v, dict) and "saturation" in v]:
        r = res[key]
        sat, dl = r["saturation"], r["delivered_near_limit"]
        print(f"\n{key}: max command {r['max_command_a']:.2f} A, steps near the limit "
              f"{sat.get('steps', 0)} (largest |I*| >= {sat.get('near_limit_a', 0):.2f} A)")
        for k in ("with_factor", "without_factor"):
            if k in sat:
                print(f"  runner's model vs exact saturating cores, {k:15s}: RMS "
                      f"{sat[k]['rel_rms'] * 100:.2f} %, max {sat[k]['rel_max'] * 100:.2f} %")
        if "commands_vs_rendered_mean_rel" in sat:
            print(f"  the commands through that model against the rendered force, "
                  f"{sat['below_bound_steps']} steps below the bounds: mean "
                  f"{sat['commands_vs_rendered_mean_rel'] * 100:+.2f} %")
        if dl.get("steps"):
            print(f"  delivered Fz - rendered Fz at those steps: mean "
                  f"{dl['fz_error_mean_n'] * 1e3:+.0f} mN, RMS {dl['fz_error_rms_n'] * 1e3:.0f} "
                  f"mN of {dl['fz_reference_mean_n'] * 1e3:.0f} mN")
        print(f"  force error RMS {r['force_error_rms_n'] * 1e3:.0f} mN of "
              f"{r['object_force_rms_n'] * 1e3:.0f} mN; causes (RMS |.|, mN): " + ", ".join(
                  f"{k} {v * 1e3:.0f}" for k, v in r["causes_norm_rms_n"].items()))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--map", default=None, help="the steel design's map (default: build one)")
    ap.add_argument("--lambda", dest="lam", type=float, default=60.0,
                    help="force constant of the hold, N/m (default 60: ~3 N)")
    ap.add_argument("--height", type=float, default=0.030, help="hold height, m (default 0.03)")
    ap.add_argument("--duration", type=float, default=1.0, help="simulated seconds per run")
    ap.add_argument("--poke", action="store_true", help="also the scripted poke at the limit")
    ap.add_argument("--poke-lambda", type=float, default=40.0, help="the poke's N/m")
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    run(a.out, map_path=a.map, lam=a.lam, height_m=a.height, duration_s=a.duration,
        poke=a.poke, poke_lam=a.poke_lambda, quick=a.quick)
