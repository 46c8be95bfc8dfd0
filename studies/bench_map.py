"""Question: does the map file v2 meet its targets (``TARGETS``) on the default design -- file
size, build time, actuation() time for one point ((3,) or (1, 3)) and for 1e4 points with numpy
alone, interpolation error relative to each row's largest |A| against the coupled model -- and
how fast are the localizer's lookups (sensor_induced_field, bias_force) and the runner's row /
coil subsets? ``--layouts``: also the maps of ``LAYOUTS`` (hex-19, a ring of 6 tilted 30
degrees; build target ``LAYOUT_BUILD_S``), their errors at N_POINTS / 5.

Builds the map, writes and reloads it with firmware_io.mapfile (numpy only), times the lookups
and compares with CoilArray at ``n_points`` random points, half in the box's lowest 10 mm; the
bias force (against the magnet as its finite cylinder) and the sensor fields at fewer points. Timings: the minimum
over repeated short runs with the median beside it, and references in the same process
(``ref_call_us`` one 8 x 9 @ 9 matvec, ``ref_copy_ms`` a copy of a (1e4, 72) array,
``direct_per_point_ms`` the coupled model itself, the 2000 x 2000 matmul).

``--scene``: full map vs the thesis hemisphere's scene map: build wall and CPU, size, errors of
both at the same points in the region, the CPU of the box-independent stages vs the rest (whose
ratio is the time ratio's floor), fit nodes.

    python studies/bench_map.py [OUT_DIR] [N_POINTS] [--scene | --layouts]
"""

from __future__ import annotations

import argparse
import functools
import importlib
import os
import sys
import time
import tomllib
from pathlib import Path
from timeit import repeat

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit import default_design, fieldmap
from designkit.design import design_from_dict
from designkit.support.atomic import write_json_atomic
from designkit.model.array import ROWS, CoilArray
from designkit.fieldmap.region import MARGIN_M, within_reach
from designkit.render import Hemisphere
from firmware_io.mapfile import MapFile

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "bench_map"
"""Default output folder (git-ignored), whatever the working directory."""
LAYOUTS = {
    "hex19": '[array]\nlayout = "hex"\nrings = 2\npitch_m = 0.044\n',
    "ring6_tilted": '[array]\nlayout = "ring"\ncount = 6\nradius_m = 0.075\ntilt_deg = 30\n',
}
"""The other layouts' designs (every other key the default design's): a hexagonal array of 19
coils (2 rings) and a ring of 6 coils whose axes lean 30 degrees inwards."""
LAYOUT_BUILD_S = 10
"""Their build-time target, s (idle, median of 3)."""
TARGETS = {"file_mb": 5, "build_s": 5, "one_point_us": 20, "points_1e4_ms": 5, "max_rel": 1e-3}
"""The map's targets: file MB, build s, actuation() us for one point and ms for 1e4 points,
interpolation error relative to each row's largest |A|."""


def _t(fn, number: int, repeats: int) -> tuple[float, float]:
    """(min, median) seconds per call over ``repeats`` runs of ``number`` calls."""
    r = np.array(repeat(fn, number=number, repeat=repeats)) / number
    return float(r.min()), float(np.median(r))


def sample_points(lo, hi, n: int, seed: int) -> np.ndarray:
    """(n, 3) m: half uniform in the box, half with z in its lowest 10 mm."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(lo, hi, (n, 3))
    p[n // 2:, 2] = rng.uniform(lo[2], min(hi[2], lo[2] + 0.010), n - n // 2)
    return p


def row_errors(got: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Per row of A: max |got - ref| / max |ref| over points and coils, (8,)."""
    return (np.abs(got - ref).max(axis=(0, 2))
            / np.maximum(np.abs(ref).max(axis=(0, 2)), 1e-300))


