"""The map file the controller runs on (format v2): the one definition, numpy and the stdlib only.

``designkit map`` writes it (:mod:`designkit.fieldmap` computes the arrays and wraps
:class:`MapFile`); the runner reads it with this module alone. Everything about the format --
array names, shapes, validation, interpolation -- is defined here and nowhere else.

What the file carries (``.npz``; every array hashed into ``meta.data_sha256``)
------------------------------------------------------------------------------
The coupled actuation matrix A(p), (8, n_coils) per point, rows :data:`ROWS` (T/A, T/(m A)),
as harmonic cells. The box is current-free, so coil k's field per ampere (all cores
magnetized, the coupling included) is B = grad(psi_k) with psi_k harmonic; every row of A is
a first or second derivative of one potential, so the stored field is divergence- and
curl-free by construction and its rows agree with each other.

* meta ``a_layers``: the box cut in z into layers stacked from its floor to its top, each a
  uniform nx x ny grid of cells over the box's footprint: ``z_lo_m``, ``z_hi_m``, ``x0_m``,
  ``y0_m``, ``nx``, ``ny``, ``cell_x_m``, ``cell_y_m``, ``degree`` L. The cells grow with the
  height above the sources (designkit.fieldmap.cell_layers), so the cell of a point is found in
  O(1): its layer by z (a handful of layers), then two floor divisions.
* ``AH0``, ``AH1``, ...: per layer, (nx * ny, (L + 1)^2 - 1, n_coils) float32, cell index
  ix * ny + iy: psi of every coil as a harmonic polynomial of degree L in the cell-local
  coordinates s = (p - centre) / r, r = half the cell's largest side (isotropic, so harmonic
  in s too). The numbers stored are psi's coefficients (T m / A) on its free monomials
  s_x^a s_y^b s_z^c, c in (0, 1), 1 <= a + b + c <= L (:func:`harmonic_terms`); the others
  follow from Laplace's equation (:func:`harmonic_potential`), the constant is dropped.
  A's rows are then polynomials of degree <= L - 1 in s (:func:`harmonic_rows`: d/ds / r for
  B, d2/ds2 / r^2 for the gradient rows).

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
coils' (coupled) field at the sensors per ampere, ``SENSOR_COIL_GRAD`` (2, n_coils, 5, n_coils)
T/(m A) its gradient rows (dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz; the sensors sit outside the
box of A, below the workspace, and the sensor calibration needs them); ``MOMENT`` (3,) A m^2; saturation ``SAT_I``
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

How a lookup of A runs (:func:`prepare_cells` expands every cell's coefficients once, at
load, into its rows' coefficients on the L^2 real solid harmonics of degree <= L - 1
(:func:`solid_harmonics`: A's rows are harmonic polynomials of that degree, so L^2 numbers
per row and coil instead of C(L + 2, 3) monomial coefficients), (L^2, 8 n_coils) float32 per
cell; 7.6 MB in memory for the default map's 1.2 MB of coefficients): one point
(:func:`cells_one`, as (3,) or (1, 3) alike) finds its cell with Python arithmetic, forms the
C(L + 2, 3) monomials from per-axis powers and takes (M,) @ (M, L^2) (the harmonics'
monomial coefficients) @ (L^2, 8 n_coils); blocks of points (:func:`cells_many`) get their
cells and cell-local coordinates in one pass (:func:`cell_local`), are sorted by cell (a radix
sort of 16-bit cell indices), their solid harmonics computed once (a recurrence in z and one
complex product per degree, each degree over the layers that need it), then one
(n_c, L^2) @ (L^2, 8 n_coils) float32 product per occupied cell on its contiguous run, and the
rows are gathered back to the caller's order in cache-sized blocks. Outside the box
(``extrapolate=True``) a point takes its nearest layer's and grid's cell, whose polynomial
degrades quickly away from it. ``rows=`` / ``coils=`` select columns of the products. The bias
force and the sensor field keep their own kernels (:func:`modes_one`, :func:`kernel_rows_many`;
the general path :func:`mode_rows`, :func:`magnet_terms` for rotated or mixed coils). The error
budget, the layout's choices and the measured errors and timings are in designkit.fieldmap's
docstring.
"""

from __future__ import annotations

import bisect
import functools
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
FORMAT_VERSION = 4
"""Format version of map v2 with A as harmonic cells (coupled A, bias force, sensor fields); 3
held A as (rho, z) and core-mode tables, 1 and 2 were grid-only maps."""
ROWS = ("Bx", "By", "Bz", "dBx/dx", "dBx/dy", "dBx/dz", "dBy/dy", "dBy/dz")
UNITS = {"A_rows_0_2": "T/A", "A_rows_3_7": "T/(m A)", "grid": "m", "moment": "A m^2",
         "current": "A", "force": "N", "field": "T", "sensor_coil_field": "T/A"}
REBUILD = ("Rebuild it for this version: designkit map --out <file.npz> (with --design "
           "<design.toml> for a design of your own)")

# name -> (dtype, shape as a function of the sizes); the single list of arrays in a map file
_FIXED = ("SCOEF", "F0_RES", "M_X", "M_Y", "M_Z", "SENSOR_POS", "SENSOR_COIL",
          "SENSOR_COIL_GRAD", "MOMENT", "SAT_I", "SAT_FACTOR")


