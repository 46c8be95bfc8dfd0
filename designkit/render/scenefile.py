"""Compiled scenes: objects + force law + lambda + grids + the map's design hash, one .npz the
runner loads with numpy alone (:class:`firmware_io.scene.Scene`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from firmware_io.scene import scene_arrays

from ..errors import BadInputError
from ..support.atomic import atomic_path
from .objects import OBJECTS, MeshSurface, VirtualObject


def make_object(name: str, **mesh_options) -> VirtualObject:
    """'plane', 'hemisphere', 'half-cylinder', 'wedge' (thesis sizes) or a .stl/.ply path."""
    key = str(name).lower()
    if key in OBJECTS:
        return OBJECTS[key]()
    if Path(name).suffix.lower() in (".stl", ".ply"):
        return MeshSurface.from_file(name, **mesh_options)
    raise BadInputError("OBJECT", f"one of {sorted(OBJECTS)} or a .stl/.ply file", name)


def compile_scene(objects, out, *, lam_n_per_m: float, law, map_design_sha256: str,
                  extra_meta: dict | None = None) -> Path:
    """Write a compiled scene atomically; returns the path.

    objects : a VirtualObject or a list of them; law : ConstraintLaw or PenetrationLaw
    (its lambda is ``lam_n_per_m``, N/m); map_design_sha256 : the map's ``design_sha256``
    (the loader refuses the scene with another map).
    """
    objs = [objects] if isinstance(objects, VirtualObject) else list(objects)
    if not objs or not all(isinstance(o, VirtualObject) for o in objs):
        raise BadInputError("objects", "VirtualObject instances", objects)
    lam = float(lam_n_per_m)
    if not np.isfinite(lam) or lam < 0:
        raise BadInputError("lam_n_per_m", ">= 0 and finite, N/m", lam_n_per_m)
    if not isinstance(map_design_sha256, str) or len(map_design_sha256) != 64:
        raise BadInputError("map_design_sha256", "a 64-hex-digit SHA-256", map_design_sha256)
    metas, arrays = [], {}
    for k, o in enumerate(objs):
        params = {key: (np.asarray(val).tolist() if isinstance(val, (np.ndarray, tuple, list))
                        else val) for key, val in o.params().items()}
        arr = o.arrays()
        metas.append({"kind": o.kind, "type": type(o).__name__, "params": params,
                      "arrays": sorted(arr)})
        for name, a in arr.items():
            arrays[f"obj{k}_{name}"] = np.asarray(a)
    meta = {"lambda_n_per_m": lam, "law": law.meta(), "map_design_sha256": map_design_sha256,
            "units": {"length": "m", "force": "N", "lambda": "N/m"},
            **(extra_meta or {})}
    data = scene_arrays(metas, arrays, meta)
    out = Path(out)
    with atomic_path(out, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **data)
    return out
