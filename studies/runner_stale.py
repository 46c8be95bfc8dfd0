"""Question: after the finger jumps or is taken away, does the runner ever render with a position
the sensors no longer support, and how soon is it back once the finger returns?

The closed loop (designkit.sim: firmware_io's runner with the map's localizer on the simulated
device, start-up calibration, 0.1 mT noise, modelled compute time) over the hemisphere. The
finger hovers 30 mm above the coils, then jumps 40 mm sideways between two control steps,
hovers, is taken away (the simulator's ``out_of_box``: lifted 60 mm above the map box, where no
trajectory may go, for 0.3 s) and comes back 40 mm from where it left. For every running step: how far the rendered position is from the finger
at the frame time of the newest fix the runner had (what it could know; acceptance: never more
than 5 mm) and from the finger now (that includes the sensing latency, about two bus passes);
for each event the time from the finger's arrival to the first running step (the issue's
acceptance limit: README), and the running steps at the old position after it.

    python studies/runner_stale.py [OUT_DIR] [--map FILE] [--seeds N]
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
from designkit.sim.loop import OUT_OF_BOX_S
from studies._common import design_and_map, finish, load_average

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "runner_stale"
"""Default output folder (git-ignored), whatever the working directory."""

LIMIT_M = 5e-3
"""A rendered position farther than this from the finger is counted, m."""


def path_csv(path, *, height_m: float = 0.030, jump_m: float = 0.040) -> dict:
    """Write the trajectory (hover, jump, hover, the sideways move back while the finger is
    away) and return the event times, s: {'jump': t, 'removed': t, 'back': t}; the removal is
    the fault schedule's ``out_of_box`` at 'removed' (the finger away for
    :data:`designkit.sim.loop.OUT_OF_BOX_S`)."""
    ev = {"jump": 0.35, "removed": 0.65, "back": 0.65 + OUT_OF_BOX_S}
    end = ev["back"] + 0.35
    x0, x1 = -jump_m / 2, jump_m / 2
    away = (ev["removed"] + ev["back"]) / 2
    pts = [(0.0, x0, height_m), (ev["jump"] - 1e-6, x0, height_m), (ev["jump"], x1, height_m),
           (away - 1e-6, x1, height_m), (away, x0, height_m), (end, x0, height_m)]
    Path(path).write_text("t_s,x_m,y_m,z_m\n" + "".join(f"{t:.7f},{x:.6f},0.0,{z:.6f}\n"
                                                       for t, x, z in pts))
    return ev


def measure(run_csv, events: dict) -> dict:
    """From run.csv: the running steps rendered more than LIMIT_M from the finger (at the fix's
    frame time, and now), and per event the time to the first running step after it and the
    running steps before the runner stopped at the old position."""
    with open(run_csv, newline="") as fh:
        rows = list(csv.DictReader(fh))
    t = np.array([float(r["t_s"]) for r in rows])
    st = np.array([r["state"] for r in rows])
    p = np.array([[float(r[k]) for k in ("x_m", "y_m", "z_m")] for r in rows])
    pe = np.array([[float(r[k]) for k in ("xe_m", "ye_m", "ze_m")] for r in rows])
    t_fix = np.array([float(r["fix_t_s"]) for r in rows])
    run = st == "running"
    at_fix = np.stack([np.interp(t_fix, t, p[:, k]) for k in range(3)], 1)
    off_frame = np.linalg.norm(pe - at_fix, axis=1)
    off_now = np.linalg.norm(pe - p, axis=1)
    out = {"running_steps": int(run.sum()),
           "off_at_frame_steps": int(np.sum(run & (off_frame > LIMIT_M))),
           "off_at_frame_max_m": float(np.max(off_frame[run])),
           "off_now_steps": int(np.sum(run & (off_now > LIMIT_M))), "events": {}}
    ends = sorted(events.values()) + [np.inf]
    for name, te in events.items():
        after = (t >= te - 1e-12) & (t < ends[ends.index(te) + 1] - 1e-12)
        moved = after & run & (off_now > LIMIT_M)
        first_off = np.flatnonzero(after & ~run)
        back = np.flatnonzero(after & run & (off_now <= LIMIT_M))
        if first_off.size:
            back = back[back > first_off[0]]
        out["events"][name] = {
            "t_s": te,
            "rendered_old_position_ms": 1e3 * float(moved.sum()) * (t[1] - t[0]),
            "stopped_after_ms": (None if not first_off.size
                                 else 1e3 * float(t[first_off[0]] - te)),
            "running_again_after_ms": (None if name == "removed" or not back.size
                                       else 1e3 * float(t[back[0]] - te))}
    return out


def run(out_dir=DEFAULT_OUT, *, map_path=None, seeds: int = 3, design=None, array=None,
        progress: bool = True) -> dict:
    """The study (module docstring) over ``seeds`` sensor-noise seeds."""
    if design is None:
        out_dir, design, array, map_path = design_and_map(out_dir, map_path, progress=progress)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    events = path_csv(out_dir / "path.csv")
    res = {"load_average_1min": load_average(), "limit_m": LIMIT_M, "runs": []}
    for seed in range(seeds):
        sub = out_dir / f"seed{seed}"
        summary = run_simulation(RunSettings(trajectory=str(out_dir / "path.csv"), seed=seed,
                                             faults=f"out_of_box@{events['removed']:g}"),
                                 design=design, map_path=map_path, array=array, out=sub,
                                 progress=False)
        row = measure(sub / "run.csv", events)
        row.update(seed=seed, running_fraction=summary["running_fraction"])
        res["runs"].append(row)
    runs = res["runs"]
    res["off_at_frame_steps_total"] = sum(r["off_at_frame_steps"] for r in runs)
    backs = [r["events"][e]["running_again_after_ms"] for r in runs for e in ("jump", "back")]
    res["running_again_max_ms"] = None if None in backs else max(backs)
    return finish(out_dir / "runner_stale.json", res, _print)


def _print(res: dict) -> None:
    print(f"runner after a 40 mm jump and a removal ({len(res['runs'])} seeds; load average "
          f"{res['load_average_1min']})")
    print("seed  running  >5mm at frame  >5mm now  | jump: old ms / stop ms / back ms | "
          "removed: old ms / stop ms | back: back ms")
    for r in res["runs"]:
        e = r["events"]

        def ms(v):
            return "   -" if v is None else f"{v:4.0f}"
        print(f"{r['seed']:4d}  {r['running_steps']:7d}  {r['off_at_frame_steps']:13d}  "
              f"{r['off_now_steps']:8d}  |  {ms(e['jump']['rendered_old_position_ms'])} / "
              f"{ms(e['jump']['stopped_after_ms'])} / {ms(e['jump']['running_again_after_ms'])}"
              f"  |  {ms(e['removed']['rendered_old_position_ms'])} / "
              f"{ms(e['removed']['stopped_after_ms'])}  |  "
              f"{ms(e['back']['running_again_after_ms'])}")
    print(f"rendered > 5 mm from the finger at the fix's frame time: "
          f"{res['off_at_frame_steps_total']} steps; running again after the finger's arrival: "
          f"<= {res['running_again_max_ms']} ms")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--map", default=None, help="an existing map file (default: build one)")
    ap.add_argument("--seeds", type=int, default=3, help="runs, seeds 0 .. SEEDS-1 (>= 1)")
    a = ap.parse_args()
    if a.seeds < 1:
        ap.error(f"--seeds must be >= 1 (runs with seeds 0 .. SEEDS-1); got {a.seeds}")
    run(a.out, map_path=a.map, seeds=a.seeds)
