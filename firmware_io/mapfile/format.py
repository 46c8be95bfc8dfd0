"""The map file's layout: array names and shapes, writing, reading, validation, version refusal.

A map file is one ``.npz`` archive: the arrays of :func:`array_names` plus ``meta``, a JSON
string (format, version, units, rows, box, the harmonic-cell layers ``a_layers``, the mode and
magnet table descriptions, coil poses, the sensor count, design name and SHA-256, drive data,
build settings and errors). Sensors are a flat list (``n_sensors`` poses, independent of the
coil count). Every array is hashed into ``meta.data_sha256``; :func:`read` refuses anything that is
not a complete, finite, uncorrupted map of this :data:`FORMAT_VERSION`, naming the problem and
how to rebuild. The arrays' meaning: docs/mapfile_format.md.
"""

from __future__ import annotations

import hashlib
import json
import math
import zipfile
from pathlib import Path

import numpy as np

from ..errors import BadInputError
from .drive import DriveRecord

FORMAT = "designkit-fieldmap"
FORMAT_VERSION = 6
"""Format version: A as harmonic cells (coupled A, bias force), the sensors as a flat list of
poses with their fields, the typed drive record (:class:`firmware_io.mapfile.drive.DriveRecord`);
a file of any other version is refused with the command that rebuilds it
(docs/mapfile_format.md lists the versions)."""
ROWS = ("Bx", "By", "Bz", "dBx/dx", "dBx/dy", "dBx/dz", "dBy/dy", "dBy/dz")
"""The eight rows of A(p) (thesis eq. 2.13), defined here once: B (T/A), then the five
independent entries of the symmetric, traceless gradient (T/(m A))."""
UNITS = {"A_rows_0_2": "T/A", "A_rows_3_7": "T/(m A)", "grid": "m", "moment": "A m^2",
         "current": "A", "force": "N", "field": "T", "sensor_coil_field": "T/A"}
REBUILD = ("Rebuild it for this version: designkit map --out <file.npz> (with --design "
           "<design.toml> for a design of your own)")

# name -> (dtype, shape as a function of the sizes); the single list of arrays in a map file
_FIXED = ("SCOEF", "F0_RES", "M_X", "M_Y", "M_Z", "SENSOR_POS", "SENSOR_ROT", "SENSOR_COIL",
          "SENSOR_COIL_GRAD", "MOMENT", "SAT_I", "SAT_FACTOR")
MAX_SENSORS = 4096
"""Most sensors a map describes (a sanity bound on ``meta.n_sensors``)."""


def _shapes(meta: dict, arrays: dict) -> dict:
    nc = int(meta["n_coils"])
    nsen = int(meta["n_sensors"])
    if not 1 <= nsen <= MAX_SENSORS:
        raise ValueError(f"n_sensors {nsen} outside 1..{MAX_SENSORS}")
    mx, my, mz = (len(arrays[k]) for k in ("M_X", "M_Y", "M_Z"))
    nsat = len(arrays["SAT_I"])
    f32, f64 = np.float32, np.float64
    nbs = int(meta["n_sensor_basis"])
    return {"SCOEF": (f64, (nc, nbs, nsen, 3)),
            "F0_RES": (f32, (mx, my, mz, 3)),
            "M_X": (f64, (mx,)), "M_Y": (f64, (my,)), "M_Z": (f64, (mz,)),
            "SENSOR_POS": (f64, (nsen, 3)), "SENSOR_ROT": (f64, (nsen, 3, 3)),
            "SENSOR_COIL": (f64, (nsen, 3, nc)), "SENSOR_COIL_GRAD": (f64, (nsen, 5, nc)),
            "MOMENT": (f64, (3,)), "SAT_I": (f64, (nsat,)), "SAT_FACTOR": (f64, (nsat, nc))}


def array_names(keys) -> list:
    """The arrays of a map in hashing order: the fixed ones present, then AH0, AH1, ...,
    MRZ0, ..., SM0, ..."""
    def tables(prefix):
        n = len(prefix)
        return sorted((k for k in keys if k.startswith(prefix) and k[n:].isdigit()),
                      key=lambda k: int(k[n:]))

    return ([k for k in _FIXED if k in keys] + tables("AH") + tables("MRZ") + tables("SM"))


def data_hash(arrays: dict) -> str:
    """SHA-256 over the arrays of :func:`array_names`, in that order."""
    h = hashlib.sha256()
    for name in array_names(arrays):
        h.update(np.ascontiguousarray(arrays[name]).tobytes())
    return h.hexdigest()


