"""Regenerate the cached FEM references the default tests hold designkit's models to.

Question: what do designkit's own GetDP models (the axisymmetric ``designkit.fem.solve`` and
the 3-D ``designkit.fem.fem3d``) say about the thesis coil with its core (mu_r 1000, 1 A), so
that the tests can check the core, coupling and pull models without running a solver?

Writes ``fem_refs.npz`` next to this file (every array in SI: m, T, T/m, N, H) and
``fem_refs.json`` (the mesh levels, mesh sizes and wall-clock seconds of each case):

- ``axi_*``: axisymmetric FEM, level ``--axi-level`` (default 1): Bz and dBz/dz on the axis at
  12, 20, 30, 50, 80 mm above the winding top; B and dBz/dz at the probe set around one coil
  (``designkit.fem.compare.probe_set``); the inductance (energy and flux linkage).
- ``two_*``: 3-D FEM, two cores at the array pitch, coil 0 at 1 A (fem3d frame: coil 0 at the
  origin), B and grad B at 12 points.
- ``centre_*``: 3-D FEM, the 3 x 3 array with the centre coil at 1 A, B and grad B on the
  5 x 5 workspace grid (150 mm wide) at 12, 20, 30, 50, 80 mm; the design point (0, 0, 30 mm)
  is one of the points.
- ``pull_*``: 3-D FEM, the pull of one core (all coils off) on the 10 x 10 mm magnet at 20, 30,
  50 mm (magnet centre above the winding top).

3-D level ``--level`` (default 0: ~50k tetrahedra per half / quarter model; the README's
numbers are at level 1, which changes B by <= 0.6 % and grad B by <= 1.3 % per point).
Usage: ``PYTHONPATH=$PWD python tests/data/make_fem_refs.py [--level N] [--axi-level N]
[--cases axi,two,pull,centre]`` (needs GetDP; several minutes per 3-D case).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
HEIGHTS_M = (0.012, 0.020, 0.030, 0.050, 0.080)
"""Heights above the coil tops of the axis and workspace points, m."""


def _load() -> tuple[dict, dict]:
    npz, js = HERE / "fem_refs.npz", HERE / "fem_refs.json"
    arrays = dict(np.load(npz)) if npz.exists() else {}
    meta = json.loads(js.read_text()) if js.exists() else {}
    return arrays, meta


def _save(arrays: dict, meta: dict) -> None:
    np.savez_compressed(HERE / "fem_refs.npz", **arrays)
    (HERE / "fem_refs.json").write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")


def axisymmetric(level: int, arrays: dict, meta: dict) -> None:
    """The thesis coil with its linear core, 1 A: axis, probes, inductance."""
    from designkit.model.coil import Coil
    from designkit.design import default_design
    from designkit.fem import solve
    from designkit.fem.compare import probe_set

    coil = Coil.from_design(default_design())
    pts, labels = probe_set(coil)
    res = solve(coil, 1.0, mu_r=1000.0, level=level, probes=pts)
    z = coil.length / 2 + np.asarray(HEIGHTS_M)
    fit = res.axis.fit(z)
    arrays["axi_axis_z_local_m"] = z
    arrays["axi_axis_bz_t"] = np.asarray(fit["bz"])
    arrays["axi_axis_dbz_dz_t_per_m"] = np.asarray(fit["dbz_dz"])
    arrays["axi_probe_rz_m"] = np.asarray(pts, float)
    for k, v in res.probes.items():
        arrays[f"axi_probe_{k}"] = np.asarray(v, float)
    arrays["axi_inductance_energy_h"] = np.array(res.inductance_energy)
    arrays["axi_inductance_linkage_h"] = np.array(res.inductance_linkage)
    meta["axi"] = {"level": level, "mesh": res.mesh_stats, "probe_labels": list(labels),
                   "probe_keys": sorted(res.probes)}


def three_d(name: str, level: int, arrays: dict, meta: dict) -> None:
    """One 3-D case: 'two', 'centre' or 'pull'."""
    from designkit.fem import fem3d

    geo = fem3d.thesis_geometry()
    if name == "pull":
        h, fz = fem3d.magnet_pull_case(level=level)
        arrays["pull_heights_m"], arrays["pull_fz_n"] = np.asarray(h), np.asarray(fz)
        meta["pull"] = {"level": level}
        return
    if name == "two":
        pts = np.array([[x, y, z] for x in (0.0, 0.025, geo["pitch"]) for y in (0.0, 0.02)
                        for z in (0.012, 0.03, 0.06)])
        b, g, res = fem3d.two_cores_case(pts, level=level)
    else:
        pts = fem3d.workspace_points(n_side=5, heights=HEIGHTS_M)
        b, g, res = fem3d.array_case(pts, energized="centre", level=level, timeout_s=7200)
    arrays[f"{name}_points_m"], arrays[f"{name}_b_t"], arrays[f"{name}_g_t_per_m"] = pts, b, g
    meta[name] = {"level": level, "tetrahedra": res.mesh_stats["tetrahedra"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--level", type=int, default=0, help="3-D mesh level")
    ap.add_argument("--axi-level", type=int, default=1, help="axisymmetric mesh level")
    ap.add_argument("--cases", default="axi,two,pull,centre")
    a = ap.parse_args(argv)
    arrays, meta = _load()
    for name in a.cases.split(","):
        t0 = time.perf_counter()
        if name == "axi":
            axisymmetric(a.axi_level, arrays, meta)
        else:
            three_d(name, a.level, arrays, meta)
        meta.setdefault("seconds", {})[name] = round(time.perf_counter() - t0, 1)
        _save(arrays, meta)
        print(f"{name}: {meta['seconds'][name]:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
