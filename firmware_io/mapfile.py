"""The map file the controller runs on (format v2): the one definition, numpy and the stdlib only.

``designkit map`` writes it (:mod:`designkit.fieldmap` computes the arrays and wraps
:class:`MapFile`); the runner reads it with this module alone. Everything about the format --
array names, shapes, validation, interpolation -- is defined here and nowhere else.

What the file carries (``.npz``; every array hashed into ``meta.data_sha256``)
------------------------------------------------------------------------------
The coupled actuation matrix A(p), (8, n_coils) per point, rows :data:`ROWS` (T/A, T/(m A)):
column k is coil k alone plus the extra magnetization coil k gives every core (the coupling),
written in the cores' own modes::

    A(p)[:, k] = A_alone_k(p) + sum over cores j and basis fields b of  F_jb(p) COEF[j, b, k]

* ``RZ0``, ``RZ1``, ...: per identical coil type (meta ``rz_tables``), the exact axisymmetric
  field per ampere of one coil alone (winding + its own core magnetized by it alone),
  (n_rho, n_u, 4) float32: the smooth, even-in-rho quantities b = Br/rho, Bz,
  e = (dBr/dz)/rho, w = (dBr/drho - Br/rho)/rho^2 on a grid uniform in
  v = rho / (1 + rho / rho_scale) and u = log(z - z_ref) (z_ref: top of the coil's sources), so
  the steps grow with the distance from the core's rim. Bilinear in (v, u), then Bx = b x,
  By = b y, Bz, dBx/dx = b + w x^2, dBx/dy = w x y, dBx/dz = e x, dBy/dy = b + w y^2,
  dBy/dz = e y in the coil's frame (no division, no special case on the axis).
* ``CM0``, ... (meta ``mode_tables``): per core type, the fields F_b of a few magnetization
  shapes of the core (the SVD of every core's extra magnetization in the coupled solve, per
  azimuthal order m = 0, 1, 2; cos and sin for m >= 1) on the same kind of (v, u) grid: m = 0
  as the coil tables, m = 1, 2 as the potentials x G, y G resp. (x^2 - y^2) H, 2 x y H with
  G, H smooth in (rho^2, z): 5 quantities (a, a1, a2, az, a1z) = -mu0 (G, G', G'', G_z, G'_z)
  give all 8 rows (:func:`mode_rows`); float32 (float16 for the sensor field's), each column
  divided by its largest |value| (meta ``column_scale``). ``COEF`` (n_coils, n_basis, n_coils) float64.

The magnet's interaction with the cores, as functions of the magnet's position p:

* the bias force F0(p), N, on the magnet (moment ``MOMENT``) at zero current (the pull of the
  cores it magnetizes): the sum over the cores of the pull of each core alone, axisymmetric
  about it (``MRZ0``, ... per coil type, meta ``magnet_tables``, (n_rho, n_u, 2) float32:
  F_rho/rho, F_z) plus ``F0_RES`` (mx, my, mz, 3) float32 on the grid ``M_X``, ``M_Y``,
  ``M_Z`` (m, z graded towards the cores), what the cores' interaction adds (trilinear). With
  linear cores the total force is ``F = force_matrix(m) @ (A(p) @ I)[3:] + F0(p)``.
* the field, T, of the cores magnetized by the magnet, at the Hall sensors (upper array then
  lower), as a function of the magnet's position p: by reciprocity (linear cores) component c
  at sensor s is m . B(p) of the cores magnetized by a unit dipole along c at s, a sum of the
  cores' modes (``SM0``, ... meta ``sensor_mode_tables``, their own SVD shapes) with the
  coefficients ``SCOEF`` (n_coils, n_sensor_basis, 2, n_coils, 3).

Constants: ``SENSOR_POS`` (2, n_coils, 3) m; ``SENSOR_COIL`` (2, n_coils, 3, n_coils) T/A, the
coils' (coupled) field at the sensors per ampere; ``MOMENT`` (3,) A m^2; saturation ``SAT_I``
(n_s,) A and ``SAT_FACTOR`` (n_s, n_coils): column k of A is multiplied by the factor at |I_k|
(linear interpolation; 1 for air coils). ``meta``: a JSON string (format, version, units,
rows, coil poses, design name and SHA-256, current limit and total budget, build settings and the
errors measured when the map was built).

Usage::

    m = MapFile.load("fieldmap.npz")
    a = m.actuation((0.0, 0.0, 0.03))            # (8, n_coils)
    f0 = m.bias_force((0.0, 0.0, 0.03))          # (3,) N
    b = m.sensor_induced_field((0.0, 0.0, 0.03))  # (2, n_coils, 3) T
    a = m.actuation(points, rows=(3, 6), coils=(0, 4))  # (n, 2, 2): only those entries

How a lookup runs: every core contributes its coil alone (coefficient 1 on its own column)
and its mode fields as one list of basis fields; each is a bilinear (v, u) lookup times
polynomials in the core-local x, y, and A = rows @ coefficients. One point (:func:`actuation_one`)
does that in ~40 small numpy calls (point as (3,) or (1, 3) alike); blocks of points
(:func:`kernel_rows_many`) in a few large ones. Maps whose coils are rotated, at different
heights or of several types take the general path (:func:`interpolate_rz`, :func:`mode_rows`).
"""

from __future__ import annotations

import bisect
import hashlib
import json
import math
import threading
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import BadInputError

FORMAT = "designkit-fieldmap"
FORMAT_VERSION = 3
"""Format version of map v2 (coupled A, bias force, sensor fields); 1 and 2 were grid-only maps."""
ROWS = ("Bx", "By", "Bz", "dBx/dx", "dBx/dy", "dBx/dz", "dBy/dy", "dBy/dz")
UNITS = {"A_rows_0_2": "T/A", "A_rows_3_7": "T/(m A)", "grid": "m", "moment": "A m^2",
         "current": "A", "force": "N", "field": "T", "sensor_coil_field": "T/A"}
REBUILD = ("Rebuild it for this version: designkit map --design <design.toml> "
           "--out <file.npz>")

# name -> (dtype, shape as a function of the sizes); the single list of arrays in a map file
_FIXED = ("COEF", "SCOEF", "F0_RES", "M_X", "M_Y", "M_Z", "SENSOR_POS", "SENSOR_COIL",
          "MOMENT", "SAT_I", "SAT_FACTOR")


def _shapes(meta: dict, arrays: dict) -> dict:
    nc = int(meta["n_coils"])
    mx, my, mz = (len(arrays[k]) for k in ("M_X", "M_Y", "M_Z"))
    nb = int(meta["n_basis"])
    ns = len(arrays["SAT_I"])
    f32, f64 = np.float32, np.float64
    nbs = int(meta["n_sensor_basis"])
    return {"COEF": (f64, (nc, nb, nc)), "SCOEF": (f64, (nc, nbs, 2, nc, 3)),
            "F0_RES": (f32, (mx, my, mz, 3)),
            "M_X": (f64, (mx,)), "M_Y": (f64, (my,)), "M_Z": (f64, (mz,)),
            "SENSOR_POS": (f64, (2, nc, 3)), "SENSOR_COIL": (f64, (2, nc, 3, nc)),
            "MOMENT": (f64, (3,)), "SAT_I": (f64, (ns,)), "SAT_FACTOR": (f64, (ns, nc))}


def array_names(keys) -> list:
    """The arrays of a map in hashing order: the fixed ones present, then RZ0, RZ1, ...,
    MRZ0, ..., CM0, ..."""
    def tables(prefix):
        n = len(prefix)
        return sorted((k for k in keys if k.startswith(prefix) and k[n:].isdigit()),
                      key=lambda k: int(k[n:]))

    return ([k for k in _FIXED if k in keys] + tables("RZ") + tables("MRZ") + tables("CM")
            + tables("SM"))


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


def _bad(path, what: str, hint: str = "") -> BadInputError:
    return BadInputError("map file", f"a designkit map file ({what})", str(path), hint)


def read(path) -> tuple[dict, dict]:
    """Open and validate a map file: ``(arrays, meta)``; BadInputError naming the problem."""
    p = Path(path)
    if not p.is_file():
        raise BadInputError("map file", "a path to an existing .npz map file", str(p))
    with open(p, "rb") as fh:
        magic = fh.read(4)
    if magic != b"PK\x03\x04":  # every .npz is a zip archive; anything else is not a map
        raise _bad(p, "a .npz archive; this file is not one, so it is not a map file",
                   "Make one with: designkit map --design <design.toml> --out <file.npz>")
    try:
        with np.load(p, allow_pickle=False) as z:
            keys = set(z.files)
            if "meta" not in keys:
                raise _bad(p, f"an array 'meta'; found {sorted(keys)} -- a foreign .npz, "
                           "not a map file")
            meta = json.loads(str(z["meta"]))
            arrays = {k: z[k] for k in array_names(keys)}
    except BadInputError:
        raise
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as exc:
        raise _bad(p, f"readable npz; {type(exc).__name__}: {exc} -- truncated or foreign")
    validate(arrays, meta, p)
    return arrays, meta