def write(path, arrays: dict, meta: dict) -> Path:
    """Validate, then write ``arrays`` and ``meta`` (``data_sha256`` filled in) to ``path``.

    Not atomic by itself: designkit.fieldmap.write wraps it in an atomic rename.
    """
    meta = dict(meta, data_sha256=data_hash(arrays))
    validate(arrays, meta, path)
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **{k: arrays[k] for k in array_names(arrays)},
                            meta=np.array(json.dumps(meta)))
    return Path(path)


def map_error(path, what: str, hint: str = "") -> BadInputError:
    """The one error of a file that is not a valid map: what it must be, its path, the fix."""
    return BadInputError("map file", f"a designkit map file ({what})", str(path), hint)


def read(path) -> tuple[dict, dict]:
    """Open and validate a map file: ``(arrays, meta)``; BadInputError naming the problem."""
    p = Path(path)
    if not p.is_file():
        raise BadInputError("map file", "a path to an existing .npz map file", str(p))
    with open(p, "rb") as fh:
        magic = fh.read(4)
    if magic != b"PK\x03\x04":  # every .npz is a zip archive; anything else is not a map
        raise map_error(p, "a .npz archive; this file is not one, so it is not a map file",
                   "Make one with: designkit map --design <design.toml> --out <file.npz>")
    try:
        with np.load(p, allow_pickle=False) as z:
            keys = set(z.files)
            if "meta" not in keys:
                raise map_error(p, f"an array 'meta'; found {sorted(keys)} -- a foreign .npz, "
                           "not a map file")
            meta = json.loads(str(z["meta"]))
            arrays = {k: z[k] for k in array_names(keys)}
    except BadInputError:
        raise
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as exc:
        raise map_error(p, f"readable npz; {type(exc).__name__}: {exc} -- truncated or foreign")
    validate(arrays, meta, p)
    return arrays, meta


def validate(arrays: dict, meta: dict, p="<map data>") -> None:
    """Check everything :func:`read` checks on arrays and meta in memory (BadInputError)."""
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise map_error(p, f"meta.format == {FORMAT!r} -- a foreign file")
    version = meta.get("version")
    if version != FORMAT_VERSION:
        when = ("an older" if isinstance(version, int) and version < FORMAT_VERSION
                else "another")
        raise map_error(p, f"format version {FORMAT_VERSION} (A as harmonic cells, sensors as a "
                        f"list of poses, a typed drive record); this file is version "
                        f"{version!r}, written by {when} designkit", REBUILD)
    if meta.get("units") != UNITS or meta.get("rows") != list(ROWS):
        raise map_error(p, f"units {UNITS} and rows {ROWS}")
    try:
        nc = int(meta["n_coils"])
        missing = [k for k in _FIXED if k not in arrays]
        if missing:
            raise map_error(p, f"arrays {list(_FIXED)}; missing {missing}", REBUILD)
        shapes = _shapes(meta, arrays)
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, BadInputError):
            raise
        raise map_error(p, f"complete metadata; {type(exc).__name__}: {exc}")
    for name, (dtype, shape) in shapes.items():
        a = arrays[name]
        if a.shape != shape or a.dtype != dtype:
            raise map_error(p, f"{name} of shape {shape} {np.dtype(dtype).name}; got {a.shape} "
                       f"{a.dtype}")
    try:
        DriveRecord.from_dict(meta.get("drive"), nc)
    except BadInputError as exc:
        raise map_error(p, f"a valid drive record in meta.drive ({exc})", REBUILD) from None
    _validate_layers(arrays, meta, nc, p)
    for key, prefix, nq in (("magnet_tables", "MRZ", NQ_MAGNET),
                            ("sensor_mode_tables", "SM", None)):
        tabs = meta.get(key)
        n_basis = int(meta["n_sensor_basis"])
        if not isinstance(tabs, list) or (not tabs and nq is not None):
            raise map_error(p, f"meta.{key} (a list, non-empty for the magnet tables)")
        covered = []
        for k, t in enumerate(tabs):
            try:
                shape = tuple(t["shape"])
                tab = arrays.get(t["name"])
                if nq is None:  # a mode table: its columns follow from its shapes
                    want = sum(N_MODE_Q[m] for m, _ in t["shapes"])
                    ok_modes = (want == shape[2] and len(t["columns"]) == len(t["shapes"])
                                and len(t["column_scale"]) == want
                                and all(math.isfinite(c) and c > 0 for c in t["column_scale"])
                                and len(t["basis"]) <= n_basis
                                and all(list(b[:2]) in [list(x) for x in t["shapes"]]
                                        and b[2] in (0, 1) for b in t["basis"]))
                else:
                    want, ok_modes = nq, True
                ok = (t["name"] == f"{prefix}{k}" and tab is not None and tab.shape == shape
                      and ok_modes
                      and (tab.dtype == np.float32 or (nq is None and tab.dtype == np.float16))
                      and len(shape) == 3
                      and shape[2] == want
                      and min(shape) >= 2 and t["rho_step_m"] > 0 and t["u_step"] > 0
                      and t["rho_scale_m"] > (shape[0] - 1) * t["rho_step_m"]
                      and len(t["coils"]) > 0 and all(0 <= c < nc for c in t["coils"]))
            except (KeyError, TypeError):
                ok = False
            if not ok:
                raise map_error(p, f"{key}[{k}] describing a float32 array {prefix}{k} (n_rho, n_u, "
                           f"{nq}) for coil indices < {nc}")
            covered += list(t["coils"])
        if nq is not None and sorted(covered) != list(range(nc)):
            raise map_error(p, f"{key}: one table for every coil 0..{nc - 1}; got coils "
                       f"{sorted(covered)}")
    for name in array_names(arrays):
        if not np.all(np.isfinite(arrays[name])):
            raise map_error(p, f"finite values only (found NaN or Inf in {name})")
    for name in ("M_X", "M_Y", "M_Z", "SAT_I"):
        if len(arrays[name]) < 2 or not np.all(np.diff(arrays[name]) > 0):
            raise map_error(p, f"{name} strictly increasing with at least 2 nodes")
    if arrays["SAT_I"][0] != 0 or not np.all(arrays["SAT_FACTOR"] > 0):
        raise map_error(p, "SAT_I starting at 0 A and SAT_FACTOR > 0 (a saturation factor scales "
                        "a column of A)")
    rot = arrays["SENSOR_ROT"]
    if (np.abs(rot @ np.swapaxes(rot, 1, 2) - np.eye(3)).max() > 1e-9
            or np.any(np.linalg.det(rot) < 0)):
        raise map_error(p, "SENSOR_ROT proper rotations (orthonormal, det +1: sensor frame -> array "
                   "frame)")
    if data_hash(arrays) != meta.get("data_sha256"):
        raise map_error(p, "data matching its recorded SHA-256 (corrupted)")


