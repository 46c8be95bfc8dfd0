"""Question: how well does the runner render the thesis' four objects on the simulated device,
where does the force error come from, and does every fault end in the safe state in time?

For the flat surface (100 mm square at 50 mm), the hemisphere, the half-cylinder and the wedge,
a finger slides across the object 4 mm below its surface, there and back in 4 s (thesis
Fig. 4.5), with the thesis' constraint law (lambda = the design's 6 N/m) rendered as a 3-D force
and as Fz alone (the thesis' eq. 4.6). designkit.sim closes firmware_io's runner around the
simulated device (exact coupled array physics, R-L coils at 30 V, register-level sensors with
noise and mounting errors, calibrated at start-up with the coils alone). The rendered-force
error (true force on the magnet vs the object's force at the true position) is split into
localization, map interpolation, allocation residual and current lag
(designkit.sim.force_error_causes). The thesis reports none of these; its only number is a
participant's 14 mm largest deviation from the flat surface.

Faults: one more run over the hemisphere with every fault type injected once
(``--faults default``); from its run.csv, for each fault: the time from injection and from
detection (the runner's log line) to the first step in the safe state, and over every row of
every run the largest commanded current and total against the limits.

    python studies/render_runner.py [OUT_DIR] [--map FILE] [--duration S] [--quick]
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit.sim import RunSettings, run_simulation
from studies._common import design_and_map, finish, load_average

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "render_runner"
"""Default output folder (git-ignored), whatever the working directory."""


OBJECTS = ("plane", "hemisphere", "half-cylinder", "wedge")


def check_run_csv(path, summary: dict) -> dict:
    """From run.csv: per scheduled fault the first safe step after injection and after its
    detection (s and control periods); the largest command |I| and sum |I| of any row (A)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    t = np.array([float(r["t_s"]) for r in rows])
    state = np.array([r["state"] for r in rows])
    cmd = np.array([[float(r[k]) for k in r if k.startswith("cmd")] for r in rows])
    period = summary["period_s"]
    drive = summary["drive"]
    out = {"max_command_a": float(np.abs(cmd).max()),
           "max_total_a": float(np.abs(cmd).sum(axis=1).max()),
           "current_limit_a": drive["current_limit_a"], "total_limit_a": drive["total_current_a"],
           "faults": []}
    # run.csv holds 9 significant digits
    out["within_limits"] = bool(out["max_command_a"] <= drive["current_limit_a"] * (1 + 1e-8)
                                and out["max_total_a"] <= drive["total_current_a"] * (1 + 1e-8))
    log = summary.get("fault_log", [])
    for f in summary.get("faults", []):
        te = f["injected_s"]
        after = np.flatnonzero((t >= te - 1e-12) & (state != "running"))
        first = int(after[0]) if len(after) else None
        seen = [e for e in log if e["t_s"] >= te - 1e-12]
        detect = seen[0]["t_s"] if seen else None
        safe_at_detect = None
        if detect is not None:
            k = int(np.argmin(np.abs(t - detect)))
            safe_at_detect = round(float((t[np.flatnonzero((t >= t[k]) & (state != "running"))[0]]
                                          - detect) / period), 6)
        out["faults"].append({
            "fault": f["fault"], "injected_s": te,
            "state": None if first is None else str(state[first]),
            "periods_from_injection": None if first is None else round(float((t[first] - te)
                                                                             / period), 6),
            "detected_s": detect, "periods_from_detection": safe_at_detect})
    return out


def run(out_dir=DEFAULT_OUT, *, map_path=None, duration_s: float = 4.0,
        quick: bool = False, objects=OBJECTS, rows=("force", "fz")) -> dict:
    out_dir, design, array, map_path = design_and_map(out_dir, map_path, progress=not quick)
    if quick:
        objects, rows, duration_s = objects[:1], rows[:1], min(duration_s, 0.5)
    res: dict = {"load_average_1min": load_average(), "duration_s": duration_s, "runs": {}}
    limits = []
    for obj in objects:
        for r in rows:
            run_dir = out_dir / f"{obj}-{r}"
            s = run_simulation(RunSettings(obj=obj, duration_s=duration_s, rows=r),
                               design=design, map_path=map_path, out=run_dir, progress=False,
                               array=array)
            v = {k: s[k] for k in (
                "force_error_rms_n", "force_error_p95_n", "object_force_rms_n", "force_lag_s",
                "localization_mae_m", "localization_p95_m", "loop_p50_s", "loop_p99_s",
                "running_fraction")}
            v["causes"] = s.get("force_error_causes", {})
            res["runs"][f"{obj}/{r}"] = v
            limits.append(check_run_csv(run_dir / "run.csv", s))
    if not quick:
        fault_dir = out_dir / "faults-hemisphere"
        s = run_simulation(RunSettings(duration_s=duration_s, faults="default"), design=design,
                           map_path=map_path, out=fault_dir, progress=False, array=array)
        res["faults"] = check_run_csv(fault_dir / "run.csv", s)
        limits.append(res["faults"])
    res["all_within_limits"] = all(c["within_limits"] for c in limits)
    res["max_command_a"] = max(c["max_command_a"] for c in limits)
    res["max_total_a"] = max(c["max_total_a"] for c in limits)
    return finish(out_dir / "render_runner.json", res, _print)


def _mn(x) -> str:
    return "    n/a" if x is None else f"{x * 1e3:7.2f}"


def _print(res: dict) -> None:
    print(f"slide {res['duration_s']} s per run; load average {res['load_average_1min']}")
    print("rendered-force error, RMS / p95 in mN: of |F| for the 3-D law ('force'), of Fz for "
          "the thesis' Fz-only law ('fz', whose lateral force is not controlled)")
    print(f"{'object/rows':20s} {'error':>15s} {'|F| error':>15s} {'obj. RMS':>8s} "
          f"{'loc. MAE':>8s} | by cause: {'localization':>15s} {'map':>15s} {'allocation':>15s} "
          f"{'current lag':>15s}")
    for k, v in res["runs"].items():
        c = v["causes"]
        key = "fz" if k.endswith("/fz") else "norm"

        def pair(d):
            return f"{_mn(d.get(key + '_rms_n'))}/{_mn(d.get(key + '_p95_n'))}"

        causes = " ".join(pair(c.get(n, {})) for n in ("localization", "map_interpolation",
                                                        "allocation", "current_lag"))
        print(f"{k:20s} {pair(c.get('total', {}))} {_mn(v['force_error_rms_n'])}/"
              f"{_mn(v['force_error_p95_n'])} {_mn(v['object_force_rms_n'])} "
              f"{(v['localization_mae_m'] or 0) * 1e3:5.2f} mm | {causes}")
    if "faults" in res:
        print("faults (hemisphere, --faults default): control periods to the safe state, from "
              "injection / from detection (the runner's log line)")
        for f in res["faults"]["faults"]:
            a, b = f["periods_from_injection"], f["periods_from_detection"]
            print(f"  {f['fault']:18s} -> {f['state']!s:18s} {'never' if a is None else a:>6} / "
                  f"{'n/a' if b is None else b}")
    print(f"largest command {res['max_command_a']:.3f} A, largest total {res['max_total_a']:.2f} A "
          f"over every step of every run; all within the limits: {res['all_within_limits']}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--map", default=None)
    ap.add_argument("--duration", type=float, default=4.0)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    run(a.out, map_path=a.map, duration_s=a.duration, quick=a.quick)
