"""Small pieces the study scripts share (not a study itself)."""

from __future__ import annotations

import argparse
import sys
import os
from pathlib import Path

import numpy as np

from designkit import default_design, fieldmap
from designkit.support.atomic import write_json_atomic
from designkit.model.array import CoilArray
from firmware_io.mapfile import read

ROOT = Path(__file__).resolve().parents[1]
"""The repository root (the studies' default outputs are under ROOT / 'out')."""


def design_and_map(out_dir, map_path=None, *, progress: bool = True, design=None):
    """Create ``out_dir``; the design (default: the default design), its CoilArray (one
    coupled solve) and a map file (``map_path``, or one built into ``out_dir/map.npz``).
    Returns (out_dir, design, array, map_path)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    design = default_design() if design is None else design
    array = CoilArray.from_design(design)
    if map_path is None:
        map_path = out_dir / "map.npz"
        fieldmap.write(map_path, fieldmap.build(design, array=array, progress=progress))
    return out_dir, design, array, Path(map_path)


def without_saturation(map_path, out) -> Path:
    """A copy of the map at ``out`` with its saturation factor table set to 1 (the runner then
    allocates on the linear columns)."""
    arrays, meta = read(map_path)
    arrays = dict(arrays, SAT_FACTOR=np.ones_like(arrays["SAT_FACTOR"]))
    meta = {k: v for k, v in meta.items() if k != "data_sha256"}
    return fieldmap.write(out, {"arrays": arrays, "meta": meta})


def load_average() -> float | None:
    """1-minute load average (None where the OS has none): timings on a loaded host are
    relative numbers."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return None


def finish(path, result: dict, printer) -> dict:
    """Write ``result`` as JSON to ``path`` (atomically), print it with ``printer`` and return
    it: the last three lines of every study."""
    write_json_atomic(path, result)
    printer(result)
    return result


def run_interruptible(run, *args) -> int:
    """``run(*args)``; exit code 0, or 130 after one line when Ctrl-C stops it (the studies
    write their outputs atomically at the end: nothing is half written)."""
    try:
        run(*args)
    except KeyboardInterrupt:
        print("interrupted: nothing written", file=sys.stderr)
        return 130
    return 0


def study_parser(doc: str, default_out, *, quick: str | None = None) -> argparse.ArgumentParser:
    """The command line the studies share: an optional output folder OUT (``default_out``,
    under out/), ``--quick`` when the study has a short version (``quick``: what it drops),
    ``--help`` from the study's docstring. Studies add their own options to it."""
    ap = argparse.ArgumentParser(description=doc.strip().split("\n\n")[0],
                                 epilog="\n\n".join(doc.strip().split("\n\n")[1:]),
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", nargs="?", type=Path, default=Path(default_out), metavar="OUT",
                    help=f"output folder (default {Path(default_out).relative_to(ROOT)})")
    if quick is not None:
        ap.add_argument("--quick", action="store_true", help=quick)
    return ap
