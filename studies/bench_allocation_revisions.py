"""Question: does a change to firmware_io.allocation keep its answers and its speed?

The allocation package of a git revision (``--base``, extracted with ``git archive`` into the
output folder and imported under another name) and the working tree's, in one process, on the
problems of studies/bench_allocation.py: every answer compared (the largest difference, A),
then each problem set timed with the two alternating (cold solves on the random mix and on the
design's limits; warm solves along the four 1 kHz paths), the per-problem minimum of
``--passes`` passes; the medians and the median of the per-problem ratios new / base.

    python studies/bench_allocation_revisions.py [OUT_DIR] --base REV [--n N] [--passes P]
"""

from __future__ import annotations

import argparse
import importlib
import io
import subprocess
import sys
import tarfile
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

import firmware_io.allocation as current
from designkit.support.blas import one_blas_thread
from studies import bench_allocation as bench
from studies._common import finish, load_average

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "out" / "bench_allocation_revisions"
"""Default output folder (git-ignored), whatever the working directory."""


def base_package(rev: str, out_dir: Path):
    """firmware_io of ``rev`` as the package ``fio_<rev>`` (its imports are relative)."""
    name = "fio_" + "".join(c for c in rev if c.isalnum())
    dest = out_dir / "revisions"
    if not (dest / name).is_dir():
        blob = subprocess.run(["git", "archive", rev, "firmware_io"], cwd=ROOT, check=True,
                              capture_output=True).stdout
        with tarfile.open(fileobj=io.BytesIO(blob)) as tar:
            tar.extractall(dest / "tmp", filter="data")
        (dest / "tmp" / "firmware_io").rename(dest / name)
    sys.path.insert(0, str(dest))
    return importlib.import_module(name + ".allocation")


def largest_difference(base, problems, paths) -> float:
    """max |I_base - I_now| (A) over cold solves and warm solves along the paths."""
    worst = 0.0
    for fm, f, u, tl, uni in problems:
        xb, _ = base.allocate(fm, f, u, tl, unipolar=uni)
        xn, _ = current.allocate(fm, f, u, tl, unipolar=uni)
        worst = max(worst, float(np.abs(xb - xn).max()))
    for _, probs in paths:
        ab, an = base.Allocator(), current.Allocator()
        for fm, f, u, tl, uni in probs:
            worst = max(worst, float(np.abs(ab(fm, f, u, tl, unipolar=uni)[0]
                                            - an(fm, f, u, tl, unipolar=uni)[0]).max()))
    return worst


def _times(mod, problems, warm: bool) -> np.ndarray:
    t = np.empty(len(problems))
    solve = mod.Allocator() if warm else mod.allocate
    for i, (fm, f, u, tl, uni) in enumerate(problems):
        t0 = time.perf_counter()
        solve(fm, f, u, tl, unipolar=uni)
        t[i] = time.perf_counter() - t0
    return t


def compare(base, problems, warm: bool, passes: int) -> dict:
    """Medians (us) and the median per-problem ratio now / base, alternating passes."""
    tb, tn = [], []
    for _ in range(passes):
        tb.append(_times(base, problems, warm))
        tn.append(_times(current, problems, warm))
    mb, mn = np.minimum.reduce(tb), np.minimum.reduce(tn)
    return {"base_median_us": 1e6 * float(np.median(mb)),
            "now_median_us": 1e6 * float(np.median(mn)),
            "base_p99_us": 1e6 * float(np.percentile(mb, 99)),
            "now_p99_us": 1e6 * float(np.percentile(mn, 99)),
            "ratio_median": float(np.median(mn / mb))}


def run(out_dir=DEFAULT_OUT, *, base: str, n: int = 2000, passes: int = 5) -> dict:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    old = base_package(base, out_dir)
    res = {"base": base, "load_average_1min": load_average(), "passes": passes}
    with one_blas_thread():
        w = bench.wrenches(200)
        sets = {"cold, random mix": (bench.problems(w, n, seed=1), False),
                "cold, design limits": (bench.problems(w, n, seed=2, design_limits=True), False)}
        paths = bench.path_problems(n // 2)
        sets.update({f"warm, {name}": (p, True) for name, p in paths})
        res["largest_difference_a"] = largest_difference(old, sets["cold, random mix"][0]
                                                         + sets["cold, design limits"][0], paths)
        res["timing"] = {name: compare(old, p, warm, passes) for name, (p, warm) in sets.items()}
    return finish(out_dir / "bench_allocation_revisions.json", res, _print)


def _print(res: dict) -> None:
    print(f"allocation: the working tree against {res['base']} (load average "
          f"{res['load_average_1min']}; per-problem minimum of {res['passes']} passes)")
    print(f"largest difference of the answers: {res['largest_difference_a']:.3g} A")
    print(f"{'problems':40s} {'base med':>9s} {'now med':>9s} {'base p99':>9s} "
          f"{'now p99':>9s} {'now/base':>9s}")
    for name, r in res["timing"].items():
        print(f"{name:40s} {r['base_median_us']:9.1f} {r['now_median_us']:9.1f} "
              f"{r['base_p99_us']:9.1f} {r['now_p99_us']:9.1f} {r['ratio_median']:9.3f}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=DEFAULT_OUT)
    ap.add_argument("--base", required=True, help="git revision to compare with")
    ap.add_argument("--n", type=int, default=2000, help="problems per set")
    ap.add_argument("--passes", type=int, default=5)
    a = ap.parse_args()
    run(a.out, base=a.base, n=a.n, passes=a.passes)
