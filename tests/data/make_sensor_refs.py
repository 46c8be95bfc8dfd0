"""Regenerate the axisymmetric GetDP reference of the core field at the Hall sensors
(tests/data/sensor_refs.*): one unpowered thesis core magnetized by the finger magnet on its
axis.

The question: Bz (T) that the core, magnetized by the design's magnet alone (every coil off),
adds at the design's two sensors of that coil -- on the axis ``sensors.offset_m`` above the
winding's top face and below its bottom face -- with the magnet's centre 20 / 30 / 50 mm above
the winding's top and its moment the design's (default: down). This is what the map calls the
sensor-induced field and what the localizer subtracts from the readings; an error in it moves
every fix. The magnet: uniform M as an azimuthal current sheet SHEET_M thick on its side, the
moment kept (tests/data/make_axisym_refs.py, 'pull'); the induced field is the difference of a
mu_r 1000 and a mu_r 1 solve on one mesh (the source's own field and its discretization error
cancel). Mesh and problem: designkit.fem's (second-order a_phi, spherical-shell infinity), the
axis sampled every 25 um around each sensor and Bz taken from a local polynomial fit. Each
height is solved at ``--levels`` (default 0,1); the largest change between the two finest is
stored as the reference's own error estimate (sensor_refs.json).

Usage: ``PYTHONPATH=$PWD python tests/data/make_sensor_refs.py [--levels 0,1]`` (needs GetDP
and gmsh; minutes per level).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

from make_axisym_refs import SHEET_M, SHELL_M, _core_rect, _mesh  # noqa: E402

from designkit.design import default_design  # noqa: E402
from designkit.fem.mesh import CORE, WINDING  # noqa: E402
from designkit.fem.problem import problem_text  # noqa: E402
from designkit.fem.runner import _read_line, find_getdp, run_getdp, work_folder  # noqa: E402
from designkit.model.coil import Coil  # noqa: E402

HEIGHTS_M = (0.020, 0.030, 0.050)
"""Magnet centre above the winding's top face, m."""
AXIS_R_M = 1e-7
"""Radius of the sampled 'axis' line, m (a_phi = 0 on the axis itself)."""
HALF_SPAN_M = 5e-3
"""Each sensor's sampled axis segment: this far above and below it, m."""


def sensor_heights_m(design) -> tuple[float, float]:
    """(upper, lower) sensor heights in the FEM frame (winding centre at z = 0), m."""
    reach = design.coil.length_m / 2 + design.sensors.offset_m
    return reach, -reach


def solve_height(design, h: float, level: int, timeout_s: float = 1800.0) -> tuple[list, dict]:
    """Induced Bz (T) at the (upper, lower) sensors with the magnet ``h`` above the winding's
    top (one mesh, two solves), and the mesh's statistics."""
    coil = Coil.from_design(design, (0.0, 0.0, 0.0))
    mag = design.magnet
    a, length = mag.radius_m, mag.length_m
    d = SHEET_M
    # the sheet's moment = the magnet's; +phi current is a +z moment: the design's sign
    sign = math.copysign(1.0, mag.moment_vector_a_m2[2])
    jd = sign * mag.magnetization_a_per_m / d * a * a / (a * a + d * d / 12)
    zc = coil.length / 2 + h
    z0, z1 = zc - length / 2, zc + length / 2
    sensors = sensor_heights_m(design)
    names = ("upper.txt", "lower.txt")
    n = int(round(2 * HALF_SPAN_M / 25e-6))
    lines = [(AXIS_R_M, s - HALF_SPAN_M, AXIS_R_M, s + HALF_SPAN_M, n, name)
             for s, name in zip(sensors, names)]
    lines.append((a, z0, a, z1, int(round(length / 0.05e-3)), "sheet.txt"))
    boxes = {WINDING: [(a - d / 2, z0, a + d / 2, z1)], CORE: [_core_rect(coil, 0.0)]}
    refine = [(a + 3e-3, z0 - 3e-3, z1 + 3e-3)] + [
        (3e-3, s - HALF_SPAN_M - 2e-3, s + HALF_SPAN_M + 2e-3) for s in sensors]
    bz = {}
    with work_folder(None, "designkit_sensor_refs_") as work:
        stats = _mesh(boxes, level, refine, work / "model.msh", h_fine=0.1e-3)
        for mu in (float(coil.core.relative_permeability), 1.0):
            pro = problem_text(current_density=jd, mu_r=mu, bh=None, has_core=True,
                               shell_inner=SHELL_M[0], shell_outer=SHELL_M[1], lines=lines,
                               winding_area=d * length, turns=1)
            run_getdp(find_getdp(), work, pro, work / "model.msh", timeout_s, expect="lower.txt")
            bz[mu] = [float(_read_line(work / name, AXIS_R_M).fit([s], half_window=2e-3)["bz"][0])
                      for s, name in zip(sensors, names)]
    lin, air = bz[float(coil.core.relative_permeability)], bz[1.0]
    return [p - q for p, q in zip(lin, air)], stats


def fem_inputs(design) -> dict:
    """What the FEM's geometry and sources depend on: the magnet, winding, core and sensors."""
    m, c, k = design.magnet, design.coil, design.core
    return {"magnet": [m.radius_m, m.length_m, m.magnetization_a_per_m],
            "coil": [c.inner_radius_m, c.outer_radius_m, c.length_m, c.turns],
            "core": [k.radius_m, k.length_m, k.relative_permeability, k.offset_m],
            "sensor_offset_m": design.sensors.offset_m}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="0,1", help="mesh levels, comma-separated (default 0,1)")
    a = ap.parse_args(argv)
    levels = [int(q) for q in a.levels.split(",")]
    design = default_design()
    arrays = {"heights_m": np.array(HEIGHTS_M),
              "sensor_z_m": np.array(sensor_heights_m(design)) - design.coil.length_m / 2,
              "moment_a_m2": np.array(design.magnet.moment_vector_a_m2)}
    meta = {"sheet_m": SHEET_M, "levels": {}, "inputs": fem_inputs(design),
            "frame": "design frame: coil top face at z = 0, magnet on the axis at x = y = 0"}
    res = {}
    for lv in levels:
        t0 = time.perf_counter()
        rows = []
        for h in HEIGHTS_M:
            b, stats = solve_height(design, h, lv)
            rows.append(b)
        res[lv] = np.array(rows)
        arrays[f"level{lv}_bz_t"] = res[lv]
        meta["levels"][str(lv)] = {**stats, "seconds": round(time.perf_counter() - t0, 1)}
        print(f"level {lv}: induced Bz (upper, lower) {res[lv].tolist()} T, "
              f"{meta['levels'][str(lv)]['seconds']:.0f} s", flush=True)
    arrays["bz_t"] = res[levels[-1]]
    arrays["level"] = np.array(levels[-1])
    if len(levels) > 1:
        meta["change_last_level"] = float(np.max(np.abs(res[levels[-1]] / res[levels[-2]] - 1)))
        print(f"change between the two finest levels {meta['change_last_level']:.2e}")
    np.savez_compressed(HERE / "sensor_refs.npz", **arrays)
    (HERE / "sensor_refs.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