def validate(arrays: dict, meta: dict, p="<map data>") -> None:
    """Check everything :func:`read` checks on arrays and meta in memory (BadInputError)."""
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise _bad(p, f"meta.format == {FORMAT!r} -- a foreign file")
    if meta.get("version") != FORMAT_VERSION:
        raise _bad(p, f"format version {FORMAT_VERSION} (map v2: coupled array, bias force, "
                   f"sensor fields); this file is version {meta.get('version')!r}, written "
                   "before v2", REBUILD)
    if meta.get("units") != UNITS or meta.get("rows") != list(ROWS):
        raise _bad(p, f"units {UNITS} and rows {ROWS}")
    try:
        nc = int(meta["n_coils"])
        missing = [k for k in _FIXED if k not in arrays]
        if missing:
            raise _bad(p, f"arrays {list(_FIXED)}; missing {missing}")
        shapes = _shapes(meta, arrays)
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, BadInputError):
            raise
        raise _bad(p, f"complete metadata; {type(exc).__name__}: {exc}")
    for name, (dtype, shape) in shapes.items():
        a = arrays[name]
        if a.shape != shape or a.dtype != dtype:
            raise _bad(p, f"{name} of shape {shape} {np.dtype(dtype).name}; got {a.shape} "
                       f"{a.dtype}")
    for key, prefix, nq in (("rz_tables", "RZ", NQ), ("magnet_tables", "MRZ", NQ_MAGNET),
                            ("mode_tables", "CM", None), ("sensor_mode_tables", "SM", None)):
        tabs = meta.get(key)
        n_basis = int(meta["n_basis" if prefix == "CM" else "n_sensor_basis"])
        if not isinstance(tabs, list) or (not tabs and nq is not None):
            raise _bad(p, f"meta.{key} (a list, non-empty for coil and magnet tables)")
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
                raise _bad(p, f"{key}[{k}] describing a float32 array {prefix}{k} (n_rho, n_u, "
                           f"{nq}) for coil indices < {nc}")
            covered += list(t["coils"])
        if nq is not None and sorted(covered) != list(range(nc)):
            raise _bad(p, f"{key}: one table for every coil 0..{nc - 1}; got coils "
                       f"{sorted(covered)}")
    for name in array_names(arrays):
        if not np.all(np.isfinite(arrays[name])):
            raise _bad(p, f"finite values only (found NaN or Inf in {name})")
    for name in ("M_X", "M_Y", "M_Z", "SAT_I"):
        if len(arrays[name]) < 2 or not np.all(np.diff(arrays[name]) > 0):
            raise _bad(p, f"{name} strictly increasing with at least 2 nodes")
    if data_hash(arrays) != meta.get("data_sha256"):
        raise _bad(p, "data matching its recorded SHA-256 (corrupted)")


# ============================================================================ (rho, z) tables
NQ = 4
"""Quantities per node of a (rho, z) coil table: b, Bz, e, w of the coil alone (winding + its
own core magnetized by it alone), per ampere."""
N_MODE_Q = {0: 4, 1: 5, 2: 5}
"""Quantities per node and shape of a mode table: m = 0 (b, Bz, e, w), m = 1, 2 (a, a1, a2, az,
a1z, see :func:`mode_rows`)."""
NQ_MAGNET = 2
"""Quantities per node of a magnet table: F_rho/rho, F_z (N/m, N) of the magnet's pull on one
core alone."""


def prepare_rz(tables: list, metas: list, positions, rotations) -> list:
    """Per coil type, what :func:`interpolate_rz` and the one-point kernels need."""
    prepared = []
    for tab, m in zip(tables, metas):
        t = _table_constants(tab, m, positions, rotations)
        idx, pos = t["idx"], t["pos"]
        tab32 = np.ascontiguousarray(tab, dtype=np.float32)
        # the one-point kernel reads a cell's 4 corners x NQ quantities as one row
        t64 = tab32.astype(np.float64)
        cells = np.ascontiguousarray(np.stack([t64[:-1, :-1], t64[:-1, 1:], t64[1:, :-1],
                                               t64[1:, 1:]], axis=2).reshape(-1, 4, NQ))
        prepared.append(dict(
            t, all=bool(len(idx) == len(positions) and np.all(idx == np.arange(len(idx)))),
            pos32=pos.astype(np.float32),
            shared_z=t["rot"] is None and bool(np.all(pos[:, 2] == pos[0, 2])),
            nodes=tab32.reshape(-1).view(f"V{4 * NQ}"), cells=cells,
            zr=pos[:, 2] + m["z_ref_m"]))
    return prepared


_WORK = threading.local()
RZ_CHUNK = 2048
"""Points per block of the batch kernels (bounds their scratch memory, keeps it in cache)."""


def _scratch(name: str, size: int, dtype) -> np.ndarray:
    """A reusable per-thread 1-D buffer of at least ``size`` elements (first ``size`` returned).

    Fresh large temporaries cost more than the arithmetic here: each new array above glibc's
    mmap threshold is page-faulted in again on every call (~3x the kernel's time).
    """
    bufs = _WORK.__dict__.setdefault("bufs", {})
    b = bufs.get(name)
    if b is None or b.size < size or b.dtype != dtype:
        b = bufs[name] = np.empty(size, dtype=dtype)
    return b[:size]


def interpolate_rz(prepared: list, p: np.ndarray, nc: int) -> np.ndarray:
    """The batch kernel of the coil tables: points (n, 3) -> rows (nc, 8, n) float32
    (coil-major), rows :data:`ROWS`, of every coil alone.

    Per (point, coil) pair everything is flat and contiguous -- numpy is fast on long inner
    loops and slow on short ones -- and written into reused scratch buffers; a node's 8 float32
    quantities are gathered as one 16-byte element.
    """
    n = len(p)
    whole = np.empty((nc, 8, n), np.float32)
    for s in range(0, n, RZ_CHUNK):
        e = min(n, s + RZ_CHUNK)
        for t in prepared:
            _rz_block(t, p[s:e], whole[:, :, s:e])
    return whole


