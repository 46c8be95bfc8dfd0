"""Question: how well does the runner render the thesis' four objects on the simulated device,
and where does the force error come from?

For the flat surface (100 mm square at 50 mm), the hemisphere, the half-cylinder and the wedge,
a finger slides across the object 4 mm below its surface, there and back in 4 s (thesis
Fig. 4.5), with the thesis' constraint law (lambda = the design's 6 N/m) rendered as a 3-D force
and as Fz alone (the thesis' eq. 4.6). designkit.plant closes firmware_io's runner around the
simulated device (exact coupled array physics, R-L coils at 30 V, register-level sensors with
noise and mounting errors). The rendered-force error (true force on the magnet vs the object's
force at the true position) is split into localization, map interpolation, allocation residual
and current lag (designkit.plant.force_error_causes). The thesis reports none of these; its only
number is a participant's 14 mm largest deviation from the flat surface.

    python studies/render_runner.py [OUT_DIR] [--map FILE] [--duration S] [--quick]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from designkit import default_design
from designkit._io import write_json_atomic

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "render_runner"
"""Default output folder (git-ignored), whatever the working directory."""


OBJECTS = ("plane", "hemisphere", "half-cylinder", "wedge")


def run(out_dir=DEFAULT_OUT, *, map_path=None, duration_s: float = 4.0,
        quick: bool = False, objects=OBJECTS, rows=("force", "fz")) -> dict:
    from designkit import fieldmap
    from designkit.array import CoilArray
    from designkit.plant import run_simulation

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    design = default_design()
    array = CoilArray.from_design(design)
    if map_path is None:
        map_path = out_dir / "map.npz"
        fieldmap.write(map_path, fieldmap.build(design, array=array, progress=not quick))
    if quick:
        objects, rows, duration_s = objects[:1], rows[:1], min(duration_s, 0.5)
    res = {}
    for obj in objects:
        for r in rows:
            s = run_simulation(design=design, obj=obj, trajectory="slide", duration_s=duration_s,
                               map_path=map_path, rows=r, out=out_dir / f"{obj}-{r}",
                               progress=False, array=array)
            res[f"{obj}/{r}"] = {k: s[k] for k in (
                "force_error_rms_n", "force_error_p95_n", "object_force_rms_n", "force_lag_s",
                "localization_mae_m", "loop_p50_s", "loop_p99_s", "running_fraction")}
            res[f"{obj}/{r}"]["causes"] = s.get("force_error_causes", {})
    write_json_atomic(out_dir / "render_runner.json", res)
    _print(res)
    return res


def _print(res: dict) -> None:
    print(f"{'object/rows':22s} {'|F| err RMS':>11s} {'p95':>8s} {'object RMS':>10s} "
          f"{'loc. MAE':>9s} {'lag':>6s} | Fz error RMS by cause (mN): loc / map / alloc / lag")
    for k, v in res.items():
        c = v["causes"]

        def mn(x):
            return "  n/a" if x is None else f"{x * 1e3:7.2f}"

        causes = " / ".join(mn(c.get(n, {}).get("fz_rms_n")) for n in
                            ("localization", "map_interpolation", "allocation", "current_lag"))
        print(f"{k:22s} {mn(v['force_error_rms_n'])} mN {mn(v['force_error_p95_n'])} "
              f"{mn(v['object_force_rms_n'])} mN "
              f"{(v['localization_mae_m'] or 0) * 1e3:7.2f} mm {v['force_lag_s'] * 1e3:4.0f} ms | "
              f"{causes}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--map", default=None)
    ap.add_argument("--duration", type=float, default=4.0)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args()
    run(a.out, map_path=a.map, duration_s=a.duration, quick=a.quick)