def _timings(m: MapFile, lo, hi) -> dict:
    q = np.random.default_rng(0).uniform(lo, hi, (10000, 3))
    m.actuation(q)  # warm-up (scratch buffers)
    a = np.random.default_rng(1).random((8, 9))
    v = np.random.default_rng(2).random(9)
    big = np.random.default_rng(0).random((10000, 72))

    def us(fn, n=50, r=40):
        return [x * 1e6 for x in _t(fn, n, r)]

    out = {
        "t_1_us_shape3": us(lambda: m.actuation(q[0])),
        "t_1_us_shape13": us(lambda: m.actuation(q[:1])),
        "t_1_us_fz_rows": us(lambda: m.actuation(q[0], rows=(3, 6))),
        "t_bias_1_us": us(lambda: m.bias_force(q[0])),
        "t_sensor_1_us": us(lambda: m.sensor_induced_field(q[0])),
        "ref_call_us": us(lambda: a @ v, 200),
        "t_1e4_ms": [x * 1e3 for x in _t(lambda: m.actuation(q), 1, 21)],
        "t_1e4_fz_rows_ms": [x * 1e3 for x in _t(lambda: m.actuation(q, rows=(3, 6)), 1, 7)],
        "ref_copy_ms": [x * 1e3 for x in _t(lambda: big.copy(), 1, 15)],
    }
    out["ratio_1_to_ref_call"] = out["t_1_us_shape3"][0] / out["ref_call_us"][0]
    out["ratio_1e4_to_ref_copy"] = out["t_1e4_ms"][0] / out["ref_copy_ms"][0]
    return out


def _case(design, out_dir: Path, name: str, n_points: int, n_magnet: int, **build) -> dict:
    t_matmul = matmul_s()
    data, t_build, c_build = _timed_build(design, **build)
    path = fieldmap.write(out_dir / f"{name}.npz", data)
    t0 = time.perf_counter()
    m = MapFile.load(path, design.spec_hash())
    t_load = time.perf_counter() - t0
    arr = CoilArray.from_design(design)
    lo, hi = m.bounds
    pts = sample_points(lo, hi, n_points, 11)
    t0 = time.perf_counter()
    ref = arr.actuation_matrix(pts)
    t_direct = time.perf_counter() - t0
    got = m.actuation(pts)
    bottom = pts[:, 2] < lo[2] + 0.010
    moment = m.moment_a_m2
    mp = pts[:n_magnet]
    size = (design.magnet.radius_m, design.magnet.length_m)   # the magnet as the cylinder it is
    f_ref = arr.bias_force(mp, moment, magnet_size_m=size)
    f_err = np.abs(m.bias_force(mp) - f_ref).max() / max(np.abs(f_ref).max(), 1e-300)
    sens = m.sensor_positions_m.reshape(-1, 3)
    nm = min(n_magnet, 20)
    s_ref = np.array([arr.magnet_core_field(sens, p, moment) for p in mp[:nm]])
    s_err = np.abs(m.sensor_induced_field(mp[:nm]) - s_ref).max() / max(np.abs(s_ref).max(),
                                                                         1e-300)
    out = {
        "build_s": t_build, "build_cpu_s": c_build, "matmul_2000_s": t_matmul,
        "build_stage_s": data["meta"]["build_seconds"],
        "build_stage_cpu_s": data["meta"]["build_cpu_seconds"], "load_s": t_load,
        "file_mb": path.stat().st_size / 1e6, "n_points": n_points,
        "n_cells": sum(lay["nx"] * lay["ny"] for lay in data["meta"]["a_layers"]),
        "layers": [(lay["nx"], lay["ny"], lay["degree"]) for lay in data["meta"]["a_layers"]],
        "build_check": data["meta"]["errors"],
        "arrays_mb": {k: round(v.nbytes / 1e6, 3) for k, v in data["arrays"].items()
                      if v.nbytes > 1e4},
        "direct_per_point_ms": t_direct / n_points * 1e3,
        "max_rel_per_row": dict(zip(ROWS, row_errors(got, ref).tolist())),
        "max_rel_per_row_bottom_10mm": dict(zip(ROWS, row_errors(got[bottom],
                                                                 ref[bottom]).tolist())),
        "bias_force_max_rel": float(f_err), "n_bias_points": len(mp),
        "sensor_induced_max_rel": float(s_err), "n_sensor_points": nm,
        **_timings(m, lo, hi),
    }
    out["max_rel"] = max(out["max_rel_per_row"].values())
    path.unlink()
    return out


FIXED_STAGES = ("coupled solve", "saturation")
"""Build stages whose cost does not depend on the map's box (the coupled solve with the sensor
field's adjoint columns; the single core's nonlinear saturation solves)."""


def matmul_s() -> float:
    """Seconds of one 2000 x 2000 float64 matmul (min of 3): the machine's speed reference."""
    a = np.random.default_rng(0).random((2000, 2000))
    return min(repeat(lambda: a @ a, number=1, repeat=3))