def _shapes(meta: dict, arrays: dict) -> dict:
    nc = int(meta["n_coils"])
    mx, my, mz = (len(arrays[k]) for k in ("M_X", "M_Y", "M_Z"))
    ns = len(arrays["SAT_I"])
    f32, f64 = np.float32, np.float64
    nbs = int(meta["n_sensor_basis"])
    return {"SCOEF": (f64, (nc, nbs, 2, nc, 3)),
            "F0_RES": (f32, (mx, my, mz, 3)),
            "M_X": (f64, (mx,)), "M_Y": (f64, (my,)), "M_Z": (f64, (mz,)),
            "SENSOR_POS": (f64, (2, nc, 3)), "SENSOR_COIL": (f64, (2, nc, 3, nc)),
            "SENSOR_COIL_GRAD": (f64, (2, nc, 5, nc)),
            "MOMENT": (f64, (3,)), "SAT_I": (f64, (ns,)), "SAT_FACTOR": (f64, (ns, nc))}


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
        raise _bad(p, f"format version {FORMAT_VERSION} (map v2, A as harmonic cells); this "
                   f"file is version {meta.get('version')!r}, written by an older designkit",
                   REBUILD)
    if meta.get("units") != UNITS or meta.get("rows") != list(ROWS):
        raise _bad(p, f"units {UNITS} and rows {ROWS}")
    try:
        nc = int(meta["n_coils"])
        missing = [k for k in _FIXED if k not in arrays]
        if missing:
            raise _bad(p, f"arrays {list(_FIXED)}; missing {missing}", REBUILD)
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
    _validate_layers(arrays, meta, nc, p)
    for key, prefix, nq in (("magnet_tables", "MRZ", NQ_MAGNET),
                            ("sensor_mode_tables", "SM", None)):
        tabs = meta.get(key)
        n_basis = int(meta["n_sensor_basis"])
        if not isinstance(tabs, list) or (not tabs and nq is not None):
            raise _bad(p, f"meta.{key} (a list, non-empty for the magnet tables)")
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
        raise _bad(p, "meta.a_layers: harmonic-cell layers stacked over the box's z range, each "
                   "with a float32 table AH<k> (nx * ny, (degree + 1)^2 - 1, n_coils)")


# ============================================================================ core tables
N_MODE_Q = {0: 4, 1: 5, 2: 5}
"""Quantities per node and shape of a mode table: m = 0 (b, Bz, e, w), m = 1, 2 (a, a1, a2, az,
a1z, see :func:`mode_rows`)."""
NQ_MAGNET = 2
"""Quantities per node of a magnet table: F_rho/rho, F_z (N/m, N) of the magnet's pull on one
core alone."""


def gradient_tensor(g5: np.ndarray) -> np.ndarray:
    """Gradient rows (..., 5) (dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz) -> the full gradient
    (..., 3, 3), [i, j] = dB_i/dx_j: symmetric (curl-free) and traceless (divergence-free)."""
    gxx, gxy, gxz, gyy, gyz = np.moveaxis(np.asarray(g5), -1, 0)
    return np.stack([np.stack([gxx, gxy, gxz], -1), np.stack([gxy, gyy, gyz], -1),
                     np.stack([gxz, gyz, -gxx - gyy], -1)], -2)


def _rotate_rows(rows: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Local rows (8, n, k) of coils with rotations (k, 3, 3) -> global rows (8, n, k)."""
    b = rows[:3].astype(np.float64)
    gxx, gxy, gxz, gyy, gyz = rows[3:].astype(np.float64)
    g = np.stack([np.stack([gxx, gxy, gxz]), np.stack([gxy, gyy, gyz]),
                  np.stack([gxz, gyz, -gxx - gyy])])  # (3, 3, n, k)
    bg = np.einsum("kia,ank->ink", rot, b)
    gg = np.einsum("kia,abnk,kjb->ijnk", rot, g, rot)
    return np.stack([bg[0], bg[1], bg[2], gg[0, 0], gg[0, 1], gg[0, 2], gg[1, 1], gg[1, 2]])


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
    """What :func:`prepare_one` needs: every group's quantities padded to 5 columns, so one
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


def mode_rows(t: dict, p: np.ndarray) -> np.ndarray:
    """Rows (n, k, n_basis, 8) of every basis field of the type's k cores at points (n, 3),
    global frame, basis in the order of ``t['order']`` (grouped by mode order and cos / sin;
    :func:`prepare_modes` permutes the coefficients to match)."""
    x, y, val = _bilinear(t, p)
    n, k = x.shape
    mono = _monomials(x, y).reshape(n * k, 15)
    parts = []
    for (m, c), cols in t["groups"]:
        v = val[..., cols]  # (n, k, nb_g, Q_m)
        pm = (mono @ _POLY_T[(m, c)]).reshape(n, k, 1, N_MODE_Q[m], 8)  # one GEMM
        # a sum over the 4-5 quantities: numpy's batched matmul is slow on tiny matrices
        acc = v[..., 0, None] * pm[..., 0, :]
        for q in range(1, v.shape[-1]):
            acc += v[..., q, None] * pm[..., q, :]
        parts.append(acc)  # (n, k, nb_g, 8)
    out = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=2)
    if t["rot"] is not None:
        flat = out.transpose(3, 0, 2, 1).reshape(8, -1, k)
        out = _rotate_rows(flat, t["rot"]).reshape(8, n, -1, k).transpose(1, 3, 2, 0)
    return out


