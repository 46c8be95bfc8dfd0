"""Is the thesis' sensor layout enough for two fingers, and if not, how many sensors where?

For the thesis device: the Cramer-Rao bound of the magnet positions (5 unknowns a magnet plus
the uniform background, TLV493D noise 0.1 mT rms per axis with the readout's rounding, the
cores the magnets magnetize) for one magnet and for two magnets 30-60 mm apart at 30-60 mm
above the coil tops (the issue's acceptance region), with the thesis' 18 sensors and with
layouts of 18, 27 and 36 sensors planned by :func:`designkit.sensing.design_plan.plan_design`
for two magnets, at each per-coil current the sensors must stay linear at. The acceptance asks
1.5 mm mean absolute error per magnet: the table gives, per layout, the worst and median rms
bound, the worst MAE bound and the share of magnets within 1.5 mm; and, for a magnet held
still, the frames a tracker would have to average to bring the worst single-frame MAE bound to
1.5 mm ((MAE / 1.5 mm)^2). Two checks of the bound itself come first: least-squares fits to
magpylib readings (their scatter against the bound) and the issue's quoted numbers.

    python studies/sensor_plan.py [OUT] [--counts 18,27,36] [--currents 6,2] [--quick]

Writes sensor_plan.txt, sensor_plan.json and one bound-map figure per current under OUT
(default out/sensor_plan).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from designkit import default_design
from designkit.constants import MU0
from designkit.sensing.crb import BoundSettings, pose_bound
from designkit.sensing.design_plan import PlanRequest, plan_design
from designkit.sensing.figure import bound_figure
from designkit.sensing.maps import ACCURACY_TARGET_M, Layout, layout_bounds, summary
from designkit.sensing.planner import PlanSettings
from designkit.sensing.region import RegionSettings
from designkit.sensing.response import MagnetShape, magnet_response, tangent_frame
from firmware_io.localization.magnet import cylinder_field

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "sensor_plan"
MAGNET_ONLY = BoundSettings(cores="none")
QUOTED = BoundSettings(dof="position", background="none", cores="none", lsb_t=0.0)


def fit_check(trials: int, seed: int = 0) -> list[dict]:
    """rms position and direction errors of least-squares fits (5 unknowns + background) to
    magpylib readings (0.1 mT noise, rounded to counts) against the bound, at three poses."""
    import magpylib as magpy

    d = default_design()
    shape = MagnetShape.of(d.magnet)
    sensors, frames = d.sensor_poses()
    out = []
    for centre in ([0.0, 0.0, 0.03], [0.025, 0.0, 0.035], [0.03, -0.02, 0.045]):
        c = np.array(centre)
        u = np.array([0.2, 0.1, -1.0]) / np.linalg.norm([0.2, 0.1, -1.0])
        e = tangent_frame(u)
        magnet = magpy.magnet.Cylinder(
            polarization=(0, 0, MU0 * shape.magnetization_a_per_m),
            dimension=(2 * shape.radius_m, shape.length_m), position=c,
            orientation=Rotation.from_matrix(e))
        truth = magnet.getB(sensors)
        rng = np.random.default_rng(seed)

        def model(x):
            uu = Rotation.from_rotvec(x[3] * e[:, 0] + x[4] * e[:, 1]).apply(u)
            return (cylinder_field(sensors, x[:3], uu * shape.moment_a_m2, shape.radius_m,
                                   shape.length_m) + x[5:]).ravel()

        err = np.empty((trials, 5))
        for t in range(trials):
            y = np.round((truth + rng.normal(0, 1e-4, truth.shape)) / 0.098e-3) * 0.098e-3
            r = least_squares(lambda x: (model(x) - y.ravel()) / 1e-4, np.r_[c, np.zeros(5)],
                              x_scale=np.r_[[1e-3] * 3, 0.05, 0.05, [1e-4] * 3], xtol=1e-12)
            err[t] = np.r_[r.x[:3] - c, r.x[3:5]]
        b = pose_bound(magnet_response(sensors, c[None], u, shape), [[0]], np.arange(18),
                       frames, MAGNET_ONLY)
        out.append({"centre_m": centre, "trials": trials,
                    "fit_rms_m": float(np.sqrt(np.mean(np.sum(err[:, :3] ** 2, 1)))),
                    "bound_rms_m": float(b.position_rms_m[0, 0]),
                    "fit_direction_rms_rad": float(np.sqrt(np.mean(np.sum(err[:, 3:] ** 2, 1)))),
                    "bound_direction_rms_rad": float(b.orientation_rms_rad[0, 0]),
                    "sampling_sd": 0.71 / math.sqrt(trials)})
    return out


def quoted_check() -> dict:
    """The issue's numbers (position only, no background, no cores, no rounding) and what the
    5-unknown bound the estimator faces gives at the same poses, mm."""
    d = default_design()
    sensors, frames = d.sensor_poses()
    pts = np.concatenate([[[0, 0, z], [-0.01, 0, z], [0.01, 0, z], [-0.015, 0, z],
                           [0.015, 0, z]] for z in (0.03, 0.045, 0.06)])
    resp = magnet_response(sensors, pts, d.magnet.direction, MagnetShape.of(d.magnet))
    out = {}
    for name, s in (("quoted model", QUOTED), ("pose, background, rounding", MAGNET_ONLY)):
        one = pose_bound(resp, [[5 * k] for k in range(3)], np.arange(18), frames, s)
        two = pose_bound(resp, [[5 * k + a, 5 * k + a + 1] for k in range(3) for a in (1, 3)],
                         np.arange(18), frames, s)
        out[name] = {"one_mm": (one.position_rms_m[:, 0] * 1e3).tolist(),
                     "two_20_30_mm": (two.position_rms_m.max(axis=1).reshape(3, 2)
                                      * 1e3).tolist()}
    out["issue"] = {"one_mm": [0.04, 0.50, 2.2], "two_20_30_mm": [[2.4, 1.4], [3.1, 2.1],
                                                                   [6.5, 4.5]]}
    return out


def run(out_dir=DEFAULT_OUT, counts=(18, 27, 36), currents=(6.0, 2.0), quick=False,
        trials=400) -> dict:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    d = default_design()
    lattice = 0.03 if quick else 0.015
    region = RegionSettings((0.03, 0.06), lattice, lattice, (0.03, 0.06))
    spacing = 0.025 if quick else 0.010
    res = {"quoted": quoted_check(), "fit_check": fit_check(20 if quick else trials),
           "region": {"heights_m": [0.03, 0.06], "lattice_m": lattice,
                      "separation_m": [0.03, 0.06], "site_spacing_m": spacing},
           "plans": []}
    for current in currents:
        blocks, layouts = None, {}
        for n in counts:
            t = time.perf_counter()
            o = plan_design(d, PlanRequest(n, 2, region, spacing, None, current,
                                           BoundSettings(), PlanSettings(count=n)))
            layouts[f"planned {n}"] = (o.layouts["planned"], o.boards_of["planned"])
            res["plans"].append(_plan_entry(o, n, current, time.perf_counter() - t))
            if blocks is None:
                blocks = {k: [(o.layouts["design"], o.bounds[k]["design"],
                               o.boards_of["design"])] for k in o.scenarios}
                scen = o.scenarios
            for k in scen:
                blocks[k].append((o.layouts["planned"], o.bounds[k]["planned"],
                                  o.boards_of["planned"]))
        bound_figure([(scen[k], blocks[k]) for k in scen], d,
                     out_dir / f"bound_maps_{current:g}A.png",
                     title=f"Position Cramer-Rao bound, thesis device, sensors linear at "
                           f"{current:g} A per coil")
    text = table_text(res)
    (out_dir / "sensor_plan.txt").write_text(text + "\n")
    (out_dir / "sensor_plan.json").write_text(json.dumps(res, indent=1) + "\n")
    print(text)
    return res


def _plan_entry(o, n, current, seconds) -> dict:
    entry = {"count": n, "max_current_a": current, "seconds": seconds,
             "planned_positions_m": o.layouts["planned"].positions_m.tolist(),
             "planned_boards": o.boards_of["planned"],
             "design_blinded": int(np.sum(o.headroom["design"].worst_signs_a < current))}
    for kind, per in o.summaries.items():
        for name, summ in per.items():
            row = summ["rows"][-1]
            entry[f"{kind} / {name}"] = {**row, "frames_to_average": max(
                1.0, (row["worst_mae_m"] / ACCURACY_TARGET_M) ** 2)}
            entry[f"{kind} / {name} / rows"] = summ["rows"]
    return entry


def table_text(res: dict) -> str:
    """The study's printed tables."""
    q = res["quoted"]
    lines = ["Checks of the bound", "issue's numbers, thesis layout (one magnet over the "
             "centre coil at 30 / 45 / 60 mm; two magnets 20 / 30 mm apart there), mm:"]
    for name in ("issue", "quoted model", "pose, background, rounding"):
        one = " / ".join(f"{x:.3g}" for x in q[name]["one_mm"])
        two = "; ".join(f"{a:.3g}-{b:.3g}" for b, a in q[name]["two_20_30_mm"])
        lines.append(f"  {name:28s} one {one}   two (30-20 mm apart) {two}")
    lines.append("least-squares fits to magpylib readings vs the bound (rms position mm, "
                 "direction deg; sampling sd of an rms):")
    for f in res["fit_check"]:
        lines.append(f"  at {np.round(np.array(f['centre_m']) * 1e3, 1).tolist()} mm, "
                     f"{f['trials']} fits: position {f['fit_rms_m'] * 1e3:.3f} vs "
                     f"{f['bound_rms_m'] * 1e3:.3f}, direction "
                     f"{math.degrees(f['fit_direction_rms_rad']):.2f} vs "
                     f"{math.degrees(f['bound_direction_rms_rad']):.2f} "
                     f"(ratio {f['fit_rms_m'] / f['bound_rms_m']:.3f}, sd "
                     f"{f['sampling_sd']:.3f})")
    lines += ["", "Layouts (two magnets 30-60 mm apart and one magnet, 30-60 mm up; bounds "
                  "rms worst / median, MAE worst, mm; share of magnets with MAE <= 1.5 mm; "
                  "frames to average for the worst MAE to reach 1.5 mm; the thesis sensors "
                  "blinded at the current)",
              "| current | layout | two magnets: rms worst / median | MAE worst | <= 1.5 mm "
              "| frames | one magnet: rms worst / median | <= 1.5 mm |",
              "|---|---|---|---|---|---|---|---|"]
    seen = set()
    for e in res["plans"]:
        for name in ("design", "planned"):
            if name == "design" and e["max_current_a"] in seen:
                continue
            two, one = e[f"two magnets / {name}"], e[f"one magnet / {name}"]
            label = (f"thesis 18 ({e['design_blinded']} blinded)" if name == "design"
                     else f"planned {e['count']}")
            lines.append(f"| {e['max_current_a']:g} A | {label} | "
                         f"{two['worst_rms_m'] * 1e3:.2f} / {two['median_rms_m'] * 1e3:.2f} | "
                         f"{two['worst_mae_m'] * 1e3:.2f} | {two['within_target']:.0%} | "
                         f"{two['frames_to_average']:.0f} | {one['worst_rms_m'] * 1e3:.2f} / "
                         f"{one['median_rms_m'] * 1e3:.2f} | {one['within_target']:.0%} |")
        seen.add(e["max_current_a"])
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", nargs="?", default=str(DEFAULT_OUT), help="output folder")
    p.add_argument("--counts", default="18,27,36", help="sensor counts to plan (default "
                                                          "18,27,36)")
    p.add_argument("--currents", default="6,2",
                   help="per-coil currents the sensors must stay linear at, A (default 6,2)")
    p.add_argument("--trials", type=int, default=400, help="fits per pose in the check")
    p.add_argument("--quick", action="store_true", help="a coarse, fast run (smoke test)")
    a = p.parse_args(argv)
    run(a.out, tuple(int(x) for x in a.counts.split(",")),
        tuple(float(x) for x in a.currents.split(",")), a.quick, a.trials)
    return 0


if __name__ == "__main__":
    sys.exit(main())