def _cold_caches() -> None:
    """Empty the per-process caches of the core models (core types, saturation, linear and
    nonlinear solves) so that a build pays for everything it needs."""
    for name in ("core_model", "saturation", "panel", "discretization"):
        mod = importlib.import_module(f"designkit.cores.{name}")
        for obj in vars(mod).values():
            if isinstance(obj, functools._lru_cache_wrapper):
                obj.cache_clear()


def _cpu_s() -> float:
    """CPU seconds of this process and of its finished children (the build's workers)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _timed_build(design, **kw) -> tuple[dict, float, float]:
    _cold_caches()
    t0, c0 = time.perf_counter(), _cpu_s()
    data = fieldmap.build(design, progress=False, **kw)
    return data, time.perf_counter() - t0, _cpu_s() - c0


def density_floor(objects, band_m: float, margin_m: float, lower, upper, z_top: float,
                  step_m: float = 1e-3) -> float:
    """The share of a map's samples that a map of the same accuracy needs over the objects'
    reach alone: the integral of (z - z_top)^-3 over the points of the box [lower, upper] (m)
    within ``band_m`` + ``margin_m`` of some object (signed distance), over the same integral
    on the whole box (midpoint rule, ``step_m``). A harmonic field's local scale is its
    distance to the sources, so a map that samples locally at a given accuracy (the map's
    cells grow in proportion to z - z_top) needs density ~ (z - z_top)^-3; over the region's
    exact shape, with no cell overhang and no region-independent work, no such scene map
    does better."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    ax = [np.arange(lower[i] + step_m / 2, upper[i], step_m) for i in range(3)]
    x, y = np.meshgrid(ax[0], ax[1], indexing="ij")
    inside = total = 0.0
    for z in ax[2]:
        pts = np.c_[x.ravel(), y.ravel(), np.full(x.size, z)]
        w = (z - z_top) ** -3
        inside += w * within_reach(objects, pts, band_m + margin_m).sum()
        total += w * len(pts)
    return float(inside / total)