_POLY_T = _poly_tensors()


# ============================================================================ one-point kernels
# The sensor field for one magnet position in a few small numpy calls (each ~0.3-1 us: the
# call, not the arithmetic, is the cost): every core's mode table looked up with one gather of
# the 4 corners and one matmul for the weights, all polynomials one GEMM and the sum one GEMV.
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


def prepare_one(modes: tuple, coefs: tuple, moment) -> dict | None:
    """The one-point kernel's constants for a sum of mode tables with coefficients ``coefs``
    ((k * n_basis, n_out) per type, MapFile's layout), giving m . B per basis field for the
    moment ``moment`` (3,) A m^2 (the sensor fields). None: the general path is used (several
    types, rotated coils or coils at different heights)."""
    if len(modes) != 1:
        return None
    mt = modes[0]
    lcm = _lookup(mt, mt["flat"])
    if lcm is None:
        return None
    n_out = coefs[0].shape[1]
    nb, width = mt["one_nb"], mt["one_width"]
    src, dst = mt["one_src"], mt["one_dst"]
    poly = mt["one_poly"].reshape(15, width, 8)[..., :3] @ np.asarray(moment, float)
    # on all 25 products x^a y^b (a, b <= 4): those of degree > 4 get zero rows
    poly25 = np.zeros((5, 5) + poly.shape[1:])
    poly25[_POW_X, _POW_Y] = poly
    # for the batch kernel: the basis fields grouped by the block of polynomials they use
    # (each mode order and cos / sin), values unpadded
    blocks: dict = {}
    for b in np.unique(dst // width):
        sel = dst // width == b
        cols = dst[sel] % width
        blocks.setdefault(int(cols.min()), []).append((int(b), src[sel][np.argsort(cols)]))
    groups = [(start, len(mem[0][1]), np.array([b for b, _ in mem], np.intp),
               np.array([v for _, v in mem], np.intp)) for start, mem in sorted(blocks.items())]
    return {"pos": mt["pos"], "cm": lcm, "src": src, "dst": dst,
            "poly": np.ascontiguousarray(poly25.reshape(25, -1)),
            "nb": nb, "width": width, "groups": groups,
            "coef": np.ascontiguousarray(coefs[0].reshape(-1, n_out))}


def modes_one(F: dict, q) -> np.ndarray:
    """One point ``q`` (3 floats, m): m . B (k * n_basis,) of every core's basis fields; the
    sensor field = that @ F['coef'] (see :func:`prepare_one`)."""
    d = np.subtract(q, F["pos"])
    x, y = d[:, 0], d[:, 1]
    val = _interp_one(F["cm"], np.sqrt(x * x + y * y), q[2])
    k = len(x)
    pw = np.power(d[:, :2, None], _POW)  # (k, 2, 5): powers 0..4 of x and y
    poly = ((pw[:, 0, :, None] * pw[:, 1, None, :]).reshape(k, 25) @ F["poly"]
            ).reshape(k, F["width"], 1)
    pad = np.zeros((k, F["nb"] * F["width"]))
    pad[:, F["dst"]] = val[:, F["src"]]
    return np.matmul(pad.reshape(k, F["nb"], F["width"]), poly).reshape(-1)


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


def kernel_rows_many(F: dict, p: np.ndarray) -> np.ndarray:
    """:func:`modes_one` for points (m, 3): (m, k * n_basis), for one GEMM with
    ``F['coef']``."""
    m = len(p)
    d = p[:, None, :] - F["pos"]  # (m, k, 3)
    k = d.shape[1]
    x, y = d[..., 0], d[..., 1]
    val = _interp_many(F["cm"], np.sqrt(x * x + y * y), p[:, 2])
    pw = np.empty((m, k, 2, 5))  # powers 0..4 of x and y (products: np.power is slow)
    pw[..., 0] = 1.0
    pw[..., 1] = d[..., :2]
    for e in range(2, 5):
        np.multiply(pw[..., e - 1], pw[..., 1], out=pw[..., e])
    mono = (pw[..., 0, :, None] * pw[..., 1, None, :]).reshape(m * k, 25)
    poly = (mono @ F["poly"]).reshape(m * k, F["width"], 1)
    # per block of polynomials, its basis fields' values (m k, n_g, Q) @ (m k, Q, 1)
    out = np.empty((m * k, F["nb"], 1))
    flat = val.reshape(m * k, -1)
    for start, nq, basis, cols in F["groups"]:
        out[:, basis] = np.matmul(flat[:, cols], poly[:, start:start + nq])
    return out.reshape(m, k * F["nb"])


# ============================================================================ harmonic cells
# A(p): the box is current-free, so every coil's field per ampere is B = grad(psi) with psi
# harmonic. The box is cut into layers (z), each a uniform grid of cells; per cell and coil the
# file holds psi as a harmonic polynomial of degree L in cell-local scaled coordinates
# s = (p - centre) / r (r = half the cell's largest side): all 8 rows are exact first and
# second derivatives of one potential (divergence- and curl-free by construction).
def harmonic_terms(degree: int) -> list:
    """The potential's free monomials s_x^a s_y^b s_z^c, c in (0, 1), 1 <= a + b + c <=
    ``degree``, in file order: total degree ascending, then c, then a descending; K = (L + 1)^2
    - 1 of them. The coefficients stored are those of these monomials in psi; all others follow
    from Laplace's equation (:func:`harmonic_potential`)."""
    return [(a, n - c - a, c) for n in range(1, degree + 1) for c in (0, 1)
            for a in range(n - c, -1, -1)]


def monomial_exponents(degree: int) -> np.ndarray:
    """(M, 3) exponents (a, b, c) of the monomials s_x^a s_y^b s_z^c of total degree <=
    ``degree``, M = C(degree + 3, 3): total degree ascending, then a descending, then b
    descending (those of degree <= d are the first C(d + 3, 3): one order serves every
    degree)."""
    return np.array([(a, b, n - a - b) for n in range(degree + 1)
                     for a in range(n, -1, -1) for b in range(n - a, -1, -1)],
                    dtype=np.intp).reshape(-1, 3)


def harmonic_potential(degree: int) -> np.ndarray:
    """(K, M) float64: the monomial coefficients (:func:`monomial_exponents` order, degree <=
    L) of psi per unit free coefficient (:func:`harmonic_terms`): the free term
    s_x^a s_y^b s_z^c plus the z^(c + 2k) terms Laplace's equation requires,
    P_k = -Laplacian_xy(P_(k-1)) / ((c + 2k)(c + 2k - 1)), P_0 = s_x^a s_y^b."""
    index = {tuple(e): i for i, e in enumerate(monomial_exponents(degree).tolist())}
    terms = harmonic_terms(degree)
    out = np.zeros((len(terms), len(index)))
    for f, (a, b, c) in enumerate(terms):
        poly, k = {(a, b): 1.0}, 0
        while poly:
            for (i, j), val in poly.items():
                out[f, index[(i, j, c + 2 * k)]] += val
            k += 1
            div = (c + 2 * k) * (c + 2 * k - 1)
            nxt: dict = {}
            for (i, j), val in poly.items():
                if i >= 2:
                    nxt[(i - 2, j)] = nxt.get((i - 2, j), 0.0) - val * i * (i - 1) / div
                if j >= 2:
                    nxt[(i, j - 2)] = nxt.get((i, j - 2), 0.0) - val * j * (j - 1) / div
            poly = {key: val for key, val in nxt.items() if val != 0.0}
    return out


def harmonic_rows(degree: int) -> np.ndarray:
    """(8, M, K) float64 with M = C(L + 2, 3): row r of A (:data:`ROWS`: the derivatives
    d/ds_x, d/ds_y, d/ds_z, d2/ds_x2, d2/ds_x ds_y, d2/ds_x ds_z, d2/ds_y2, d2/ds_y ds_z of psi)
    as monomial coefficients of degree <= L - 1 per unit free coefficient. In metres: divide
    rows 0-2 by r and rows 3-7 by r^2."""
    e = monomial_exponents(degree)
    index = {tuple(x): i for i, x in enumerate(e.tolist())}
    m_low = len(monomial_exponents(degree - 1))
    pot = harmonic_potential(degree).T  # (M_L, K)

    def diff(coef: np.ndarray, axis: int) -> np.ndarray:
        out = np.zeros_like(coef)
        for i, x in enumerate(e.tolist()):
            if x[axis] >= 1:
                y = list(x)
                y[axis] -= 1
                out[index[tuple(y)]] += x[axis] * coef[i]
        return out

    dx, dy, dz = (diff(pot, a) for a in range(3))
    rows = [dx, dy, dz, diff(dx, 0), diff(dx, 1), diff(dx, 2), diff(dy, 1), diff(dy, 2)]
    return np.stack([r[:m_low] for r in rows])


def monomials(s: np.ndarray, degree: int, out: np.ndarray | None = None) -> np.ndarray:
    """(M, n) monomials of degree <= ``degree`` (:func:`monomial_exponents` order) of local
    coordinates s (n, 3), built degree by degree (3 products per degree: x times the previous
    degree's block, y times its x-free part, z times its last)."""
    n = len(s)
    if out is None:
        out = np.empty((len(monomial_exponents(degree)), n), s.dtype)
    out[0] = 1.0
    x, y, z = s[:, 0], s[:, 1], s[:, 2]
    start, size = 0, 1  # the previous degree's block
    for d in range(1, degree + 1):
        new = start + size
        prev = out[start:new]
        np.multiply(prev, x, out=out[new:new + size])
        np.multiply(prev[size - d:], y, out=out[new + size:new + size + d])
        np.multiply(prev[size - 1:], z, out=out[new + size + d:new + size + d + 1])
        start, size = new, size + d + 1
    return out


@functools.lru_cache(maxsize=None)
def solid_harmonic_betas(degree: int) -> tuple:
    """Per degree l <= ``degree`` (a tuple, cached) the (2l - 3, 1) factors
    beta_l^m = ((l - 1)^2 - m^2) / ((2l - 1)(2l - 3)) of the z-recurrence of
    :func:`solid_harmonics` (rows m = 0, 1, 1, 2, 2, ...; empty for l < 2)."""
    out = []
    for ell in range(degree + 1):
        m = np.array([(j + 1) // 2 for j in range(max(0, 2 * ell - 3))], float)
        out.append((((ell - 1) ** 2 - m * m) / ((2 * ell - 1) * (2 * ell - 3)))[:, None])
    return tuple(out)


def solid_harmonic_coefficients(degree: int) -> np.ndarray:
    """(M, (degree + 1)^2) float64: the monomial coefficients (:func:`monomial_exponents`
    order, M = C(degree + 3, 3)) of the basis :func:`solid_harmonics` evaluates, exact (the
    same recurrence run on coefficient vectors)."""
    e = monomial_exponents(degree)
    index = {tuple(x): i for i, x in enumerate(e.tolist())}
    up = [np.array([index.get(tuple(x + np.eye(3, dtype=np.intp)[a]), -1) for x in e])
          for a in range(3)]

    def times(v, a):  # v times s_a (v of degree < ``degree``)
        out = np.zeros_like(v)
        nz = np.flatnonzero(v)
        out[up[a][nz]] = v[nz]
        return out

    betas = solid_harmonic_betas(degree)
    cols = [np.eye(len(e))[0]]
    for ell in range(1, degree + 1):
        b, b1, b2 = ell * ell, (ell - 1) ** 2, max(ell - 2, 0) ** 2
        for j in range(2 * ell - 1):
            v = times(cols[b1 + j], 2)
            if j < 2 * ell - 3:
                r2 = sum(times(times(cols[b2 + j], a), a) for a in range(3))
                v = v - betas[ell][j, 0] * r2
            cols.append(v)
        c = cols[b - 2] if ell > 1 else cols[0]
        s = cols[b - 1] if ell > 1 else np.zeros(len(e))
        cols += [times(c, 0) - times(s, 1), times(c, 1) + times(s, 0)]
    return np.stack(cols, axis=1)


def solid_harmonics(s: np.ndarray, degree: int, out: np.ndarray | None = None,
                    work: np.ndarray | None = None, spans=None) -> np.ndarray:
    """((degree + 1)^2, n) the real regular solid harmonics of degree <= ``degree`` at local
    coordinates ``s`` (3, n) (rows x, y, z), a basis of the harmonic polynomials of that degree
    (A's rows in a cell are such polynomials: their L^2 coefficients instead of the
    C(L + 2, 3) monomials' halve a batch's multiply-adds). Block l (rows l^2 .. (l + 1)^2 - 1)
    holds G_l^0, then the cos and sin parts of G_l^m, m = 1..l:
    G_l^l = Re, Im (s_x + i s_y)^l (from G_(l-1)^(l-1) by one complex product) and, for m < l,
    G_l^m = s_z G_(l-1)^m - beta_l^m |s|^2 G_(l-2)^m (:func:`solid_harmonic_betas`; r^l P_l^m
    of the associated Legendre functions up to a factor per (l, m)). ``work``: scratch of
    shape (2 degree + 4, n) or more; both buffers take the dtype of ``s``. ``spans``: per
    degree l a range (a, b) of the columns that need it (nested: each within the one of l - 1);
    the other columns of block l are left unset."""
    n = s.shape[1]
    if out is None:
        out = np.empty(((degree + 1) ** 2, n), s.dtype)
    if work is None:
        work = np.empty((2 * degree + 4, n), s.dtype)
    if spans is None:
        spans = [(0, n)] * (degree + 1)
    a, b = spans[0]
    out[0, a:b] = 1.0
    if degree == 0:
        return out
    a, b = spans[1]
    x, y, z = s[:, a:b]
    out[1, a:b], out[2, a:b], out[3, a:b] = z, x, y
    r2, xx, ym = work[0, a:b], work[1:3, a:b], work[3:5, a:b]
    np.multiply(x, x, out=r2)
    r2 += y * y
    r2 += z * z
    xx[0], xx[1], ym[0], ym[1] = x, x, y, y
    np.negative(ym[0], out=ym[0])
    a1 = a
    betas = solid_harmonic_betas(degree)
    for ell in range(2, degree + 1):
        a, b = spans[ell]
        o = a - a1  # this degree's columns within the work rows
        z_, r2_, xx_, ym_ = z[o:o + b - a], r2[o:o + b - a], xx[:, o:o + b - a], ym[:, o:o + b - a]
        tmp = work[5:, a:b]
        c, c1, c2 = ell * ell, (ell - 1) ** 2, (ell - 2) ** 2
        k = 2 * ell - 3
        np.multiply(out[c1:c, a:b], z_, out=out[c:c + k + 2, a:b])
        t = tmp[:k]
        np.multiply(out[c2:c1, a:b], r2_, out=t)
        t *= betas[ell]
        out[c:c + k, a:b] -= t
        sec = out[c + k + 2:c + k + 4, a:b]
        np.multiply(out[c - 2:c, a:b], xx_, out=sec)
        np.multiply(out[c - 1:c - 3:-1, a:b], ym_, out=tmp[:2])
        sec += tmp[:2]
    return out


def _rows_on_harmonics(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """(8, H, K) float64: :func:`harmonic_rows` of a potential of degree ``degree`` on the
    H = degree^2 :func:`solid_harmonics` of degree <= degree - 1 (every row is harmonic, so it
    lies in their span: checked to rounding), and (M, H) their monomial coefficients."""
    got = _ROWS_H.get(degree)
    if got is None:
        ops = harmonic_rows(degree)  # (8, M, K)
        hc = solid_harmonic_coefficients(degree - 1)  # (M, H)
        ops_h = np.linalg.pinv(hc) @ ops
        resid = np.abs(hc @ ops_h - ops).max()
        if not resid <= 1e-9 * np.abs(ops).max():  # pragma: no cover - a bug, not bad input
            raise AssertionError(f"rows of degree {degree} off the harmonic span ({resid})")
        got = _ROWS_H[degree] = (ops_h, hc)
    return got


_ROWS_H: dict = {}


def prepare_cells(layers: list, tables: list, nc: int) -> dict:
    """What the A lookups need: per cell its rows on the solid harmonics of degree <= L - 1,
    (L^2, 8 nc) float32 (coefficients x :func:`_rows_on_harmonics`, in T/A and T/(m A) per
    unit :func:`solid_harmonics`), its centre and 1 / r, per layer the grid constants (lists
    for the one-point path) and per degree the harmonics' monomial coefficients (M, L^2)
    float32 (one point: its monomials @ those, then @ the cell's)."""
    cells, centres, inv_r, degree = [], [], [], []
    grid, z_edges = [], []
    exps: dict = {}
    to_h: dict = {}
    off = 0
    for lay, tab in zip(layers, tables):
        deg, nx, ny = int(lay["degree"]), int(lay["nx"]), int(lay["ny"])
        hx, hy = float(lay["cell_x_m"]), float(lay["cell_y_m"])
        z0, z1 = float(lay["z_lo_m"]), float(lay["z_hi_m"])
        r = max(hx, hy, z1 - z0) / 2
        ops, hc = _rows_on_harmonics(deg)  # (8, H, K), (M, H)
        scale = np.array([r] * 3 + [r * r] * 5)[:, None, None]
        h = ops.shape[1]
        # (n_cells, K, nc) -> (n_cells, H, 8, nc): every row of every coil per harmonic
        rows = np.einsum("rhk,ckn->chrn", ops / scale, tab.astype(np.float64))
        cells += list(rows.reshape(len(tab), h, 8 * nc).astype(np.float32))
        ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
        centres.append(np.c_[lay["x0_m"] + (ix.ravel() + 0.5) * hx,
                             lay["y0_m"] + (iy.ravel() + 0.5) * hy,
                             np.full(nx * ny, (z0 + z1) / 2)])
        inv_r += [1.0 / r] * (nx * ny)
        degree += [deg] * (nx * ny)
        grid.append((float(lay["x0_m"]), float(lay["y0_m"]), 1.0 / hx, 1.0 / hy, nx, ny, off))
        z_edges.append(z1)
        off += nx * ny
        exps[deg - 1] = monomial_exponents(deg - 1)
        to_h[deg - 1] = hc.astype(np.float32)
    centres = np.concatenate(centres)
    lay_deg = [int(lay["degree"]) - 1 for lay in layers]
    r_lay = [max(float(lay["cell_x_m"]), float(lay["cell_y_m"]),
                 float(lay["z_hi_m"]) - float(lay["z_lo_m"])) / 2 for lay in layers]
    # per layer, for cell_local's gathers: origin, 1 / cell sides, last index, cell side / r,
    # z centre, 1 / r, cells per row, first cell
    lay_f = np.array([(x0, y0, ihx, ihy, nx - 1.0, ny - 1.0, 1.0 / (ihx * r), 1.0 / (ihy * r),
                       (float(lay["z_lo_m"]) + float(lay["z_hi_m"])) / 2, 1.0 / r)
                      for (x0, y0, ihx, ihy, nx, ny, _), lay, r in zip(grid, layers, r_lay)])
    lay_i = np.array([(ny, o) for (_, _, _, _, _, ny, o) in grid], np.intp)
    return {"cells": cells,
            "centre_inv_r": [tuple(c) + (ir,) for c, ir in zip(centres.tolist(), inv_r)],
            "n_harm": [d * d for d in degree],
            "cap": [max(1, GEMM_CAP // (d * d * 8 * nc)) for d in degree],
            "degree": max(degree) - 1, "grid": grid,
            "layer_f": np.ascontiguousarray(lay_f.T), "layer_i": np.ascontiguousarray(lay_i.T),
            "z_inner": z_edges[:-1], "z_inner_arr": np.array(z_edges[:-1]),
            "one_idx": {d: (e[:, 0], e[:, 1] + d + 1, e[:, 2] + 2 * (d + 1))
                        for d, e in exps.items()},
            "to_harm": to_h,
            # per layer (its last cell, its harmonics' degree), for the batch path
            "layer_degree": [(g[6] + g[4] * g[5] - 1, d) for g, d in zip(grid, lay_deg)],
            "cell_degree": [d - 1 for d in degree], "n_cells": off, "nc": nc}


def cell_local(C: dict, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cells (n,) intp of points (n, 3) and their cell-local coordinates s = (p - centre) / r
    (3, n) float64: the layer by z (outside the box: the end layer), then the layer's uniform
    grid (outside: the edge cells, whose polynomials extrapolate). One gather of the layer
    constants, every operation on contiguous (n,) rows."""
    x, y, z = p.T.copy()
    li = np.searchsorted(C["z_inner_arr"], z, side="right")
    x0, y0, ihx, ihy, mx, my, kx, ky, zc, ir = np.take(C["layer_f"], li, axis=1)
    ny, off = np.take(C["layer_i"], li, axis=1)
    s = np.empty((3, len(p)))
    x -= x0
    x *= ihx  # in cell widths from the layer's origin
    y -= y0
    y *= ihy
    ix = np.clip(x, 0.0, mx).astype(np.intp)
    iy = np.clip(y, 0.0, my).astype(np.intp)
    x -= ix
    x -= 0.5
    np.multiply(x, kx, out=s[0])
    y -= iy
    y -= 0.5
    np.multiply(y, ky, out=s[1])
    z -= zc
    np.multiply(z, ir, out=s[2])
    ix *= ny
    ix += iy
    ix += off
    return ix, s


def cell_index(C: dict, p: np.ndarray) -> np.ndarray:
    """Cell (n,) of points (n, 3) (:func:`cell_local`)."""
    return cell_local(C, p)[0]


def _scratch(name: str, shape: tuple, dtype) -> np.ndarray:
    """A reusable per-thread buffer of ``shape`` (fresh multi-MB temporaries cost more than the
    arithmetic here: each is page-faulted in again on every call)."""
    bufs = _WORK.__dict__.setdefault("bufs", {})
    size = int(np.prod(shape))
    b = bufs.get(name)
    if b is None or b.size < size or b.dtype != dtype:
        b = bufs[name] = np.empty(size, dtype=dtype)
    return b[:size].reshape(shape)


_WORK = threading.local()


GEMM_CAP = 400_000
"""Largest multiply-add count of one per-cell product in :func:`cells_many` (cells with more
points are split): OpenBLAS (0.3.31 here) runs products above ~5.2e5 on all cores, and when
another process keeps a core busy each such call waits milliseconds (measured: 1e4 points took
0.28 s instead of ~4 ms without a cap, products up to 7e5, while one of two cores was busy)."""


CELL_CHUNK = 32768
"""Points per block of :func:`cells_many` (its scratch is ~(2 L^2 + 8 n_coils) floats per
point)."""


def cells_many(C: dict, p: np.ndarray, cols=None, out=None) -> np.ndarray:
    """A at points (n, 3) (n <= :data:`CELL_CHUNK`): (n, 8 nc) float64, or only the flat
    columns ``cols`` (row * nc + coil) (n, len(cols)), into ``out`` if given. Points are sorted
    by cell (stable), their solid harmonics computed once (each degree over the run of the
    layers that need it), then one float32 (n_c, H) @ (H, n_out) product per occupied cell;
    the rows are gathered back to the caller's order in blocks."""
    n = len(p)
    cell, s = cell_local(C, p)
    # 16-bit keys sort by radix (~8x faster than a merge sort of intp)
    order = np.argsort(cell.astype(np.int16) if C["n_cells"] < 32768 else cell, kind="stable")
    counts = np.bincount(cell, minlength=C["n_cells"])
    ends = np.cumsum(counts).tolist()
    d_max = C["degree"]
    st = _scratch("s", (3, n), np.float32)
    for k in range(3):
        st[k] = s[k].take(order)
    harm = _scratch("harm", ((d_max + 1) ** 2, n), np.float32)
    work = _scratch("harm_work", (2 * d_max + 4, n), np.float32)
    spans = []  # per degree the run of sorted points whose layer needs it
    a = 0
    for off, deg in C["layer_degree"]:
        b = ends[off]
        if b > a:
            for d in range(deg + 1):
                if d < len(spans):
                    spans[d] = (min(spans[d][0], a), max(spans[d][1], b))
                else:
                    spans.append((a, b))
        a = b
    if spans:
        solid_harmonics(st, len(spans) - 1, harm, work, spans)
    width = 8 * C["nc"] if cols is None else len(cols)
    res = _scratch("res", (n, width), np.float32)
    cells, n_harm = C["cells"], C["n_harm"]
    caps = C["cap"] if cols is None else [max(1, GEMM_CAP // (h * width)) for h in n_harm]
    views = {h: harm[:h] for h in set(n_harm)}
    dot = np.matmul
    counts = counts.tolist()
    for c in np.flatnonzero(counts).tolist():
        b = ends[c]
        a = b - counts[c]
        h = views[n_harm[c]]
        w = cells[c] if cols is None else cells[c][:, cols]
        step = caps[c]
        if b - a <= step:
            dot(h[:, a:b].T, w, out=res[a:b])
        else:
            for a in range(a, b, step):
                e = min(b, a + step)
                dot(h[:, a:e].T, w, out=res[a:e])
    out = np.empty((n, width)) if out is None else out
    # back to the caller's order: a gather (sequential writes) in blocks that stay in cache,
    # faster than the scatter out[order] = res
    inv = np.empty(n, np.intp)
    inv[order] = np.arange(n)
    blk = _scratch("blk", (GATHER_BLOCK, width), np.float32)
    for a in range(0, n, GATHER_BLOCK):
        b = min(n, a + GATHER_BLOCK)
        np.take(res, inv[a:b], axis=0, out=blk[:b - a])
        out[a:b] = blk[:b - a]
    return out


GATHER_BLOCK = 1024
"""Rows per block of :func:`cells_many`'s gather back to the caller's order."""


def cells_one(C: dict, q) -> np.ndarray:
    """A at one point (3 Python floats): (8 nc,) float32; the cell by Python arithmetic, the
    monomials from per-axis powers, the harmonics from those (one small product)."""
    x, y, z = q
    lay = C["grid"][bisect.bisect_right(C["z_inner"], z)]
    x0, y0, ihx, ihy, nx, ny, off = lay
    i = int(min(max((x - x0) * ihx, 0.0), nx - 1.0))
    j = int(min(max((y - y0) * ihy, 0.0), ny - 1.0))
    c = off + i * ny + j
    cx, cy, cz, ir = C["centre_inv_r"][c]
    sx, sy, sz = (x - cx) * ir, (y - cy) * ir, (z - cz) * ir
    d = C["cell_degree"][c]
    px, py, pz = [1.0], [1.0], [1.0]
    for _ in range(d):
        px.append(px[-1] * sx)
        py.append(py[-1] * sy)
        pz.append(pz[-1] * sz)
    pw = np.array(px + py + pz, np.float32)
    ia, ib, ic = C["one_idx"][d]
    return ((pw[ia] * pw[ib] * pw[ic]) @ C["to_harm"][d]) @ C["cells"][c]


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
    """The prepared lookups: 'cells' (A, :func:`prepare_cells`), 'scoef', 'magnet',
    'magnet_f0' and the one-point kernels 'sensor_one', 'magnet_one' (None where the general
    path runs)."""

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
        layers = meta["a_layers"]
        cells = prepare_cells(layers, [arrays[lay["name"]] for lay in layers], nc)
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
            "cells": cells, "scoef": scoefs,
            "magnet": tuple(magnet),
            "magnet_f0": (maxes, np.ascontiguousarray(f0.reshape(-1, 3)), f0.shape[:3]),
            "sensor_one": (prepare_one(smodes, tuple(c for _, c in scoefs), arrays["MOMENT"])
                           if smodes else None),
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
        # per-column extremes first (NaN propagates into them; one reduction per column: numpy's
        # p.min(axis=0) over (n, 3) is ~20x slower): the row-wise search below runs only for a
        # bad input
        if not len(p):
            return p, single
        p_min = [p[:, k].min() for k in range(3)]
        p_max = [p[:, k].max() for k in range(3)]
        if not all(math.isfinite(v) for v in p_min + p_max):
            raise BadInputError(name, "finite (no NaN or Inf)", p.tolist()[:3])
        lo, hi = self.bounds
        tol = 1e-9
        box_lo, box_hi = self._box_lists
        if not extrapolate and (any(v < b for v, b in zip(p_min, box_lo))
                                or any(v > b for v, b in zip(p_max, box_hi))):
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
        only those: (len(rows), len(coils)) per point, in the given order; a batch's per-cell
        products then take only those columns (a single point computes all 8 x n_coils and
        selects).
        """
        nc = self.n_coils
        r_sel = self._subset("rows", rows, 8)
        c_sel = self._subset("coils", coils, nc)
        C = self.kernels["cells"]
        q = self._one_point(points, extrapolate)
        if q is not None:
            a = cells_one(C, q).astype(np.float64).reshape(8, nc)
            if r_sel is not None:
                a = a[r_sel]
            if c_sel is not None:
                a = a[:, c_sel]
            return a if np.ndim(points) == 1 else a[None]
        p, single = self._points(points, extrapolate)
        r = np.arange(8) if r_sel is None else r_sel
        c = np.arange(nc) if c_sel is None else c_sel
        cols = None if r_sel is None and c_sel is None else (r[:, None] * nc + c).ravel()
        n = len(p)
        if n <= CELL_CHUNK:
            out = cells_many(C, p, cols)
        else:
            out = np.empty((n, 8 * nc if cols is None else len(cols)))
            for s in range(0, n, CELL_CHUNK):
                cells_many(C, p[s:s + CELL_CHUNK], cols, out[s:s + CELL_CHUNK])
        out = out.reshape(n, len(r), len(c))
        return out[0] if single else out

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
            b = (modes_one(one, q) @ one["coef"]).reshape(2, nc, 3)
            return b if np.ndim(magnet_position_m) == 1 else b[None]
        p, single = self._points(magnet_position_m, extrapolate, "magnet_position_m")
        out = np.zeros((len(p), 6 * nc))
        if one is not None:
            for s in range(0, len(p), BATCH_CHUNK):
                f = kernel_rows_many(one, p[s:s + BATCH_CHUNK])  # (m, K): m . B per basis
                out[s:s + BATCH_CHUNK] = f @ one["coef"]
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

    def sensor_coil_gradient(self) -> np.ndarray:
        """The coils' field gradient at the sensors per ampere, (2, n_coils, 3, 3, n_coils)
        T/(m A), entry [a, s, i, j, k] = dB_i/dx_j of coil k (:func:`gradient_tensor` of the
        stored rows)."""
        g = gradient_tensor(np.moveaxis(self.arrays["SENSOR_COIL_GRAD"], 2, -1))
        return np.moveaxis(g, (-2, -1), (2, 3))

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
