"""Small pieces the study scripts share (not a study itself)."""

from __future__ import annotations

import os
from pathlib import Path

from designkit import default_design, fieldmap
from designkit.support.atomic import write_json_atomic
from designkit.model.array import CoilArray


def design_and_map(out_dir, map_path=None, *, progress: bool = True):
    """Create ``out_dir``; the default design, its CoilArray (one coupled solve) and a map file
    (``map_path``, or one built into ``out_dir/map.npz``). Returns (out_dir, design, array,
    map_path)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    design = default_design()
    array = CoilArray.from_design(design)
    if map_path is None:
        map_path = out_dir / "map.npz"
        fieldmap.write(map_path, fieldmap.build(design, array=array, progress=progress))
    return out_dir, design, array, Path(map_path)


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
