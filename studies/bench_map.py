"""Question: does the map file v2 meet its targets on the default design -- file <= 5 MB, built in
<= 30 s, actuation() <= 20 us for one point given as (3,) or (1, 3) and <= 5 ms for 1e4
points with numpy alone, interpolation error <= 1e-3 of each row's largest |A| against direct
evaluation of the coupled model -- and how close are the bias force and the sensor fields?

Builds the default map (thesis design: coupled iron-core array), writes and reloads it with
firmware_io.mapfile (numpy only), times the lookups, and compares with CoilArray (the coupled
model) at ``n_points`` uniformly random points in the box (errors per row relative to that
row's largest |value| over the sample, max and RMS, and in the bottom 2 mm of the box); the bias
force against CoilArray.bias_force and the sensor fields against CoilArray.magnet_core_field
at fewer points (each is one core solve). Timings are the minimum of repeated short runs
(robust to a loaded machine) and medians; the reference in the same process is a numpy copy
of a (1e4, 72) float64 array, the memory traffic of writing A for 1e4 points.

    python studies/bench_map.py [OUT_DIR] [N_POINTS]     (default out/bench_map, 10000)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from timeit import repeat

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit import default_design, fieldmap
from designkit._io import write_json_atomic
from designkit.array import ROWS, CoilArray
from firmware_io.mapfile import MapFile


DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "bench_map"
"""Default output folder (git-ignored), whatever the working directory."""


def _t(fn, number: int, repeats: int) -> tuple[float, float]:
    r = np.array(repeat(fn, number=number, repeat=repeats)) / number
    return float(r.min()), float(np.median(r))


def _case(design, out_dir: Path, name: str, n_points: int, n_magnet: int, **build) -> dict:
    t0 = time.perf_counter()
    data = fieldmap.build(design, progress=False, **build)
    path = fieldmap.write(out_dir / f"{name}.npz", data)
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    m = MapFile.load(path, design.spec_hash())
    t_load = time.perf_counter() - t0
    arr = CoilArray.from_design(design)
    lo, hi = m.bounds
    rng = np.random.default_rng(11)
    pts = rng.uniform(lo, hi, (n_points, 3))
    t0 = time.perf_counter()
    ref = arr.actuation_matrix(pts)
    t_direct = time.perf_counter() - t0
    got = m.actuation(pts)
    scale = np.abs(ref).max(axis=(0, 2))
    rel = np.abs(got - ref) / scale[None, :, None]
    bottom = pts[:, 2] < lo[2] + 0.002
    moment = m.moment_a_m2
    mp = pts[:n_magnet]
    f_ref = arr.bias_force(mp, moment)
    f_err = np.abs(m.bias_force(mp) - f_ref).max() / max(np.abs(f_ref).max(), 1e-300)
    sens = m.sensor_positions_m.reshape(-1, 3)
    nm = min(n_magnet, 20)
    s_ref = np.array([arr.magnet_core_field(sens, p, moment).reshape(2, -1, 3) for p in mp[:nm]])
    s_err = np.abs(m.sensor_induced_field(mp[:nm]) - s_ref).max() / max(np.abs(s_ref).max(),
                                                                         1e-300)
    q = rng.uniform(lo, hi, (10000, 3))
    m.actuation(q)  # warm-up (scratch buffers)
    big = np.random.default_rng(0).random((10000, 72))
    out = {
        "build_s": t_build, "build_stage_s": data["meta"]["build_seconds"], "load_s": t_load,
        "file_mb": path.stat().st_size / 1e6, "n_points": n_points,
        "n_basis": data["meta"]["n_basis"],
        "arrays_mb": {k: round(v.nbytes / 1e6, 3) for k, v in data["arrays"].items()
                      if v.nbytes > 1e4},
        "direct_per_point_ms": t_direct / n_points * 1e3,
        "max_rel_per_row": dict(zip(ROWS, rel.max(axis=(0, 2)).tolist())),
        "rms_rel_per_row": dict(zip(ROWS, np.sqrt((rel ** 2).mean(axis=(0, 2))).tolist())),
        "max_rel": float(rel.max()),
        "max_rel_bottom_2mm": float(rel[bottom].max()) if bottom.any() else None,
        "bias_force_max_rel": float(f_err), "n_bias_points": len(mp),
        "sensor_induced_max_rel": float(s_err), "n_sensor_points": nm,
        "t_1_us_shape3": [x * 1e6 for x in _t(lambda: m.actuation(q[0]), 20, 200)],
        "t_1_us_shape13": [x * 1e6 for x in _t(lambda: m.actuation(q[:1]), 20, 200)],
        "t_bias_1_us": [x * 1e6 for x in _t(lambda: m.bias_force(q[0]), 20, 100)],
        "t_sensor_1_us": [x * 1e6 for x in _t(lambda: m.sensor_induced_field(q[0]), 20, 100)],
        "t_1e4_ms": [x * 1e3 for x in _t(lambda: m.actuation(q), 1, 15)],
        "ref_copy_1e4x72_ms": [x * 1e3 for x in _t(lambda: big.copy(), 1, 15)],
    }
    out["ratio_1e4_to_ref_copy"] = out["t_1e4_ms"][0] / out["ref_copy_1e4x72_ms"][0]
    path.unlink()
    return out


def run(out_dir=DEFAULT_OUT, quick: bool = False, n_points: int = 10000) -> dict:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    d = default_design()
    if quick:  # air coils over a small box: no iron, seconds
        small = d.replace(**{"core": None, "workspace.half_width_m": 0.03,
                             "workspace.z_max_m": 0.03})
        res = {"air_quick": _case(small, out_dir, "air_quick", 300, 5, n_check=10)}
    else:
        res = {"default": _case(d, out_dir, "default", n_points, 100)}
    write_json_atomic(out_dir / "bench_map.json", res)
    return res


def _print(res):
    for name, r in res.items():
        stages = ", ".join(f"{k} {v:.1f}" for k, v in r["build_stage_s"].items())
        print(f"== {name}: file {r['file_mb']:.2f} MB (target 5), build {r['build_s']:.1f} s "
              f"(target 30; stages {stages}), load {r['load_s']:.2f} s, core modes "
              f"{r['n_basis']}")
        print(f"   arrays MB: {r['arrays_mb']}")
        print(f"   one point (3,) {r['t_1_us_shape3'][0]:.1f} us, (1, 3) "
              f"{r['t_1_us_shape13'][0]:.1f} us (target 20; min of runs, medians "
              f"{r['t_1_us_shape3'][1]:.1f}, "
              f"{r['t_1_us_shape13'][1]:.1f}); bias {r['t_bias_1_us'][0]:.1f} us, sensors "
              f"{r['t_sensor_1_us'][0]:.1f} us")
        print(f"   1e4 points {r['t_1e4_ms'][0]:.2f} ms (target 5; median {r['t_1e4_ms'][1]:.2f})"
              f" = {r['ratio_1e4_to_ref_copy']:.1f} x a numpy copy of 1e4 x 72 float64 "
              f"({r['ref_copy_1e4x72_ms'][0]:.2f} ms)")
        print(f"   error vs direct coupled model at {r['n_points']} points "
              f"({r['direct_per_point_ms']:.1f} ms/point direct): max {r['max_rel']:.2e} "
              f"(target 1e-3), bottom 2 mm {r['max_rel_bottom_2mm']}")
        print("      max per row: " + ", ".join(f"{k} {v:.1e}" for k, v in
                                                 r["max_rel_per_row"].items()))
        print(f"   bias force max rel error {r['bias_force_max_rel']:.2e} ({r['n_bias_points']} "
              f"points); sensor-induced field {r['sensor_induced_max_rel']:.2e} "
              f"({r['n_sensor_points']} positions)")


if __name__ == "__main__":
    out = (Path(sys.argv[1]) if len(sys.argv) > 1
           else Path(__file__).resolve().parents[1] / "out" / "bench_map")
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 10000
    _print(run(out, n_points=n))
    print(f"written to {out}")