def _validate_layers(arrays: dict, meta: dict, nc: int, p) -> None:
    """The harmonic cells of A: layers stacked without gaps over the box's z range, each grid
    covering the box in x and y, each table AH<k> (nx * ny, (L + 1)^2 - 1, n_coils) float32."""
    layers = meta.get("a_layers")
    try:
        lo, hi = (np.asarray(c, float) for c in meta["box_m"])
        ok = isinstance(layers, list) and len(layers) > 0 and lo.shape == hi.shape == (3,)
        z = float(lo[2]) if ok else 0.0
        tol = 1e-9
        for k, lay in enumerate(layers if ok else []):
            tab = arrays.get(f"AH{k}")
            deg, nx, ny = int(lay["degree"]), int(lay["nx"]), int(lay["ny"])
            hx, hy = float(lay["cell_x_m"]), float(lay["cell_y_m"])
            ok = ok and (lay["name"] == f"AH{k}" and tab is not None and 1 <= deg <= 16
                         and nx >= 1 and ny >= 1 and hx > 0 and hy > 0
                         and tab.dtype == np.float32
                         and tab.shape == (nx * ny, (deg + 1) ** 2 - 1, nc)
                         and abs(float(lay["z_lo_m"]) - z) <= tol
                         and float(lay["z_hi_m"]) > z
                         and lay["x0_m"] <= lo[0] + tol and lay["y0_m"] <= lo[1] + tol
                         and lay["x0_m"] + nx * hx >= hi[0] - tol
                         and lay["y0_m"] + ny * hy >= hi[1] - tol)
            z = float(lay["z_hi_m"])
        ok = ok and abs(z - float(hi[2])) <= tol
        ok = ok and sorted(k for k in arrays if k.startswith("AH")) == sorted(
            f"AH{k}" for k in range(len(layers)))
    except (KeyError, TypeError, ValueError):
        ok = False
    if not ok:
        raise map_error(p, "meta.a_layers: harmonic-cell layers stacked over the box's z range, each "
                   "with a float32 table AH<k> (nx * ny, (degree + 1)^2 - 1, n_coils)")


N_MODE_Q = {0: 4, 1: 5, 2: 5}
"""Quantities per node and shape of a mode table: m = 0 (b = Br/rho, Bz, e = (dBr/dz)/rho,
w = (dBr/drho - Br/rho)/rho^2), m = 1, 2 (the potential x G resp. (x^2 - y^2) H with
G(rho^2, z): a, a1, a2, az, a1z = -mu0 (G, G', G'', G_z, G'_z), ' = d/d(rho^2); the rows they
give: :func:`firmware_io.mapfile.modes.mode_rows`)."""
NQ_MAGNET = 2
"""Quantities per node of a magnet table: F_rho/rho, F_z (N/m, N) of the magnet's pull on one
core alone."""