def _rz_block(t: dict, p: np.ndarray, whole: np.ndarray) -> None:
    """One coil type, one block of points: rows into ``whole`` (nc, 8, n)[idx]."""
    f32 = np.float32
    n, k = len(p), len(t["idx"])
    m = n * k
    x = _scratch("x", m, f32)
    y = _scratch("y", m, f32)
    if t["rot"] is None:
        pf = p.astype(f32)
        np.subtract(pf[:, 0:1], t["pos32"][:, 0], out=x.reshape(n, k))
        np.subtract(pf[:, 1:2], t["pos32"][:, 1], out=y.reshape(n, k))
        if t["shared_z"]:
            z = p[:, 2] - t["zr"][0]
        else:
            z = (p[:, 2:3] - t["zr"]).reshape(m)
    else:
        loc = np.einsum("nki,kij->nkj", p[:, None, :] - t["pos"], t["rot"])
        x[:] = loc[:, :, 0].reshape(m)
        y[:] = loc[:, :, 1].reshape(m)
        z = loc[:, :, 2].reshape(m) - t["z_ref"]
    # u = log(z - z_ref): per point when all coils of the type share a height
    u = np.log(np.maximum(z, 1e-12))
    u -= t["u0"]
    u *= t["inv_du"]
    np.clip(u, 0.0, t["n_u"] - 1.000001, out=u)
    j = u.astype(np.intp)
    tz = (u - j).astype(f32)
    # v = rho / (1 + rho / rho_scale) in steps
    rho = _scratch("rho", m, f32)
    tr = _scratch("tr", m, f32)
    np.multiply(x, x, out=rho)
    np.multiply(y, y, out=tr)
    rho += tr
    np.sqrt(rho, out=rho)
    np.multiply(rho, f32(t["inv_scale"]), out=tr)
    tr += f32(1.0)
    np.divide(rho, tr, out=tr)
    tr *= f32(t["inv_h"])
    np.minimum(tr, f32(t["n_rho"] - 1.0001), out=tr)
    i = _scratch("i", m, np.intp)
    np.copyto(i, tr, casting="unsafe")  # truncation = floor (tr >= 0)
    np.subtract(tr, i, out=tr, casting="unsafe")
    i *= t["n_u"]
    if t["shared_z"]:
        i.reshape(n, k)[:] += j[:, None]
    else:
        i += j
    nodes, n_u = t["nodes"], t["n_u"]
    c = _scratch("c", 4 * m, np.dtype(f"V{4 * NQ}")).reshape(4, m)
    # mode='clip' (indices are in range): with the default 'raise', out= costs a copy
    np.take(nodes, i, out=c[0], mode="clip")
    i += 1
    np.take(nodes, i, out=c[1], mode="clip")
    i += n_u
    np.take(nodes, i, out=c[3], mode="clip")
    i -= 1
    np.take(nodes, i, out=c[2], mode="clip")
    cf = c.view(f32)  # (4, 8 m): per pair the 8 quantities of a corner
    # along u on both rho rows, then along rho with the 8 quantities transposed to rows
    tzb = tz[:, None] if t["shared_z"] else np.repeat(tz, NQ).reshape(m, NQ)
    for lo, hi in ((0, 1), (2, 3)):
        a, b = cf[lo].reshape(n, -1), cf[hi].reshape(n, -1)
        if not t["shared_z"]:
            a, b = a.reshape(m, NQ), b.reshape(m, NQ)
        b -= a
        b *= tzb
        b += a
    q = _scratch("q", NQ * m, f32).reshape(NQ, m)
    lo_t = cf[1].reshape(m, NQ).T
    np.subtract(cf[3].reshape(m, NQ).T, lo_t, out=q)
    q *= tr
    q += lo_t
    rows = _scratch("rows", 8 * m, f32).reshape(1, 8, m)
    wx = _scratch("wx", m, f32)
    for part in range(1):
        bb, bz, e, w = q[4 * part:4 * part + 4]
        r = rows[part]
        # Bx = b x, By = b y, Bz, Gxx = b + w x^2, Gxy = w x y, Gxz = e x, Gyy = b + w y^2,
        # Gyz = e y
        np.multiply(bb, x, out=r[0])
        np.multiply(bb, y, out=r[1])
        r[2] = bz
        np.multiply(w, x, out=wx)
        np.multiply(wx, x, out=r[3])
        r[3] += bb
        np.multiply(wx, y, out=r[4])
        np.multiply(e, x, out=r[5])
        np.multiply(w, y, out=r[6])
        r[6] *= y
        r[6] += bb
        np.multiply(e, y, out=r[7])
    for part, out in ((0, whole),):
        r = rows[part].reshape(8, n, k)
        if t["rot"] is not None:
            r = _rotate_rows(r, t["rot"])
        r = r.transpose(2, 0, 1)
        if t["all"]:
            out[...] = r
        else:
            out[t["idx"]] = r


