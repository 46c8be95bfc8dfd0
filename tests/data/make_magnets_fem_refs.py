"""Regenerate the cached 3-D FEM references of two finger magnets over the thesis array.

Question: what does designkit's own 3-D GetDP model (``designkit.fem.fem3d.magnets_case``) say
about the cores of the thesis 3 x 3 array (mu_r 1000, no current) magnetized by two N52
10 x 10 mm magnets, so that the default tests can hold the coupled model's several-magnet
terms (each magnet's F0, the cross terms, the cores' field) to it without running a solver?

Cases (array frame, coil tops at z = 0; moments along -z unless said):

- ``side``: magnets at (-15, 0, 30) and (15, 0, 30) mm: 30 mm apart, 30 mm up;
- ``apart``: (-25, 0, 20) and (25, 0, 40) mm: 53.9 mm apart, 20 and 40 mm up;
- ``tilted``: (0, 0, 60) mm with its moment tilted 30 degrees towards +x, and (45, 0, 45) mm:
  47.4 mm apart.

At the mesh levels ``--levels`` (default -1, as cached: a level-0 case takes several times
longer; the FEM converges like h^2, so two levels' difference estimates the finer one's error).
Writes ``magnets_fem_refs.npz`` next to this file (SI: m,
A m^2, N, N m, T): ``<case>_positions_m`` (2, 3), ``<case>_moments_a_m2`` (2, 3),
``<case>_points_m`` (n, 3), and per level L ``<case>_L<L>_force_n`` (2, 2, 3) (entry [i, k]:
on magnet i from the cores magnetized by magnet k), ``_torque_n_m``, ``_b_t`` (2, n, 3);
``magnets_fem_refs.json`` the tetrahedra and GetDP seconds. Resumable: a case and level already
in the file is skipped.

Usage: ``PYTHONPATH=$PWD python tests/data/make_magnets_fem_refs.py [--levels -1]
[--cases side,apart,tilted]`` (needs GetDP; a level -1 case ~400-500 s under load).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
NPZ, JSON = HERE / "magnets_fem_refs.npz", HERE / "magnets_fem_refs.json"
POINTS_M = np.array([[0.0, 0.0, 0.014], [0.05, 0.0, 0.014], [-0.05, 0.0, 0.014],
                     [0.0, 0.05, 0.014], [0.0, 0.03, 0.03], [0.03, 0.03, 0.05]])
"""Where the cores' field is compared: four upper-sensor places (14 mm above coil tops) and
two workspace points, m."""
TILT = math.radians(30.0)
CASES = {
    "side": ([(-0.015, 0.0, 0.030), (0.015, 0.0, 0.030)], [(0, 0, -1), (0, 0, -1)]),
    "apart": ([(-0.025, 0.0, 0.020), (0.025, 0.0, 0.040)], [(0, 0, -1), (0, 0, -1)]),
    "tilted": ([(0.0, 0.0, 0.060), (0.045, 0.0, 0.045)],
               [(math.sin(TILT), 0.0, -math.cos(TILT)), (0, 0, -1)]),
}


def case_magnets(name: str):
    """(positions (2, 3) m, moments (2, 3) A m^2, radius m, length m) of a case: the default
    design's magnet (N52, 10 x 10 mm)."""
    from designkit.design import default_design

    mag = default_design().magnet
    pos, dirs = CASES[name]
    d = np.asarray(dirs, float)
    mom = mag.moment_a_m2 * d / np.linalg.norm(d, axis=1)[:, None]
    return np.asarray(pos, float), mom, mag.radius_m, mag.length_m


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--levels", default="-1", help="mesh levels, comma-separated")
    ap.add_argument("--cases", default=",".join(CASES), help="cases, comma-separated")
    args = ap.parse_args(argv)
    from designkit.fem.fem3d import magnets_case
    from designkit.model.array import CoilArray
    from firmware_io.cylinder_magnet import CylinderMagnet

    arr = CoilArray.default()
    arrays = dict(np.load(NPZ)) if NPZ.exists() else {}
    meta = json.loads(JSON.read_text()) if JSON.exists() else {}
    for name in args.cases.split(","):
        pos, mom, r, length = case_magnets(name)
        arrays.update({f"{name}_positions_m": pos, f"{name}_moments_a_m2": mom,
                       f"{name}_points_m": POINTS_M})
        for level in (int(x) for x in args.levels.split(",")):
            key = f"{name}_L{level}"
            if f"{key}_force_n" in arrays:
                continue
            mags = [CylinderMagnet(p, m, r, length) for p, m in zip(pos, mom)]
            res = magnets_case(arr, mags, POINTS_M, level=level)
            arrays.update({f"{key}_force_n": res["force_n"],
                           f"{key}_torque_n_m": res["torque_n_m"], f"{key}_b_t": res["b_t"]})
            meta[key] = {"tetrahedra": res["tetrahedra"], "getdp_seconds": res["seconds"],
                         "mesh_seconds": res["mesh_seconds"], "symmetry": res["symmetry"]}
            np.savez_compressed(NPZ, **arrays)
            JSON.write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
            print(f"{key}: {res['tetrahedra']} tetrahedra, {res['seconds']:.0f} s; F0 "
                  f"{np.round(res['force_n'][0, 0] * 1e3, 3).tolist()} mN", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
