"""Question: does every design of the docs gallery go through the whole chain -- ``check``,
``report --quick``, ``map``, ``cad`` and ``run --simulate --duration 1`` -- with the exit code
each command documents (``check``: 0 every rule holds, 3 a rule violated; the others 0), and
what does each cost and give (map build wall against the same process's 2000 x 2000 matmul,
the parts' totals, the simulated run's force error and localization)?

Each command runs as a user runs it (``python -m designkit ...`` in a fresh process, the
design file from docs/gallery); a traceback on stderr counts as a failure whatever the exit
code. Writes OUT/gallery.json and prints one table a design.

    python studies/gallery.py [OUT_DIR] [--designs NAME ...] [--skip-report]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from studies.bench_map import matmul_s  # noqa: E402

from designkit.support.atomic import write_json_atomic  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
GALLERY = ROOT / "docs" / "gallery"
EXPECTED_EXIT = {"check": (0, 3)}
"""Exit codes that mean the command worked (others: 0)."""


def run(args: list[str], cwd: Path) -> dict:
    """One ``designkit`` command in a fresh process: exit code, wall s, stderr's last line."""
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "designkit", *args], cwd=cwd,
                         capture_output=True, text=True)
    wall = time.perf_counter() - t0
    ok_codes = EXPECTED_EXIT.get(args[0], (0,))
    return {"args": args, "exit": res.returncode, "wall_s": wall,
            "ok": res.returncode in ok_codes and "Traceback" not in res.stderr,
            "stderr_tail": (res.stderr.strip().splitlines() or [""])[-1][:300],
            "stdout_tail": res.stdout.strip().splitlines()[-3:]}


def one_design(name: str, out: Path, report: bool) -> dict:
    """Every command of the chain on docs/gallery/NAME.toml; the numbers they write."""
    design = str(GALLERY / f"{name}.toml")
    d = out / name
    d.mkdir(parents=True, exist_ok=True)
    steps = {"check": run(["check", "--design", design], d)}
    if report:
        steps["report"] = run(["report", "--quick", "--design", design, "--out",
                               str(d / "report"), "--no-progress"], d)
    yard_before = matmul_s()
    steps["map"] = run(["map", "--design", design, "--out", str(d / "map.npz"),
                        "--no-progress"], d)
    yard = 0.5 * (yard_before + matmul_s())
    steps["cad"] = run(["cad", "--design", design, "--out", str(d / "cad")], d)
    steps["run"] = run(["run", "--simulate", "--duration", "1", "--design", design,
                        "--map", str(d / "map.npz"), "--out", str(d / "run"),
                        "--no-progress"], d)
    row = {"design": name, "steps": steps, "matmul_2000_s": yard,
           "map_over_matmul": steps["map"]["wall_s"] / yard}
    parts = d / "cad" / "parts.json"
    if parts.exists():
        row["parts_totals"] = json.loads(parts.read_text()).get("totals")
    summary = d / "run" / "summary.json"
    if summary.exists():
        s = json.loads(summary.read_text())
        row["run"] = {k: s.get(k) for k in (
            "lambda_n_per_m", "force_rms_n", "force_error_rms_n", "force_error_p95_n",
            "localization_mae_m", "running_fraction", "max_current_a")}
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", nargs="?", default=str(ROOT / "out" / "gallery"),
                    help="output folder (default out/gallery)")
    ap.add_argument("--designs", nargs="+", default=None,
                    help="gallery design names (default: every docs/gallery/*.toml)")
    ap.add_argument("--skip-report", action="store_true",
                    help="leave out `report --quick` (the slowest step)")
    a = ap.parse_args(argv)
    names = a.designs or sorted(p.stem for p in GALLERY.glob("*.toml"))
    missing = [n for n in names if not (GALLERY / f"{n}.toml").exists()]
    if missing:
        print(f"error: --designs: {missing} are not in docs/gallery "
              f"({sorted(p.stem for p in GALLERY.glob('*.toml'))})", file=sys.stderr)
        return 1
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    try:
        for name in names:
            row = one_design(name, out, not a.skip_report)
            rows.append(row)
            cells = "  ".join(f"{k} {'ok' if s['ok'] else 'FAILED'} (exit {s['exit']}, "
                              f"{s['wall_s']:.1f} s)" for k, s in row["steps"].items())
            print(f"{name}: {cells}; map / matmul {row['map_over_matmul']:.1f}")
            if "run" in row:
                print(f"  run: {row['run']}")
            for k, s in row["steps"].items():
                if not s["ok"]:
                    print(f"  {k}: {s['stderr_tail']}")
    except KeyboardInterrupt:
        print("interrupted: nothing written", file=sys.stderr)
        return 130
    write_json_atomic(out / "gallery.json", rows)
    print(f"wrote {out / 'gallery.json'}")
    return 0 if all(s["ok"] for r in rows for s in r["steps"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