def _rotate_rows(rows: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Local rows (8, n, k) of coils with rotations (k, 3, 3) -> global rows (8, n, k)."""
    b = rows[:3].astype(np.float64)
    gxx, gxy, gxz, gyy, gyz = rows[3:].astype(np.float64)
    g = np.stack([np.stack([gxx, gxy, gxz]), np.stack([gxy, gyy, gyz]),
                  np.stack([gxz, gyz, -gxx - gyy])])  # (3, 3, n, k)
    bg = np.einsum("kia,ank->ink", rot, b)
    gg = np.einsum("kia,abnk,kjb->ijnk", rot, g, rot)
    return np.stack([bg[0], bg[1], bg[2], gg[0, 0], gg[0, 1], gg[0, 2], gg[1, 1], gg[1, 2]])


# one point: rows (8,) of a part = (b, Bz, e, w) @ M, M (4, 8) = mono @ _POLY with the monomials
# mono = (1, x, y, x x, x y, y x, y y) of the coil-local horizontal offsets
_POLY = np.zeros((7, 4, 8))
_POLY[1, 0, 0] = _POLY[2, 0, 1] = _POLY[0, 0, 3] = _POLY[0, 0, 6] = 1.0  # b: Bx, By, Gxx, Gyy
_POLY[0, 1, 2] = 1.0                                                       # Bz
_POLY[1, 2, 5] = _POLY[2, 2, 7] = 1.0                                      # e: Gxz, Gyz
_POLY[3, 3, 3] = _POLY[4, 3, 4] = _POLY[6, 3, 6] = 1.0                     # w: Gxx, Gxy, Gyy
_POLY = _POLY.reshape(7, 32)


def _rz_one(t: dict, q) -> np.ndarray:
    """One point (3 floats), one coil type: rows (k, 8) float64 of its k coils alone, global
    frame."""
    if t["rot"] is None:
        d = np.subtract(q, t["pos"])
        if t["shared_z"]:
            zz = q[2] - t["zr"][0]
            u = (math.log(zz if zz > 1e-12 else 1e-12) - t["u0"]) * t["inv_du"]
            u = min(max(u, 0.0), t["n_u"] - 1.000001)
            j = int(u)
            tz = u - j
        else:
            u = (np.log(np.maximum(q[2] - t["zr"], 1e-12)) - t["u0"]) * t["inv_du"]
            u = np.clip(u, 0.0, t["n_u"] - 1.000001)
            j = u.astype(np.intp)
            tz = u[:, None]
    else:
        d = np.einsum("ki,kij->kj", np.subtract(q, t["pos"]), t["rot"])
        u = (np.log(np.maximum(d[:, 2] - t["z_ref"], 1e-12)) - t["u0"]) * t["inv_du"]
        u = np.clip(u, 0.0, t["n_u"] - 1.000001)
        j = u.astype(np.intp)
        tz = (u - j)[:, None]
    xy = d[:, :2]
    k = len(xy)
    outer = (xy[:, :, None] * xy[:, None, :]).reshape(k, 4)
    rho = np.sqrt(outer[:, 0] + outer[:, 3])
    vv = np.minimum(rho * t["inv_h"] / (1.0 + rho * t["inv_scale"]), t["n_rho"] - 1.0001)
    i = vv.astype(np.intp)
    tr = (vv - i)[:, None]
    cells = t["cells"][i * (t["n_u"] - 1) + j]  # (k, corner, quantity)
    # bilinear weights of the corners (rho_i, u_j), (rho_i, u_j+1), (rho_i+1, u_j), (.., ..)
    wz = np.concatenate([1.0 - tz, tz], axis=-1) if np.ndim(tz) else np.array([1.0 - tz, tz])
    w = (np.concatenate([1.0 - tr, tr], axis=1)[:, :, None] * wz[..., None, :]).reshape(k, 1, 4)
    val = np.matmul(w, cells)  # (k, 1, 4): b Bz e w
    mono = np.concatenate([np.ones((k, 1)), xy, outer], axis=1)  # (k, 7)
    rows = np.matmul(val, (mono @ _POLY).reshape(k, 4, 8))[:, 0]  # (k, 8) local frame
    if t["rot"] is not None:
        rows = _rotate_rows(rows.T[:, None, :], t["rot"])[:, 0, :].T
    return rows


def prepare_magnet(tables: list, metas: list, positions, rotations) -> list:
    """Per coil type, what :func:`magnet_terms` needs."""
    out = []
    for tab, m in zip(tables, metas):
        out.append(dict(_table_constants(tab, m, positions, rotations),
                        flat=np.ascontiguousarray(tab, dtype=np.float64).reshape(-1, NQ_MAGNET)))
    return out


def _table_constants(tab: np.ndarray, m: dict, positions, rotations) -> dict:
    """What every (v, u) table lookup needs: its coils (idx, pos, rot or None), its size and
    its steps (inverted), from the table and its meta entry."""
    idx = np.asarray(m["coils"], dtype=np.intp)
    rot = np.asarray(rotations, float)[idx]
    return {"idx": idx, "pos": np.asarray(positions, float)[idx],
            "rot": None if np.all(rot == np.eye(3)) else rot,
            "n_rho": tab.shape[0], "n_u": tab.shape[1], "inv_h": 1.0 / m["rho_step_m"],
            "inv_scale": 1.0 / m["rho_scale_m"], "z_ref": m["z_ref_m"], "u0": m["u0"],
            "inv_du": 1.0 / m["u_step"]}


def magnet_terms(prepared: list, p: np.ndarray) -> np.ndarray:
    """The magnet's pull at points (n, 3) summed over the cores, each core alone: (n, 3) N."""
    force = np.zeros((len(p), 3))
    for t in prepared:
        x, y, val = _bilinear(t, p)  # val (n, k, 2): F_rho / rho, F_z
        fl = np.stack([val[..., 0] * x, val[..., 0] * y, val[..., 1]], axis=-1)  # local frame
        if t["rot"] is not None:
            fl = np.einsum("kij,nkj->nki", t["rot"], fl)
        force += fl.sum(axis=1)
    return force


# ============================================================================ coupled core modes
def prepare_modes(tables: list, metas: list, positions, rotations) -> list:
    """Per core type, what :func:`mode_rows` needs."""
    out = []
    for tab, m in zip(tables, metas):
        out.append(dict(_table_constants(tab, m, positions, rotations),
                        flat=(tab.reshape(-1, tab.shape[2]).astype(np.float64)
                              * np.asarray(m["column_scale"], float)),
                        basis=[tuple(b) for b in m["basis"]],
                        col={tuple(s): c for s, c in zip(m["shapes"], m["columns"])}))
        t = out[-1]
        groups, order = [], []
        for key in sorted({(b[0], b[2]) for b in t["basis"]}):
            members = [i for i, b in enumerate(t["basis"]) if (b[0], b[2]) == key]
            cols = np.array([[t["col"][(t["basis"][i][0], t["basis"][i][1])] + q
                              for q in range(N_MODE_Q[key[0]])] for i in members], np.intp)
            groups.append((key, cols))
            order += members
        t["groups"], t["order"] = groups, np.array(order, np.intp)
        _prepare_one(t)
    return out


def _prepare_one(t: dict) -> None:
    """What :func:`mode_rows_one` needs: every group's quantities padded to 5 columns, so one
    GEMM gives all polynomials and one batched matmul all basis rows.

    ``one_src`` / ``one_dst``: scatter of the table's columns into (n_basis, 5 n_groups) per core
    (basis in ``t['order']``); ``one_poly`` (15, 5 n_groups * 8): the groups' :data:`_POLY_T`
    side by side (zero rows for the padding of m = 0's 4 quantities).
    """
    width = 5 * len(t["groups"])
    src, dst = [], []
    poly = np.zeros((15, width, 8))
    s = 0
    for g, ((m, c), cols) in enumerate(t["groups"]):
        poly[:, 5 * g:5 * g + N_MODE_Q[m]] = _POLY_T[(m, c)].reshape(15, N_MODE_Q[m], 8)
        for member in cols:
            src += [int(x) for x in member]
            dst += [s * width + 5 * g + q for q in range(len(member))]
            s += 1
    t["one_src"], t["one_dst"] = np.array(src, np.intp), np.array(dst, np.intp)
    t["one_poly"], t["one_width"], t["one_nb"] = poly.reshape(15, -1), width, s


_POW_X = np.array([0, 1, 0, 2, 1, 0, 3, 2, 1, 0, 4, 3, 2, 1, 0], np.intp)
"""Powers of x, resp. y, of the 15 monomials of :func:`_monomials`."""
_POW_Y = np.array([0, 0, 1, 0, 1, 2, 0, 1, 2, 3, 0, 1, 2, 3, 4], np.intp)
_POW = np.arange(5.0)


def mode_rows_one(t: dict, pq: np.ndarray) -> np.ndarray:
    """:func:`mode_rows` for one point ``pq`` (1, 3) with few numpy calls: (k * n_basis, 8),
    rows of core-major basis fields in ``t['order']`` (the layout of MapFile's coefficients)."""
    if t["rot"] is not None:
        return mode_rows(t, pq).reshape(-1, 8)
    x, y, val = _bilinear(t, pq)
    x, y, val = x[0], y[0], val[0]
    k = len(x)
    mono = (np.power(x[:, None], _POW)[:, _POW_X] * np.power(y[:, None], _POW)[:, _POW_Y])
    poly = (mono @ t["one_poly"]).reshape(k, t["one_width"], 8)
    pad = np.zeros((k, t["one_nb"] * t["one_width"]))
    pad[:, t["one_dst"]] = val[:, t["one_src"]]
    return np.matmul(pad.reshape(k, t["one_nb"], t["one_width"]), poly).reshape(-1, 8)


def _bilinear(t: dict, p: np.ndarray):
    """Local x, y (n, k) and the table quantities (n, k, Q) of a type's k coils at (n, 3)."""
    d = p[:, None, :] - t["pos"][None]
    loc = d if t["rot"] is None else np.einsum("nki,kij->nkj", d, t["rot"])
    x, y = loc[..., 0], loc[..., 1]
    rho = np.sqrt(x * x + y * y)
    vv = np.minimum(rho * t["inv_h"] / (1.0 + rho * t["inv_scale"]), t["n_rho"] - 1.0001)
    u = (np.log(np.maximum(loc[..., 2] - t["z_ref"], 1e-12)) - t["u0"]) * t["inv_du"]
    u = np.clip(u, 0.0, t["n_u"] - 1.000001)
    i, j = vv.astype(np.intp), u.astype(np.intp)
    tr, tz = (vv - i)[..., None], (u - j)[..., None]
    base = i * t["n_u"] + j
    f, nu = t["flat"], t["n_u"]
    lo = f[base]
    lo += tz * (f[base + 1] - lo)
    hi = f[base + nu]
    hi += tz * (f[base + nu + 1] - hi)
    lo += tr * (hi - lo)
    return x, y, lo


def _poly(x: np.ndarray, y: np.ndarray, m: int, c: int) -> np.ndarray:
    """(n, k, Q_m, 8): row r of a basis field = sum over its quantities q of val[q] * P[q, r].

    m = 0: (b, Bz, e, w) -> Bx = b x, By = b y, Bz, Gxx = b + w x^2, Gxy = w x y, Gxz = e x,
    Gyy = b + w y^2, Gyz = e y. m = 1, 2: B = -grad of the potential x G, y G (m = 1 cos, sin)
    or (x^2 - y^2) H, 2 x y H (m = 2), G, H functions of (rho^2, z); the quantities are
    (a, a1, a2, az, a1z) = -mu0 (G, G', G'', G_z, G'_z), ' = d/d(rho^2).
    """
    xx, xy, yy = x * x, x * y, y * y
    P = np.zeros(x.shape + (N_MODE_Q[m], 8))
    if m == 0:
        P[..., 0, 0], P[..., 0, 1], P[..., 0, 3], P[..., 0, 6] = x, y, 1.0, 1.0
        P[..., 1, 2] = 1.0
        P[..., 2, 5], P[..., 2, 7] = x, y
        P[..., 3, 3], P[..., 3, 4], P[..., 3, 6] = xx, xy, yy
    elif m == 1 and c == 0:
        P[..., 0, 0] = 1.0
        P[..., 1, 0], P[..., 1, 1], P[..., 1, 3], P[..., 1, 4], P[..., 1, 6] = (
            2 * xx, 2 * xy, 6 * x, 2 * y, 2 * x)
        P[..., 2, 3], P[..., 2, 4], P[..., 2, 6] = 4 * x * xx, 4 * xx * y, 4 * x * yy
        P[..., 3, 2], P[..., 3, 5] = x, 1.0
        P[..., 4, 5], P[..., 4, 7] = 2 * xx, 2 * xy
    elif m == 1:
        P[..., 0, 1] = 1.0
        P[..., 1, 0], P[..., 1, 1], P[..., 1, 3], P[..., 1, 4], P[..., 1, 6] = (
            2 * xy, 2 * yy, 2 * y, 2 * x, 6 * y)
        P[..., 2, 3], P[..., 2, 4], P[..., 2, 6] = 4 * xx * y, 4 * x * yy, 4 * y * yy
        P[..., 3, 2], P[..., 3, 7] = y, 1.0
        P[..., 4, 5], P[..., 4, 7] = 2 * xy, 2 * yy
    elif c == 0:
        pp = xx - yy
        P[..., 0, 0], P[..., 0, 1], P[..., 0, 3], P[..., 0, 6] = 2 * x, -2 * y, 2.0, -2.0
        P[..., 1, 0], P[..., 1, 1], P[..., 1, 3], P[..., 1, 6] = (
            2 * x * pp, 2 * y * pp, 8 * xx + 2 * pp, 2 * pp - 8 * yy)
        P[..., 2, 3], P[..., 2, 4], P[..., 2, 6] = 4 * xx * pp, 4 * xy * pp, 4 * yy * pp
        P[..., 3, 2], P[..., 3, 5], P[..., 3, 7] = pp, 2 * x, -2 * y
        P[..., 4, 5], P[..., 4, 7] = 2 * x * pp, 2 * y * pp
    else:
        qq = 2 * xy
        P[..., 0, 0], P[..., 0, 1], P[..., 0, 4] = 2 * y, 2 * x, 2.0
        P[..., 1, 0], P[..., 1, 1], P[..., 1, 3], P[..., 1, 4], P[..., 1, 6] = (
            2 * x * qq, 2 * y * qq, 12 * xy, 4 * (xx + yy), 12 * xy)
        P[..., 2, 3], P[..., 2, 4], P[..., 2, 6] = 4 * xx * qq, 4 * xy * qq, 4 * yy * qq
        P[..., 3, 2], P[..., 3, 5], P[..., 3, 7] = qq, 2 * y, 2 * x
        P[..., 4, 5], P[..., 4, 7] = 2 * x * qq, 2 * y * qq
    return P


def _monomials(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(..., 15): 1, x, y, x^2, x y, y^2, x^3, x^2 y, x y^2, y^3, x^4, x^3 y, x^2 y^2,
    x y^3, y^4."""
    xx, yy = x * x, y * y
    return np.stack([np.ones_like(x), x, y, xx, x * y, yy, xx * x, xx * y, x * yy, yy * y,
                     xx * xx, xx * x * y, xx * yy, x * yy * y, yy * yy], axis=-1)


def _poly_tensors() -> dict:
    """_poly as constant tensors on the monomials: P = monomials @ T[(m, c)] (15, Q_m * 8).

    _poly is a polynomial of degree <= 4 in (x, y), so evaluating it at 40 random points and
    solving for the 15 monomial coefficients is exact up to rounding (checked)."""
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-1, 1, (2, 40))
    mono = _monomials(x, y)
    out = {}
    for key in ((0, 0), (1, 0), (1, 1), (2, 0), (2, 1)):
        p = _poly(x, y, *key).reshape(40, -1)
        t = np.linalg.lstsq(mono, p, rcond=None)[0]
        t[np.abs(t) < 1e-9] = 0.0
        t = np.round(t)  # the coefficients are small integers
        assert np.allclose(mono @ t, p, atol=1e-12)
        out[key] = t
    return out


def mode_rows(t: dict, p: np.ndarray, rows=None) -> np.ndarray:
    """Rows (n, k, n_basis, 8) of every basis field of the type's k cores at points (n, 3),
    global frame, basis in the order of ``t['order']`` (grouped by mode order and cos / sin;
    :func:`prepare_modes` permutes the coefficients to match). ``rows``: indices into
    :data:`ROWS` to compute only those (last axis len(rows)); not with rotated coils."""
    if rows is not None and t["rot"] is not None:
        return mode_rows(t, p)[..., rows]
    x, y, val = _bilinear(t, p)
    n, k = x.shape
    mono = _monomials(x, y).reshape(n * k, 15)
    nr = 8 if rows is None else len(rows)
    parts = []
    for (m, c), cols in t["groups"]:
        v = val[..., cols]  # (n, k, nb_g, Q_m)
        tens = _POLY_T[(m, c)]
        if rows is not None:
            tens = tens.reshape(15, N_MODE_Q[m], 8)[:, :, rows].reshape(15, -1)
        pm = (mono @ tens).reshape(n, k, 1, N_MODE_Q[m], nr)  # one GEMM
        # a sum over the 4-5 quantities: numpy's batched matmul is slow on tiny matrices
        acc = v[..., 0, None] * pm[..., 0, :]
        for q in range(1, v.shape[-1]):
            acc += v[..., q, None] * pm[..., q, :]
        parts.append(acc)  # (n, k, nb_g, nr)
    out = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=2)
    if t["rot"] is not None:
        flat = out.transpose(3, 0, 2, 1).reshape(8, -1, k)
        out = _rotate_rows(flat, t["rot"]).reshape(8, n, -1, k).transpose(1, 3, 2, 0)
    return out


_POLY_T = _poly_tensors()


# ============================================================================ one-point kernels
# One point through the whole sum in ~40 small numpy calls (each ~0.3-1 us: the call, not the
# arithmetic, is the cost): every core's coil table and mode table looked up with one gather
# of the 4 corners and one matmul for the weights; the coil alone as one more "mode" whose
# coefficient is 1 on its own column, so all polynomials are one GEMM and the sum one GEMV.
_POLY15 = np.zeros((15, 5, 8))
"""The coil tables' :data:`_POLY` on the 15 monomials of :func:`_monomials` (padded to 5
quantities like the mode groups)."""
for _r15, _r7 in ((0, 0), (1, 1), (2, 2), (3, 3), (4, 4), (4, 5), (5, 6)):
    _POLY15[_r15, :NQ] += _POLY.reshape(7, NQ, 8)[_r7]


def _lookup(t: dict, flat: np.ndarray) -> dict | None:
    """A table of a prepared type as :func:`_interp_one` reads it; None unless its coils are
    unrotated at one height (then z and u are scalars)."""
    pos = np.asarray(t["pos"], float)
    if t["rot"] is not None or not np.all(pos[:, 2] == pos[0, 2]):
        return None
    nu = t["n_u"]
    return {"flat": np.ascontiguousarray(flat, dtype=np.float64), "n_u": nu,
            "inv_h": t["inv_h"], "inv_scale": t["inv_scale"], "vmax": t["n_rho"] - 1.0001,
            "zr0": float(pos[0, 2] + t["z_ref"]), "u0": t["u0"], "inv_du": t["inv_du"],
            "umax": nu - 1.000001, "off4": np.array([0, 1, nu, nu + 1], np.intp)}


def _interp_one(L: dict, rho: np.ndarray, zq: float) -> np.ndarray:
    """Bilinear in (v, u) at one height ``zq`` (global, m) for every coil's rho (k,) m:
    (k, Q) float64, the same cells and weights as the batch kernels."""
    vv = rho * L["inv_h"]
    vv /= rho * L["inv_scale"] + 1.0
    np.minimum(vv, L["vmax"], out=vv)
    i = vv.astype(np.intp)
    vv -= i
    zz = zq - L["zr0"]
    u = (math.log(zz if zz > 1e-12 else 1e-12) - L["u0"]) * L["inv_du"]
    u = min(max(u, 0.0), L["umax"])
    j = int(u)
    tz = u - j
    sz = 1.0 - tz
    corners = L["flat"][(i * L["n_u"] + j)[:, None] + L["off4"]]  # (k, 4, Q)
    w = np.multiply.outer(vv, (-sz, -tz, sz, tz))
    w += (sz, tz, 0.0, 0.0)
    return np.matmul(w[:, None, :], corners)[:, 0]


def prepare_one(rz: tuple, modes: tuple, coefs: tuple, nc: int,
                moment=None) -> dict | None:
    """The one-point kernel's constants for a sum of coil tables ``rz`` (the coils alone: one
    more basis field per core with coefficient 1 on its own column; ``()`` for none) and mode
    tables with coefficients ``coefs`` ((k * n_basis, n_out) per type, MapFile's layout).
    With ``moment`` (3,) A m^2 the kernel gives m . B per basis field instead of the 8 rows
    (the sensor fields). None: the general path is used (several types, rotated coils or
    coils at different heights)."""
    if len(rz) > 1 or len(modes) > 1 or (rz and not rz[0]["all"]) or not (rz or modes):
        return None
    first = rz[0] if rz else modes[0]
    lrz = _lookup(rz[0], rz[0]["nodes"].view(np.float32).reshape(-1, NQ)) if rz else None
    if rz and lrz is None:
        return None
    n_out = coefs[0].shape[1] if modes else nc
    n_self = NQ if rz else 0
    src, dst, poly = [np.arange(n_self)], [np.arange(n_self)], [_POLY15[:, :n_self]]
    if modes:
        mt = modes[0]
        if not np.array_equal(mt["idx"], first["idx"]):
            return None
        lcm = _lookup(mt, mt["flat"])
        if lcm is None:
            return None
        nb, width = mt["one_nb"], mt["one_width"]
        shift = 1 if rz else 0  # basis 0: the coil alone
        src.append(n_self + mt["one_src"])
        dst.append((mt["one_dst"] // width + shift) * (width + n_self)
                   + n_self + mt["one_dst"] % width)
        poly.append(mt["one_poly"].reshape(15, width, 8))
        cm = coefs[0].reshape(len(mt["idx"]), nb, n_out)
    else:
        lcm, nb, width = None, 0, 0
        cm = np.zeros((nc, 0, nc))
    poly = np.concatenate(poly, axis=1)
    if moment is not None:
        poly = poly[..., :3] @ np.asarray(moment, float)
    # on all 25 products x^a y^b (a, b <= 4): those of degree > 4 get zero rows
    poly25 = np.zeros((5, 5) + poly.shape[1:])
    poly25[_POW_X, _POW_Y] = poly
    coef = (np.concatenate([np.eye(nc)[:, None, :], cm], axis=1) if rz else cm)
    src, dst = np.concatenate(src), np.concatenate(dst)
    # for the batch kernel: the basis fields grouped by the block of polynomials they use
    # (the coil alone, then each mode order and cos / sin), values unpadded
    tw = width + n_self
    blocks: dict = {}
    for b in np.unique(dst // tw):
        sel = dst // tw == b
        cols = dst[sel] % tw
        blocks.setdefault(int(cols.min()), []).append((int(b), src[sel][np.argsort(cols)]))
    groups = [(start, len(mem[0][1]), np.array([b for b, _ in mem], np.intp),
               np.array([v for _, v in mem], np.intp)) for start, mem in sorted(blocks.items())]
    return {"pos": first["pos"], "rz": lrz, "cm": lcm, "src": src, "dst": dst,
            "poly": np.ascontiguousarray(poly25.reshape(25, -1)),
            "nb": nb + (1 if rz else 0), "width": tw, "groups": groups,
            "n_rows": 1 if moment is not None else 8,
            "coef": np.ascontiguousarray(coef.reshape(-1, n_out))}


def actuation_one(F: dict, q) -> np.ndarray:
    """One point ``q`` (3 floats, m): rows (k * (n_basis + 1), 8) of every core's coil-alone
    field and basis fields; A (8, nc) = rows.T @ F['coef'] (see :func:`prepare_one`)."""
    d = np.subtract(q, F["pos"])
    x, y = d[:, 0], d[:, 1]
    rho = np.sqrt(x * x + y * y)
    if F["rz"] is None:
        val = _interp_one(F["cm"], rho, q[2])
    else:
        val = _interp_one(F["rz"], rho, q[2])
        if F["cm"] is not None:
            val = np.concatenate([val, _interp_one(F["cm"], rho, q[2])], axis=1)
    k = len(x)
    pw = np.power(d[:, :2, None], _POW)  # (k, 2, 5): powers 0..4 of x and y
    poly = ((pw[:, 0, :, None] * pw[:, 1, None, :]).reshape(k, 25) @ F["poly"]
            ).reshape(k, F["width"], F["n_rows"])
    pad = np.zeros((k, F["nb"] * F["width"]))
    pad[:, F["dst"]] = val[:, F["src"]]
    return np.matmul(pad.reshape(k, F["nb"], F["width"]), poly).reshape(-1, F["n_rows"])


def _interp_many(L: dict, rho: np.ndarray, z: np.ndarray) -> np.ndarray:
    """:func:`_interp_one` for points (m,) at heights ``z`` (m,) m, rho (m, k) m: (m, k, Q)."""
    vv = rho * L["inv_h"]
    vv /= rho * L["inv_scale"] + 1.0
    np.minimum(vv, L["vmax"], out=vv)
    i = vv.astype(np.intp)
    vv -= i
    u = np.log(np.maximum(z - L["zr0"], 1e-12))
    u -= L["u0"]
    u *= L["inv_du"]
    np.clip(u, 0.0, L["umax"], out=u)
    j = u.astype(np.intp)
    tz = (u - j)[:, None, None]
    f, nu = L["flat"], L["n_u"]
    base = i * nu + j[:, None]
    lo = f[base]
    lo += tz * (f[base + 1] - lo)
    base += nu
    hi = f[base]
    hi += tz * (f[base + 1] - hi)
    hi -= lo
    hi *= vv[..., None]
    hi += lo
    return hi


BATCH_CHUNK = 256
"""Points per block of :func:`kernel_rows_many` (~k * 1.5 k floats of temporaries per point:
small blocks stay in cache)."""


def kernel_rows_many(F: dict, p: np.ndarray, rows=None) -> np.ndarray:
    """:func:`actuation_one` for points (m, 3): (m, nr, k * n_basis) -- the basis fields' rows
    (all 8, or ``rows``), transposed for one GEMM with ``F['coef']``."""
    m = len(p)
    d = p[:, None, :] - F["pos"]  # (m, k, 3)
    k = d.shape[1]
    x, y = d[..., 0], d[..., 1]
    rho = np.sqrt(x * x + y * y)
    if F["rz"] is None:
        val = _interp_many(F["cm"], rho, p[:, 2])
    else:
        val = _interp_many(F["rz"], rho, p[:, 2])
        if F["cm"] is not None:
            val = np.concatenate([val, _interp_many(F["cm"], rho, p[:, 2])], axis=2)
    nr = F["n_rows"] if rows is None else len(rows)
    poly_t = F["poly"] if rows is None else (
        F["poly"].reshape(25, F["width"], 8)[:, :, rows].reshape(25, -1))
    pw = np.empty((m, k, 2, 5))  # powers 0..4 of x and y (products: np.power is slow)
    pw[..., 0] = 1.0
    pw[..., 1] = d[..., :2]
    for e in range(2, 5):
        np.multiply(pw[..., e - 1], pw[..., 1], out=pw[..., e])
    mono = (pw[..., 0, :, None] * pw[..., 1, None, :]).reshape(m * k, 25)
    poly = (mono @ poly_t).reshape(m * k, F["width"], nr)
    # per block of polynomials, its basis fields' values (m k, n_g, Q) @ (m k, Q, nr)
    out = np.empty((m * k, F["nb"], nr))
    flat = val.reshape(m * k, -1)
    for start, nq, basis, cols in F["groups"]:
        out[:, basis] = np.matmul(flat[:, cols], poly[:, start:start + nq])
    return out.reshape(m, k * F["nb"], nr).transpose(0, 2, 1)


# ============================================================================ 3-D grids
def _cells(axis: np.ndarray, x: np.ndarray):
    """Cell index (n,) and local coordinate t (n,) of ``x`` on a strictly increasing axis;
    outside, the end cell with t < 0 or > 1 (linear extrapolation)."""
    i = np.clip(np.searchsorted(axis, x, side="right") - 1, 0, len(axis) - 2)
    return i, (x - axis[i]) / (axis[i + 1] - axis[i])


def _trilinear(grid: tuple, p: np.ndarray) -> np.ndarray:
    """Trilinear interpolation of ``values`` (nx * ny * nz, q) at points (n, 3) -> (n, q)."""
    axes, values, shape = grid
    ny, nz = shape[1], shape[2]
    ix, tx = _cells(axes[0], p[:, 0])
    iy, ty = _cells(axes[1], p[:, 1])
    iz, tz = _cells(axes[2], p[:, 2])
    base = (ix * ny + iy) * nz + iz
    ux, uy, uz = 1.0 - tx, 1.0 - ty, 1.0 - tz
    out = np.zeros((len(p), values.shape[1]), values.dtype)
    for off, w in ((0, ux * uy * uz), (1, ux * uy * tz), (nz, ux * ty * uz),
                   (nz + 1, ux * ty * tz), (ny * nz, tx * uy * uz), (ny * nz + 1, tx * uy * tz),
                   (ny * nz + nz, tx * ty * uz), (ny * nz + nz + 1, tx * ty * tz)):
        corner = np.take(values, base + off, axis=0)
        corner *= w.astype(values.dtype)[:, None]
        out += corner
    return out


def _trilinear_one(grid: tuple, q) -> np.ndarray:
    """The same for one point (3 floats) -> (q,), with Python scalars for the index work."""
    axes, values, shape = grid
    xs, ys, zs = grid_lists(grid)
    i = min(max(bisect.bisect_right(xs, q[0]) - 1, 0), len(xs) - 2)
    j = min(max(bisect.bisect_right(ys, q[1]) - 1, 0), len(ys) - 2)
    k = min(max(bisect.bisect_right(zs, q[2]) - 1, 0), len(zs) - 2)
    tx = (q[0] - xs[i]) / (xs[i + 1] - xs[i])
    ty = (q[1] - ys[j]) / (ys[j + 1] - ys[j])
    tz = (q[2] - zs[k]) / (zs[k + 1] - zs[k])
    ux, uy, uz = 1.0 - tx, 1.0 - ty, 1.0 - tz
    w = np.array([ux * uy * uz, ux * uy * tz, ux * ty * uz, ux * ty * tz,
                  tx * uy * uz, tx * uy * tz, tx * ty * uz, tx * ty * tz], dtype=values.dtype)
    block = values.reshape(shape + (-1,))[i:i + 2, j:j + 2, k:k + 2].reshape(8, -1)
    return w @ block


_LISTS: dict = {}


def grid_lists(grid: tuple) -> tuple:
    key = id(grid[0])
    got = _LISTS.get(key)
    if got is None or got[0] is not grid[0]:
        got = _LISTS[key] = (grid[0], tuple(ax.tolist() for ax in grid[0]))
    return got[1]


# ============================================================================ the reader
def check_currents(currents, n_coils: int, error=BadInputError) -> np.ndarray:
    """``currents`` as a float array (n_coils,) A, or ``error`` (an InputRangeError class: the
    caller's own, e.g. designkit's BadInputError) naming the parameter and the shape."""
    i = np.asarray(currents, dtype=float)
    if i.shape != (n_coils,) or not np.all(np.isfinite(i)):
        raise error("currents", f"{n_coils} finite values, A", f"shape {i.shape}")
    return i


def _interp_factor(currents, sat_i, sat_f) -> np.ndarray:
    """Saturation factors (n_coils,) at the magnitudes of ``currents`` (clamped to the table)."""
    a = np.abs(np.asarray(currents, float))
    return np.array([np.interp(a[k], sat_i, sat_f[:, k]) for k in range(sat_f.shape[1])])


@dataclass(frozen=True, eq=False)
class MapFile:
    """A validated map file (see the module docstring for what each part means).

    Attributes: ``meta`` (dict), ``bounds`` ((lower, upper) corners of the box, m), ``n_coils``,
    ``sensor_positions_m`` (2, n_coils, 3), ``moment_a_m2`` (3,), ``design_sha256``,
    ``max_current_a`` (per coil), ``total_current_a`` (sum of |I|), ``arrays`` (the raw arrays).
    """

    arrays: dict
    meta: dict
    bounds: tuple
    n_coils: int
    kernels: dict = field(repr=False)
    """The prepared lookups: 'rz', 'modes', 'coef', 'scoef', 'magnet', 'magnet_f0' and the
    one-point kernels 'one', 'sensor_one', 'magnet_one' (None where the general path runs)."""

    @classmethod
    def load(cls, path, expected_design_sha256: str | None = None) -> "MapFile":
        """Read and validate ``path``; with ``expected_design_sha256``, refuse another
        design's map."""
        arrays, meta = read(path)
        if expected_design_sha256 is not None and meta["design_sha256"] != expected_design_sha256:
            raise _bad(path, f"built from the design with SHA-256 {expected_design_sha256[:12]}"
                       f"...; this one is from design {meta.get('design_name')!r} "
                       f"({meta['design_sha256'][:12]}...)", REBUILD)
        return cls.from_arrays(arrays, meta)

    @classmethod
    def from_arrays(cls, arrays: dict, meta: dict) -> "MapFile":
        """A MapFile from already validated arrays (what :func:`read` returns)."""
        nc = int(meta["n_coils"])
        tabs = meta["rz_tables"]
        rz = prepare_rz([arrays[t["name"]] for t in tabs], tabs, meta["coil_positions_m"],
                         meta["coil_rotations"])
        mtabs = meta["mode_tables"]
        modes = prepare_modes([arrays[t["name"]] for t in mtabs], mtabs,
                              meta["coil_positions_m"], meta["coil_rotations"])
        coef = arrays["COEF"]
        # per type: COEF rows of its cores and its basis, laid out (k * n_basis, nc)
        coefs = tuple(np.ascontiguousarray(coef[t["idx"]][:, t["order"]].reshape(-1, nc))
                      for t in modes)
        stabs = meta["sensor_mode_tables"]
        smodes = prepare_modes([arrays[t["name"]] for t in stabs], stabs,
                               meta["coil_positions_m"], meta["coil_rotations"])
        sc = arrays["SCOEF"]
        scoefs = tuple((t, np.ascontiguousarray(sc[t["idx"]][:, t["order"]]
                                                .reshape(-1, 6 * nc))) for t in smodes)
        maxes = tuple(np.asarray(arrays[k], float) for k in ("M_X", "M_Y", "M_Z"))
        f0 = arrays["F0_RES"]
        mt = meta["magnet_tables"]
        magnet = prepare_magnet([arrays[t["name"]] for t in mt], mt, meta["coil_positions_m"],
                                meta["coil_rotations"])
        g = meta["box_m"]
        kernels = {
            "rz": tuple(rz), "modes": tuple(modes), "coef": coefs, "scoef": scoefs,
            "magnet": tuple(magnet),
            "magnet_f0": (maxes, np.ascontiguousarray(f0.reshape(-1, 3)), f0.shape[:3]),
            "one": prepare_one(rz, modes, coefs, nc),
            "sensor_one": (prepare_one((), smodes, tuple(c for _, c in scoefs), nc,
                                       arrays["MOMENT"]) if smodes else None),
            "magnet_one": _lookup(magnet[0], magnet[0]["flat"]) if len(magnet) == 1 else None}
        return cls(arrays, meta, (np.asarray(g[0], float), np.asarray(g[1], float)), nc,
                   kernels)

    # ------------------------------------------------------------------ plain attributes
    @property
    def sensor_positions_m(self) -> np.ndarray:
        """(2, n_coils, 3) m: upper array then lower array, one sensor per coil centre."""
        return self.arrays["SENSOR_POS"].copy()

    @property
    def moment_a_m2(self) -> np.ndarray:
        """The finger magnet's moment (3,) A m^2 the map's bias force was computed for."""
        return self.arrays["MOMENT"].copy()

    @property
    def design_sha256(self) -> str:
        return self.meta["design_sha256"]

    @property
    def max_current_a(self) -> float:
        """Per-coil current limit, A."""
        return float(self.meta["max_current_a"])

    @property
    def total_current_a(self) -> float:
        """Budget on the sum of |I_k| over the coils, A."""
        return float(self.meta["total_current_a"])

    # ------------------------------------------------------------------ point checks
    def _points(self, points, extrapolate: bool, name: str = "points"):
        """(p (n, 3) float64, single) after the shape, finiteness and box checks."""
        p = np.asarray(points, dtype=float)
        single = p.ndim == 1
        if p.shape[-1:] != (3,) or p.ndim > 2:
            raise BadInputError(name, "array-like of shape (3,) or (n, 3), m",
                                f"shape {p.shape}")
        p = p.reshape(-1, 3)
        if not np.all(np.isfinite(p)):
            raise BadInputError(name, "finite (no NaN or Inf)", p.tolist()[:3])
        if not extrapolate:
            lo, hi = self.bounds
            tol = 1e-9
            bad = np.any((p < lo - tol) | (p > hi + tol), axis=1)
            if bad.any():
                k = int(np.argmax(bad))
                raise BadInputError(name, f"inside the map box {lo.tolist()} .. {hi.tolist()} m"
                                    " (or extrapolate=True)", f"{p[k].tolist()} at row {k}")
        return p, single

    def _one_point(self, points, extrapolate: bool, name: str = "points"):
        """Three Python floats, or None when ``points`` is not one point."""
        try:
            arr = np.asarray(points, dtype=float)
        except (TypeError, ValueError):
            raise BadInputError(name, "array-like of shape (3,) or (n, 3), m",
                                points) from None
        if arr.shape != (3,) and arr.shape != (1, 3):
            return None
        q = arr.reshape(3).tolist()
        lo, hi = self._box_lists
        for k in range(3):
            if not math.isfinite(q[k]):
                raise BadInputError(name, "finite (no NaN or Inf)", q)
            if not extrapolate and not (lo[k] <= q[k] <= hi[k]):
                raise BadInputError(name, f"inside the map box {self.bounds[0].tolist()} .. "
                                    f"{self.bounds[1].tolist()} m (or extrapolate=True)", q)
        return q

    @property
    def _box_lists(self) -> tuple:
        """The box corners as Python floats widened by the 1e-9 m tolerance."""
        got = self.__dict__.get("_box_cache")
        if got is None:
            got = ([float(v) - 1e-9 for v in self.bounds[0]],
                   [float(v) + 1e-9 for v in self.bounds[1]])
            object.__setattr__(self, "_box_cache", got)
        return got

    # ------------------------------------------------------------------ the interpolators
    def _subset(self, name: str, sel, n: int):
        """None (all) or an index array (m,) for the ``rows=`` / ``coils=`` keywords."""
        if sel is None:
            return None
        try:
            idx = np.asarray(sel)
            ok = idx.ndim == 1 and len(idx) > 0 and np.issubdtype(idx.dtype, np.integer)
        except (TypeError, ValueError):
            ok = False
        if not ok or np.any(idx < 0) or np.any(idx >= n):
            raise BadInputError(name, f"a non-empty sequence of indices 0..{n - 1}", sel)
        return idx.astype(np.intp)

    def actuation(self, points, extrapolate: bool = False, *, rows=None,
                  coils=None) -> np.ndarray:
        """The coupled A at points (3,) -> (8, n_coils) or (n, 3) -> (n, 8, n_coils), float64.

        Rows :data:`ROWS`, T/A and T/(m A). Outside the box: BadInputError unless
        ``extrapolate`` (the end cells' polynomials, which degrade quickly away from the box).
        ``rows``, ``coils``: index sequences (into :data:`ROWS`, resp. the coils) to evaluate
        only those: (len(rows), len(coils)) per point, in the given order; the mode sum then
        skips the other rows' polynomials and the other coils' coefficients.
        """
        nc = self.n_coils
        r_sel = self._subset("rows", rows, 8)
        c_sel = self._subset("coils", coils, nc)
        nr = 8 if r_sel is None else len(r_sel)
        ncs = nc if c_sel is None else len(c_sel)
        q = self._one_point(points, extrapolate)
        if q is not None:
            a = self._actuation_one(q, r_sel, c_sel)
            return a if np.ndim(points) == 1 else a[None]
        p, single = self._points(points, extrapolate)
        n = len(p)
        out = np.empty((n, nr, ncs))
        F = self.kernels["one"]
        if F is not None:
            c = F["coef"] if c_sel is None else F["coef"][:, c_sel]
            for s in range(0, n, BATCH_CHUNK):
                e = min(n, s + BATCH_CHUNK)
                f = kernel_rows_many(F, p[s:e], r_sel)  # (m, nr, K)
                np.matmul(f.reshape(-1, f.shape[2]), c, out=out[s:e].reshape(-1, ncs))
            return out[0] if single else out
        for s in range(0, n, RZ_CHUNK):
            e = min(n, s + RZ_CHUNK)
            m = e - s
            a = interpolate_rz(self.kernels["rz"], p[s:e], nc)  # (nc, 8, m) float32
            if c_sel is not None:
                a = a[c_sel]
            if r_sel is not None:
                a = a[:, r_sel]
            a = a.transpose(2, 1, 0).astype(np.float64)
            for t, c in zip(self.kernels["modes"], self.kernels["coef"]):
                if c_sel is not None:
                    c = c[:, c_sel]
                fields = mode_rows(t, p[s:e], r_sel)  # (m, k, nb, nr)
                a += (fields.reshape(m, -1, nr).transpose(0, 2, 1).reshape(nr * m, -1) @ c
                      ).reshape(m, nr, ncs)
            out[s:e] = a
        return out[0] if single else out

    def _actuation_one(self, q, r_sel, c_sel) -> np.ndarray:
        """One point (3 floats): (n_rows, n_coils) float64 of the selection."""
        nc = self.n_coils
        if self.kernels["one"] is not None:
            f = actuation_one(self.kernels["one"], q)
            c = self.kernels["one"]["coef"]
            if r_sel is not None:
                f = f[:, r_sel]
            return f.T @ (c if c_sel is None else c[:, c_sel])
        if len(self.kernels["rz"]) == 1 and self.kernels["rz"][0]["all"]:
            a = _rz_one(self.kernels["rz"][0], q)  # (nc, 8)
        else:
            a = np.empty((nc, 8))
            for t in self.kernels["rz"]:
                a[t["idx"]] = _rz_one(t, q)
        if c_sel is not None:
            a = a[c_sel]
        a = a.T if r_sel is None else a[:, r_sel].T
        pq = np.array([q])
        for t, c in zip(self.kernels["modes"], self.kernels["coef"]):
            f = mode_rows_one(t, pq)  # (k * nb, 8)
            if r_sel is not None:
                f = f[:, r_sel]
            a += f.T @ (c if c_sel is None else c[:, c_sel])
        return a

    def bias_force(self, points, extrapolate: bool = False) -> np.ndarray:
        """F0, the force on the magnet (moment :attr:`moment_a_m2`) at zero current, N:
        (3,) -> (3,), (n, 3) -> (n, 3)."""
        q = self._one_point(points, extrapolate)
        if q is not None:
            L = self.kernels["magnet_one"]
            if L is None:
                f = magnet_terms(self.kernels["magnet"], np.array([q]))[0]
            else:
                d = np.subtract(q, self.kernels["magnet"][0]["pos"])
                x, y = d[:, 0], d[:, 1]
                val = _interp_one(L, np.sqrt(x * x + y * y), q[2])  # F_rho/rho, F_z per core
                f = np.array([val[:, 0] @ x, val[:, 0] @ y, val[:, 1].sum()])
            f += _trilinear_one(self.kernels["magnet_f0"], q)
            return f if np.ndim(points) == 1 else f[None]
        p, single = self._points(points, extrapolate)
        f = magnet_terms(self.kernels["magnet"], p) + _trilinear(self.kernels["magnet_f0"], p)
        return f[0] if single else f

    def sensor_induced_field(self, magnet_position_m, extrapolate: bool = False) -> np.ndarray:
        """Field of the cores magnetized by the magnet at the Hall sensors, T:
        (3,) -> (2, n_coils, 3) (upper array then lower), (n, 3) -> (n, 2, n_coils, 3).

        By reciprocity (linear cores): component c at sensor s is m . B(p) of the cores
        magnetized by a unit dipole along c at s -- a mode sum like A (``SCOEF``)."""
        nc = self.n_coils
        q = self._one_point(magnet_position_m, extrapolate, "magnet_position_m")
        one = self.kernels["sensor_one"]
        if q is not None and one is not None:
            b = (actuation_one(one, q)[:, 0] @ one["coef"]).reshape(2, nc, 3)
            return b if np.ndim(magnet_position_m) == 1 else b[None]
        p, single = self._points(magnet_position_m, extrapolate, "magnet_position_m")
        out = np.zeros((len(p), 6 * nc))
        if one is not None:
            for s in range(0, len(p), BATCH_CHUNK):
                f = kernel_rows_many(one, p[s:s + BATCH_CHUNK])  # (m, 1, K): m . B per basis
                out[s:s + BATCH_CHUNK] = f[:, 0] @ one["coef"]
            b = out.reshape(-1, 2, nc, 3)
            return b[0] if single else b
        one = q is not None
        m = self.arrays["MOMENT"]
        for t, c in self.kernels["scoef"]:
            rows = mode_rows(t, p)[..., :3]  # (n, k, nb, 3): B per unit coefficient
            out += (rows @ m).reshape(len(p), -1) @ c
        b = out.reshape(-1, 2, nc, 3)
        return b[0] if (single or (one and np.ndim(magnet_position_m) == 1)) else b

    def sensor_coil_field(self, currents=None) -> np.ndarray:
        """The coils' field at the sensors: per ampere (2, n_coils, 3, n_coils) T/A, or with
        ``currents`` (n_coils,) A the field (2, n_coils, 3) T (saturation not applied)."""
        g = self.arrays["SENSOR_COIL"]
        if currents is None:
            return g.copy()
        return g @ self._currents(currents)

    def saturation_factor(self, currents) -> np.ndarray:
        """Per-coil factors (n_coils,) on the columns of A at these currents (A): the
        saturation correction (1 for linear cores)."""
        return _interp_factor(self._currents(currents), self.arrays["SAT_I"],
                              self.arrays["SAT_FACTOR"])

    def _currents(self, currents) -> np.ndarray:
        return check_currents(currents, self.n_coils)

    def currents_for(self, point, wanted: np.ndarray, rows=slice(None)) -> np.ndarray:
        """Least-norm currents (A) with A[rows] I = wanted at ``point`` (pseudo-inverse)."""
        a = self.actuation(point)[rows]
        return np.linalg.lstsq(a, np.asarray(wanted, float), rcond=None)[0]


def _self_check():  # pragma: no cover - manual use on the target host
    import sys

    m = MapFile.load(sys.argv[1])
    lo, hi = m.bounds
    print(m.meta["design_name"], m.actuation((lo + hi) / 2).shape, m.bias_force((lo + hi) / 2))


if __name__ == "__main__":  # pragma: no cover
    _self_check()
