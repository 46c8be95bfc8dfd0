"""Regenerate the nonlinear axisymmetric GetDP reference of the saturation factor
(tests/data/saturation_refs.json).

The question: by what factor does a 1010-steel core (``Core(bh='steel1010')``) reduce the force
of the design's coil on an upright magnet, against the linear core at ``relative_permeability``
that the coupled array model (and so the map's A) assumes? The factor is what the map stores
(``SAT_FACTOR``, designkit.cores.saturation_table) and what the runner and the simulated plant
apply: ``s(I) = dBz/dz_steel1010(I) / (I dBz/dz_linear(1 A))`` on the coil's axis, which is
also the ratio of the vertical forces on a magnet there (F_z = m_z dBz/dz).

Model: designkit.fem's axisymmetric problem of the thesis coil with its core (second-order
a_phi, spherical-shell infinity, GetDP's Newton iteration on the 1010 B-H table for the
nonlinear core); dBz/dz from local polynomial fits along the axis line
(designkit.fem.runner.solve). Heights: 20 / 30 / 50 mm above the winding's top (30 mm is the
map's design point), and off the axis at PROBES_M, where the winding's and the core's parts of
the field differ in share (the per-point saturation of the simulated plant,
designkit.sim.saturation): there the factor of each of Br, Bz, dBr/dz, dBz/dz (B and its
z-derivatives from a local polynomial through a short vertical segment,
``designkit.fem.runner.solve(probes=...)``). Currents CURRENTS_A. Each mesh level in
``--levels`` (default 0,1); the largest change of a factor between the two finest is stored as
the reference's own error estimate.

Usage: ``PYTHONPATH=$PWD python tests/data/make_saturation_refs.py [--levels 0,1]`` (needs
GetDP and gmsh; minutes per level).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

from designkit.design import default_design
from designkit.fem.runner import solve
from designkit.model.coil import Coil

HERE = Path(__file__).resolve().parent
HEIGHTS_M = (0.020, 0.030, 0.050)
"""Points on the axis above the winding's top face, m."""
CURRENTS_A = (3.0, 5.0, 6.0)
"""Coil currents of the nonlinear solves, A (the linear one is solved at 1 A)."""
PROBES_M = ((0.025, 0.020), (0.050, 0.020), (0.050, 0.040))
"""Off-axis points (r, height above the winding's top), m."""
PROBE_KEYS = ("br", "bz", "dbr_dz", "dbz_dz")


def fem_inputs(design) -> dict:
    """What the FEM's geometry and material depend on: the winding and the core."""
    c, k = design.coil, design.core
    return {"coil": [c.inner_radius_m, c.outer_radius_m, c.length_m, c.turns],
            "core": [k.radius_m, k.length_m, k.relative_permeability, k.offset_m]}


def factors(design, level: int) -> tuple[np.ndarray, np.ndarray]:
    """Saturation factors at mesh ``level``: on the axis (len(CURRENTS_A), len(HEIGHTS_M))
    and at the probes (len(CURRENTS_A), len(PROBES_M), len(PROBE_KEYS))."""
    coil = Coil.from_design(design, (0.0, 0.0, 0.0))
    z = coil.length / 2 + np.array(HEIGHTS_M)
    probes = np.array([(r, coil.length / 2 + h) for r, h in PROBES_M])
    linear = dataclasses.replace(coil, core=dataclasses.replace(coil.core, bh="linear"))
    lin = solve(linear, 1.0, level=level, probes=probes)
    g_lin = lin.axis.fit(z)["dbz_dz"]
    p_lin = np.stack([lin.probes[k] for k in PROBE_KEYS], -1)
    rows, at_probes = [], []
    for i in CURRENTS_A:
        res = solve(coil, float(i), bh="steel1010", level=level, probes=probes)
        if not res.newton_converged:
            raise SystemExit(f"the nonlinear FEM did not converge at {i} A, level {level}")
        rows.append(res.axis.fit(z)["dbz_dz"] / (i * g_lin))
        at_probes.append(np.stack([res.probes[k] for k in PROBE_KEYS], -1) / (i * p_lin))
    return np.array(rows), np.array(at_probes)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--levels", default="0,1", help="mesh levels, comma-separated (default 0,1)")
    a = ap.parse_args(argv)
    levels = [int(q) for q in a.levels.split(",")]
    design = default_design()
    meta = {"heights_m": list(HEIGHTS_M), "currents_a": list(CURRENTS_A),
            "probes_m": [list(q) for q in PROBES_M], "probe_keys": list(PROBE_KEYS),
            "inputs": fem_inputs(design), "levels": {},
            "what": "factor: dBz/dz of the steel1010 core at I over I x that of the linear core "
                    "at 1 A, on the axis at heights_m above the winding's top (rows: currents_a, "
                    "columns: heights_m); probe_factor: the same ratio of each of probe_keys at "
                    "probes_m (r, height above the top) (currents_a x probes x keys)"}
    res = {}
    for lv in levels:
        t0 = time.perf_counter()
        res[lv] = factors(design, lv)
        meta["levels"][str(lv)] = {"factor": res[lv][0].tolist(),
                                   "probe_factor": res[lv][1].tolist(),
                                   "seconds": round(time.perf_counter() - t0, 1)}
        print(f"level {lv}: axis factors {np.round(res[lv][0], 5).tolist()}, probes "
              f"{np.round(res[lv][1], 4).tolist()}, "
              f"{meta['levels'][str(lv)]['seconds']:.0f} s", flush=True)
    meta["level"] = levels[-1]
    meta["factor"] = res[levels[-1]][0].tolist()
    meta["probe_factor"] = res[levels[-1]][1].tolist()
    if len(levels) > 1:
        a, b = res[levels[-1]], res[levels[-2]]
        meta["change_last_level"] = float(np.max(np.abs(a[0] - b[0])))
        meta["probe_change_last_level"] = float(np.max(np.abs(a[1] - b[1])))
        print(f"change between the two finest levels: axis {meta['change_last_level']:.2e}, "
              f"probes {meta['probe_change_last_level']:.2e}")
    (HERE / "saturation_refs.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
