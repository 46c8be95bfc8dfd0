"""How long does exporting the full default part set take, and how big are the files?

Question: is ``designkit cad`` on the thesis design (all parts in STL + STEP + 3MF, the
assembly STEP, the assembly PNG, the parts list, with every mesh checked) done within the
60 s target on this machine, where does the time go, and what does the tessellation
tolerance cost in file size and volume error?

Reference run (same process): building the parts alone (the build123d kernel work every
export needs); the table reports the full export as a ratio to it. A tolerance sweep
exports the STL set at three linear deflections and reports total STL size and the worst
relative mesh-volume error, against the area x tolerance bound the checker enforces.

``run(out_dir, quick=True)`` exports STL only at one tolerance without the picture.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from cad.export import export_all  # noqa: E402
from cad.params import from_design  # noqa: E402
from designkit.support.atomic import write_json_atomic  # noqa: E402
from designkit.design import default_design  # noqa: E402


def run(out_dir, quick: bool = False) -> dict:
    # late: the first build below times the one-off build123d import
    from cad.assembly import build_parts

    out = Path(out_dir)
    params = from_design(default_design())

    t = time.perf_counter()
    build_parts(params)  # also pays the one-off build123d import if not yet done
    t_first_build = time.perf_counter() - t
    t = time.perf_counter()
    build_parts(params)
    t_build = time.perf_counter() - t

    formats = ("stl",) if quick else ("stl", "step", "3mf")
    picture = "none" if quick else "png"
    t = time.perf_counter()
    report = export_all(params, out / "full", formats, picture=picture, progress="none")
    t_export = time.perf_counter() - t
    files = report["files"]

    def sweep_row(rep: dict, tol: float, seconds: float) -> dict:
        checked = [r for r in rep["parts"] if "stl" in r.get("checks", {})]
        return {"tolerance_mm": tol, "seconds": seconds,
                "stl_bytes": sum(v for k, v in rep["files"].items() if k.endswith(".stl")),
                "max_rel_volume_error": max(abs(r["checks"]["stl"]["relative_volume_error"])
                                            for r in checked),
                "max_rel_bound": max(r["checks"]["stl"]["volume_bound_mm3"] / r["volume_mm3"]
                                     for r in checked)}

    if quick:  # the full run above already is an STL export at the default tolerance
        sweep = [sweep_row(report, params.printer.tolerance_mm, t_export)]
    else:
        sweep = []
        for tol in (0.005, 0.02, 0.05):
            p = dataclasses.replace(params, printer=dataclasses.replace(params.printer,
                                                                        tolerance_mm=tol))
            t = time.perf_counter()
            rep = export_all(p, out / f"stl_tol_{tol:g}", ("stl",), picture="none",
                             check_interference="no", progress="none")
            sweep.append(sweep_row(rep, tol, time.perf_counter() - t))

    result = {
        "quick": quick, "formats": list(formats),
        "first_build_s": t_first_build, "build_s": t_build, "export_s": t_export,
        "export_over_build": t_export / t_build, "target_s": 60.0,
        "within_target": t_export <= 60.0,
        "stages_s": report["seconds"], "files": files, "total_bytes": sum(files.values()),
        "tolerance_sweep": sweep,
    }
    write_json_atomic(out / "bench_cad.json", result)
    return result


def _table(r: dict) -> str:
    lines = [f"full export ({','.join(r['formats'])}): {r['export_s']:.2f} s "
             f"(target {r['target_s']:.0f} s; {r['export_over_build']:.1f} x the part build "
             f"{r['build_s']:.2f} s; first build incl. import {r['first_build_s']:.2f} s)",
             "stages: " + ", ".join(f"{k} {v:.2f} s" for k, v in r["stages_s"].items()), "",
             f"{'file':<26} {'kB':>9}"]
    lines += [f"{k:<26} {v / 1e3:>9.1f}" for k, v in r["files"].items()]
    lines += [f"{'total':<26} {r['total_bytes'] / 1e3:>9.1f}", "",
              f"{'tol mm':>7} {'s':>6} {'STL kB':>9} {'max |dV|/V':>11} {'bound A*tol/V':>14}"]
    lines += [f"{s['tolerance_mm']:>7g} {s['seconds']:>6.2f} {s['stl_bytes'] / 1e3:>9.1f} "
              f"{s['max_rel_volume_error']:>11.2e} {s['max_rel_bound']:>14.2e}"
              for s in r["tolerance_sweep"]]
    return "\n".join(lines)


if __name__ == "__main__":
    from studies._common import study_parser

    a = study_parser(__doc__, Path(__file__).resolve().parents[1] / "out" / "bench_cad",
                     quick="STL only, one tolerance, no picture").parse_args()
    res = run(a.out, quick=a.quick)
    print(_table(res))
    print(f"\nfiles under {a.out}")
