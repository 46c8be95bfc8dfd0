"""Regenerate the cached 3-D FEM references of arrays of other layouts than the thesis grid.

Question: what does designkit's own 3-D GetDP model (``designkit.fem.fem3d.device_case``: every
core in its pose, one energized winding at 1 A, linear cores) say about a hexagonal array of 7
coils, a ring of 6 coils whose axes lean 30 degrees inwards and (``--cases grid4x4_c5``, a full
model) a 4 x 4 grid, so that the default tests hold the coupled model of any layout to an
independent reference without running a solver?

Writes ``layout_fem_refs.npz`` next to this file (per case ``<case>_points_m`` (n, 3) m,
``<case>_b_t`` (n, 3) T, ``<case>_g_t_per_m`` (n, 3, 3) T/m) and ``layout_fem_refs.json``
(per case: the design file's text, the energized coil, the mesh level, tetrahedra, the model's
symmetry cut and the wall-clock seconds). Points: a 5 x 5 grid over the design's workspace
bounding box at 20, 30, 50 and 80 mm above the coil tops.

Usage: ``PYTHONPATH=$PWD python tests/data/make_layout_fem_refs.py [--level N]
[--cases hex7_c0,hex7_c1,ring6_c0,grid4x4_c5]`` (needs GetDP; minutes to an hour per case).
"""

from __future__ import annotations

import argparse
import json
import time
import tomllib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
HEIGHTS_M = (0.020, 0.030, 0.050, 0.080)
"""Heights of the points above the coil tops, m."""
DESIGNS = {
    "hex7": '[array]\nlayout = "hex"\nrings = 1\npitch_m = 0.044\n',
    "ring6": '[array]\nlayout = "ring"\ncount = 6\nradius_m = 0.075\ntilt_deg = 30\n',
    "grid4x4": '[array]\nrows = 4\ncolumns = 4\n',
}
"""The design files of the cases (every other key the default design's)."""
CASES = {"hex7_c0": ("hex7", 0), "hex7_c1": ("hex7", 1), "ring6_c0": ("ring6", 0),
         "grid4x4_c5": ("grid4x4", 5)}
"""Case name -> (design, energized coil) (the 4 x 4 grid's coil 5 is an inner one: no mirror
keeps it, the full model is solved)."""


def case_array(name: str):
    """The CoilArray of a design of :data:`DESIGNS`."""
    from designkit.design import design_from_dict
    from designkit.model.array import CoilArray

    return CoilArray.from_design(design_from_dict(tomllib.loads(DESIGNS[name])))


def case_points(name: str) -> np.ndarray:
    """(100, 3) m: 5 x 5 over the workspace's bounding box at :data:`HEIGHTS_M`."""
    from designkit.design import design_from_dict

    lo, hi = design_from_dict(tomllib.loads(DESIGNS[name])).workspace_region().bounds_m()
    X, Y, Z = np.meshgrid(np.linspace(lo[0], hi[0], 5), np.linspace(lo[1], hi[1], 5),
                          np.array(HEIGHTS_M), indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])


def _load() -> tuple[dict, dict]:
    npz, js = HERE / "layout_fem_refs.npz", HERE / "layout_fem_refs.json"
    arrays = dict(np.load(npz)) if npz.exists() else {}
    meta = json.loads(js.read_text()) if js.exists() else {}
    return arrays, meta


def main(argv=None) -> int:
    from designkit.fem.fem3d import device_case

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--level", type=int, default=0, help="3-D mesh level")
    ap.add_argument("--cases", default="hex7_c0,hex7_c1,ring6_c0")
    a = ap.parse_args(argv)
    arrays, meta = _load()
    for case in a.cases.split(","):
        design, k = CASES[case]
        pts = case_points(design)
        t0 = time.perf_counter()
        b, g, res = device_case(case_array(design), pts, energized=k, level=a.level,
                                timeout_s=4 * 3600.0)
        arrays.update({f"{case}_points_m": pts, f"{case}_b_t": b, f"{case}_g_t_per_m": g})
        meta[case] = {"design_toml": DESIGNS[design], "energized": k, "level": a.level,
                      "tetrahedra": res.mesh_stats["tetrahedra"],
                      "symmetry": res.extra["symmetry"],
                      "seconds": round(time.perf_counter() - t0, 1)}
        np.savez_compressed(HERE / "layout_fem_refs.npz", **arrays)
        (HERE / "layout_fem_refs.json").write_text(json.dumps(meta, indent=1, sort_keys=True)
                                                   + "\n")
        print(f"{case}: {meta[case]['seconds']:.0f} s, {meta[case]['tetrahedra']} tetrahedra",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
