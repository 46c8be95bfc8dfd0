"""Question: with coil currents up to +-6 A in any pattern, which Hall sensors stay usable, how
often does the runner's sensor side still get a trusted fix from them, and can the scene keep
the sensors it needs in their linear range?

Open loop (frames): the default design's sensors (designkit.sim.readings: exact magnet,
coupled coils and cores, mounting and gain errors calibrated at start-up through the firmware's
path, 0.1 mT noise, 12-bit clipping) with the magnet at random positions
20-70 mm above the coils and current patterns of one amplitude (every coil at +-A, random
signs; and the +-A checkerboard); the runner's SensorPipeline leaves out every sensor its model
predicts beyond 80 % of the 130 mT range (the coils' field from the map, the magnet's dipole
at the true position) and the map's estimator fits the rest, as the runner does while it
tracks the finger (with its tracker's prior: the true pose off by PRIOR_SD) and cold (no
prior: the first fix, or one after the track was lost). Per amplitude: the sensors left,
the fraction of frames with a trusted fix (tracking, cold), and the trusted fixes more than
5 mm off.
`designkit check` gives the same in currents: one coil alone blinds its sensors at ~4.2 A.

Closed loop: the hemisphere slide with a stiff object (lambda 40 N/m: forces up to ~1.6 N,
currents up to the limit), without and with the scene keeping the upper sensors (0-8) within
their range (``designkit run --simulate --keep-sensors 0-8``): the running fraction, the
force error and the most sensors dropped for saturation in a frame.

    python studies/runner_headroom.py [OUT_DIR] [--map FILE] [--frames N] [--quick]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit.sim import RunSettings, SimulatedDevice, run_simulation
from firmware_io.localization import SensorModel, estimator_from_map
from firmware_io.mapfile import MapFile
from firmware_io.localization.pose import tangent_axes
from firmware_io.runner import CurrentHistory, SensorFrame, SensorLayout, SensorPipeline
from firmware_io.runner.tracker import TrackedPose
from studies._common import design_and_map, finish, load_average

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "runner_headroom"
"""Default output folder (git-ignored), whatever the working directory."""

AMPLITUDES_A = (0.0, 2.0, 3.0, 4.0, 6.0)
"""Current amplitudes of the patterns, A."""

PRIOR_SD = (0.5e-3, np.radians(2.0))
"""The tracker's prior while tracking: position sd per axis, m; direction sd per tangent axis,
rad (as studies/pose_integrity.py)."""


def frames_at(design, array, map_path, amplitude_a: float, n: int, seed: int = 0) -> dict:
    """The open-loop frames at one amplitude (module docstring): dict of the numbers."""
    rng = np.random.default_rng(seed)
    device = SimulatedDevice(design, array, seed=seed)
    sim = device.sensor_sim
    fmap = MapFile.load(map_path)
    cal = device.calibrate_sensors(SensorModel.from_map(map_path))
    estimator = estimator_from_map(map_path, "model", calibration=cal)
    layout = SensorLayout.of_map(fmap)
    pos = rng.uniform([-0.03, -0.03, 0.02], [0.03, 0.03, 0.07], (n, 3))
    signs = rng.choice([-1.0, 1.0], (n, array.n_coils))
    board = np.array([(-1.0) ** k for k in range(array.n_coils)])
    signs[: n // 4] = board                         # a quarter: the checkerboard
    cur = amplitude_a * signs
    r = sim.read(pos, cur)
    readings = np.concatenate([r.top_t, r.bottom_t], axis=1)
    left, trusted, off = [], {"track": 0, "cold": 0}, 0
    moment = np.asarray(fmap.moment_a_m2, float)     # the simulated magnet is upright
    cov = np.diag([PRIOR_SD[0] ** 2] * 3 + [PRIOR_SD[1] ** 2] * 2)
    for k in range(n):
        hist = CurrentHistory(array.n_coils, 2)
        hist.push(0.0, cur[k])
        for mode in trusted:
            pipe = SensorPipeline(estimator, layout, hist.at, fmap.moment_a_m2)
            pipe.position_m = pos[k]                    # the pose the model predicts with
            if mode == "track":
                pipe.track = _prior(pos[k], moment, cov, rng)
            estimator.reset()
            fix = pipe.process(SensorFrame(readings[k], ("ok",) * len(readings[k]), 0.0))
            if mode == "track":
                left.append(int((~fix.excluded & np.isfinite(readings[k]).all(axis=1)).sum()))
            if fix.ok:
                trusted[mode] += 1
                off += int(np.linalg.norm(fix.position_m - pos[k]) > 5e-3)
    return {"amplitude_a": amplitude_a, "frames": n, "sensors_left_median": float(np.median(left)),
            "sensors_left_min": int(min(left)), "trusted_fraction": trusted["track"] / n,
            "trusted_fraction_cold": trusted["cold"] / n, "trusted_beyond_5mm": off}


def _prior(position_m, moment_a_m2, cov, rng) -> TrackedPose:
    """A tracker's state at the frame's time: the true pose off by :data:`PRIOR_SD`."""
    e1, e2 = tangent_axes(moment_a_m2 / np.linalg.norm(moment_a_m2))
    a, b = rng.normal(scale=PRIOR_SD[1], size=2)
    m = moment_a_m2 + np.linalg.norm(moment_a_m2) * (a * e1 + b * e2)
    m *= np.linalg.norm(moment_a_m2) / np.linalg.norm(m)
    return TrackedPose(position_m + rng.normal(scale=PRIOR_SD[0], size=3), m, cov, 0.0,
                       np.zeros(3), 0.0, 0.0, 0.0)


def run(out_dir=DEFAULT_OUT, *, map_path=None, frames: int = 200, quick: bool = False) -> dict:
    out_dir, design, array, map_path = design_and_map(out_dir, map_path, progress=not quick)
    res = {"load_average_1min": load_average(), "open_loop": [], "closed_loop": {}}
    for amp in AMPLITUDES_A[::2] if quick else AMPLITUDES_A:
        res["open_loop"].append(frames_at(design, array, map_path, amp, 30 if quick else frames))
    for name, keep in (("plain", ()), ("keep_upper_sensors", tuple(range(9)))):
        s = run_simulation(RunSettings(lam_n_per_m=40.0, duration_s=0.6 if quick else 4.0,
                                       keep_sensors=keep), design=design, map_path=map_path,
                           out=out_dir / name, progress=False, array=array)
        res["closed_loop"][name] = {k: s[k] for k in (
            "running_fraction", "force_error_rms_n", "object_force_rms_n", "max_command_a",
            "max_saturating_sensors", "localization_mae_m", "rendered_off_frame_steps")}
    return finish(out_dir / "runner_headroom.json", res, _print)


def _print(res: dict) -> None:
    print(f"sensor headroom (load average {res['load_average_1min']})")
    print("open loop: amplitude A | sensors left median (min) | trusted fixes tracking "
          "(cold) | > 5 mm off")
    for r in res["open_loop"]:
        print(f"  {r['amplitude_a']:4.1f} | {r['sensors_left_median']:5.1f} "
              f"({r['sensors_left_min']:2d}) | {r['trusted_fraction']:6.3f} "
              f"({r['trusted_fraction_cold']:5.3f}) | {r['trusted_beyond_5mm']}")
    print("closed loop, hemisphere at 40 N/m: running | force error RMS mN (object RMS) | "
          "max |I| A | most sensors dropped | MAE mm")
    for name, r in res["closed_loop"].items():
        mae = r["localization_mae_m"]
        print(f"  {name:20s} {r['running_fraction']:6.3f} | "
              f"{1e3 * r['force_error_rms_n']:6.1f} ({1e3 * r['object_force_rms_n']:6.1f}) | "
              f"{r['max_command_a']:4.2f} | {r['max_saturating_sensors']:2d} | "
              f"{'n/a' if mae is None else f'{1e3 * mae:.2f}'}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--map", default=None, help="an existing map file (default: build one)")
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    run(a.out, map_path=a.map, frames=a.frames, quick=a.quick)