def scene_vs_full(out_dir=DEFAULT_OUT, n_points: int = 2000) -> dict:
    """Full map vs the scene map of the thesis hemisphere: time, size, errors in the region."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    d = default_design()
    lo, hi = fieldmap.default_box(d)
    box = fieldmap.scene_region([Hemisphere()], 0.0, lo, hi)
    res = {"matmul_2000_s": matmul_s(), "region_m": [box[0].tolist(), box[1].tolist()],
           "margin_m": MARGIN_M}
    arr = CoilArray.from_design(d)
    z_top = fieldmap.sources_top(arr)
    res["density_floor"] = {"margin": density_floor([Hemisphere()], 0.0, MARGIN_M, lo,
                                                    hi, z_top),
                            "no margin": density_floor([Hemisphere()], 0.0, 0.0, lo, hi, z_top)}
    pts = sample_points(box[0], box[1], n_points, 11)
    ref = arr.actuation_matrix(pts)
    mp = pts[:50]
    moment = d.magnet.moment_vector_a_m2
    f_ref = arr.bias_force(mp, moment, magnet_size_m=(d.magnet.radius_m, d.magnet.length_m))
    sens = arr.sensor_positions_m().reshape(-1, 3)
    s_ref = np.array([arr.magnet_core_field(sens, q, moment) for q in mp[:10]])
    scene = fieldmap.scene_build_args(d, [Hemisphere()], 0.0, region={"objects": ["half_ball"]})
    for name, kw in (("full", {}), ("scene", scene)):
        data, wall, cpu = _timed_build(d, **kw)
        path = fieldmap.write(out_dir / f"{name}.npz", data)
        m = MapFile.load(path, d.spec_hash())
        res[name] = {"build_s": wall, "build_cpu_s": cpu, "file_mb": path.stat().st_size / 1e6,
                     "max_rel_per_row": dict(zip(ROWS, row_errors(m.actuation(pts),
                                                                  ref).tolist())),
                     "bias_force_max_rel": float(np.abs(m.bias_force(mp) - f_ref).max()
                                                 / np.abs(f_ref).max()),
                     "sensor_induced_max_rel": float(
                         np.abs(m.sensor_induced_field(mp[:10]) - s_ref).max()
                         / np.abs(s_ref).max()),
                     "build_check": data["meta"]["errors"],
                     "n_fit_points": data["meta"]["settings"]["n_fit_points"],
                     "stage_cpu_s": data["meta"]["build_cpu_seconds"]}
        path.unlink()
    res["matmul_2000_s_after"] = matmul_s()
    write_json_atomic(out_dir / "bench_scene_map.json", res)
    return res


def report_scene(res: dict) -> None:
    """Print the table of :func:`scene_vs_full`."""
    print(f"== full map vs scene map (thesis hemisphere, region "
          f"{np.round(np.array(res['region_m']) * 1e3, 1).tolist()} mm); 2000 x 2000 matmul "
          f"{res['matmul_2000_s']:.3f} s before, {res['matmul_2000_s_after']:.3f} s after")
    print("   map    build s  CPU s  s/matmul  file MB  A err in region (of row max)  "
          "F0 err  sensor err  (in the region; build check: A, sensor)")
    for name in ("full", "scene"):
        r = res[name]
        c = r["build_check"]
        print(f"   {name:6s} {r['build_s']:7.1f} {r['build_cpu_s']:6.1f} "
              f"{r['build_s'] / res['matmul_2000_s']:9.0f} {r['file_mb']:8.2f}  "
              f"{max(r['max_rel_per_row'].values()):28.2e}  {r['bias_force_max_rel']:6.2e}  "
              f"{r['sensor_induced_max_rel']:10.2e}  "
              f"({max(c['actuation_max_rel_per_row'].values()):.2e}, "
              f"{c['sensor_induced_max_rel']:.2e})")
    f, s = res["full"], res["scene"]
    print(f"   scene / full: wall {s['build_s'] / f['build_s']:.2f}, CPU "
          f"{s['build_cpu_s'] / f['build_cpu_s']:.2f}, size {s['file_mb'] / f['file_mb']:.2f}")
    for name in ("full", "scene"):
        print(f"   {name} stages CPU s: " + ", ".join(
            f"{k} {v:.2f}" for k, v in res[name]["stage_cpu_s"].items()))
    fixed = {k: sum(v for st, v in res[k]["stage_cpu_s"].items() if st in FIXED_STAGES)
             for k in ("full", "scene")}
    region = {k: sum(res[k]["stage_cpu_s"].values()) - fixed[k] for k in ("full", "scene")}
    print(f"   region-independent stages ({', '.join(FIXED_STAGES)}) CPU s: full "
          f"{fixed['full']:.2f}, scene {fixed['scene']:.2f}; the rest: full "
          f"{region['full']:.2f}, scene {region['scene']:.2f} -> scene / full "
          f"{region['scene'] / region['full']:.2f} (the ratio's floor with no fixed cost); "
          f"fit nodes {s['n_fit_points']} / {f['n_fit_points']} = "
          f"{s['n_fit_points'] / f['n_fit_points']:.2f}")
    floor = res["density_floor"]
    ratio = (fixed["full"] + floor["margin"] * region["full"]) / sum(f["stage_cpu_s"].values())
    print(f"   the floor of any scene map of the full map's accuracy (samples ~ (z - z_top)^-3 "
          f"over the hemisphere's exact reach, no cell overhang, no region-independent work): "
          f"{floor['margin']:.3f} with the {res['margin_m'] * 1e3:g} mm margin, "
          f"{floor['no margin']:.3f} without; with this build's region-independent CPU "
          f"{fixed['full']:.2f} s: time ratio >= {ratio:.2f}")


def layout_design(name: str):
    """The design of :data:`LAYOUTS` ``name``."""
    return design_from_dict(tomllib.loads(LAYOUTS[name]))


def run(out_dir=DEFAULT_OUT, quick: bool = False, n_points: int = 10000,
        layouts: bool = False) -> dict:
    """The default map's case (``quick``: air coils over a small box instead); with
    ``layouts`` also the maps of :data:`LAYOUTS` (their errors at ``n_points`` / 5 points)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    d = default_design()
    if quick:  # air coils over a small box: no iron, seconds
        small = d.replace(**{"core": None, "workspace.shape": "box",
                             "workspace.half_width_m": 0.03, "workspace.z_max_m": 0.03})
        res = {"air_quick": _case(small, out_dir, "air_quick", 300, 5, n_check=10)}
    else:
        res = {"default": _case(d, out_dir, "default", n_points, 100)}
    if layouts:
        for name in LAYOUTS:
            res[name] = _case(layout_design(name), out_dir, name, max(200, n_points // 5), 40)
    write_json_atomic(out_dir / "bench_map.json", res)
    return res


def report(res: dict) -> None:
    """Print the table of :func:`run`'s result."""
    for name, r in res.items():
        stages = ", ".join(f"{k} {v:.1f} ({r['build_stage_cpu_s'][k]:.2f})"
                           for k, v in r["build_stage_s"].items())
        target = LAYOUT_BUILD_S if name in LAYOUTS else TARGETS["build_s"]
        print(f"== {name}: file {r['file_mb']:.2f} MB (target {TARGETS['file_mb']}), build "
              f"{r['build_s']:.1f} s (target {target}; CPU {r['build_cpu_s']:.1f} s, "
              f"{r['build_s'] / r['matmul_2000_s']:.0f} matmuls; "
              f"2000 x 2000 matmul in this process "
              f"{r['matmul_2000_s']:.3f} s; stages wall (CPU) s: {stages}), load "
              f"{r['load_s']:.2f} s, A in "
              f"{r['n_cells']} "
              f"harmonic cells (nx, ny, degree per layer: {r['layers']})")
        print(f"   arrays MB: {r['arrays_mb']}")
        print(f"   one point: (3,) {r['t_1_us_shape3'][0]:.1f} us, (1, 3) "
              f"{r['t_1_us_shape13'][0]:.1f} us (target {TARGETS['one_point_us']}; medians "
              f"{r['t_1_us_shape3'][1]:.1f}, {r['t_1_us_shape13'][1]:.1f}) = "
              f"{r['ratio_1_to_ref_call']:.0f} x one small numpy matvec "
              f"({r['ref_call_us'][0]:.2f} us); rows (3, 6) only {r['t_1_us_fz_rows'][0]:.1f}"
              f" us; bias_force {r['t_bias_1_us'][0]:.1f} us, sensor_induced_field "
              f"{r['t_sensor_1_us'][0]:.1f} us")
        print(f"   1e4 points {r['t_1e4_ms'][0]:.1f} ms (target {TARGETS['points_1e4_ms']}; "
              f"median {r['t_1e4_ms'][1]:.1f};"
              f" rows (3, 6) only {r['t_1e4_fz_rows_ms'][0]:.1f}) = "
              f"{r['ratio_1e4_to_ref_copy']:.0f} x a numpy copy of 1e4 x 72 float64 "
              f"({r['ref_copy_ms'][0]:.2f} ms); the direct coupled model: "
              f"{r['direct_per_point_ms'] * 1e4:.0f} ms per 1e4 points")
        print(f"   error vs the direct coupled model at {r['n_points']} points (half in the "
              f"lowest 10 mm; {r['direct_per_point_ms']:.1f} ms/point direct): max "
              f"{r['max_rel']:.2e} (target {TARGETS['max_rel']:g})")
        for key in ("max_rel_per_row", "max_rel_per_row_bottom_10mm"):
            print(f"      {key}: " + ", ".join(f"{k} {v:.1e}" for k, v in r[key].items()))
        print(f"   bias force max rel error {r['bias_force_max_rel']:.2e} ({r['n_bias_points']} "
              f"points); sensor-induced field {r['sensor_induced_max_rel']:.2e} "
              f"({r['n_sensor_points']} positions)")


def main(argv=None) -> int:

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", nargs="?", default=str(DEFAULT_OUT),
                    help="output folder (default out/bench_map)")
    ap.add_argument("n_points", nargs="?", type=int, default=None,
                    help="random check points (default 10000; 2000 with --scene)")
    which = ap.add_mutually_exclusive_group()
    which.add_argument("--scene", action="store_true",
                       help="the full map against the thesis hemisphere's scene map")
    which.add_argument("--layouts", action="store_true",
                       help="also the maps of a hex-19 and a tilted ring of 6")
    a = ap.parse_args(argv)
    if a.n_points is not None and a.n_points < 10:
        ap.error(f"n_points must be >= 10; got {a.n_points}")
    folder = Path(a.out)
    if a.scene:
        report_scene(scene_vs_full(folder, a.n_points or 2000))
    else:
        report(run(folder, n_points=a.n_points or 10000, layouts=a.layouts))
    print(f"written to {folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
