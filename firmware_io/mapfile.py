"""Read the force-current map written by ``designkit map`` -- numpy and the standard library only.

The file (``.npz``): ``A`` (nx, ny, nz, 8, n_coils) float32 with rows Bx, By, Bz, dBx/dx,
dBx/dy, dBx/dz, dBy/dy, dBy/dz (T/A and T/(m A)); ``dG`` (nx, ny, nz, 7, n_coils) float32, the
third derivatives T_xxx, T_xxy, T_xxz, T_xyy, T_xyz, T_yyy, T_yyz (T/(m^2 A)); ``meta``, a JSON
string (grid, units, coil poses, magnet moment, limits, hashes); ``RZ0``, ``RZ1``, ... (meta
``rz_tables``): per identical coil type, a (n_rho, n_u, 4) float32 table of Br/rho, Bz,
(dBr/dz)/rho, (dBr/drho - Br/rho)/rho^2 per ampere in the coil's local (rho, z) frame.
designkit.fieldmap documents the format and both interpolators; this module repeats them so the
runner never imports designkit: one point or small batches use the 3-D grid, batches of
>= BATCH_MIN points inside the box the (rho, z) tables.

    m = MapFile.load("fieldmap.npz")
    a = m.actuation((0.0, 0.0, 0.03))        # (8, n_coils)
"""

from __future__ import annotations

import hashlib
import json
import threading
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import BadInputError

FORMAT = "designkit-fieldmap"
FORMAT_VERSION = 2
BATCH_MIN = 64
ROWS = ("Bx", "By", "Bz", "dBx/dx", "dBx/dy", "dBx/dz", "dBy/dy", "dBy/dz")
UNITS = {"A_rows_0_2": "T/A", "A_rows_3_7": "T/(m A)", "dG": "T/(m^2 A)", "grid": "m",
         "moment": "A m^2", "current": "A"}
_CORNERS = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)], float)


def _bad(path, what):
    return BadInputError("map file", f"a designkit force-current map ({what})", str(path))


def _correction(nc: int) -> np.ndarray:
    """(3 * nc * 15, 8 * nc): half the gradient . offset terms, see designkit.fieldmap."""
    # d(row)/dx_d as (d, q, sign); q: 0-4 = gxx gxy gxz gyy gyz, 5-11 = T xxx..yyz
    grad = {0: [(0, 0, 1), (1, 1, 1), (2, 2, 1)], 1: [(0, 1, 1), (1, 3, 1), (2, 4, 1)],
            2: [(0, 2, 1), (1, 4, 1), (2, 0, -1), (2, 3, -1)],
            3: [(0, 5, 1), (1, 6, 1), (2, 7, 1)], 4: [(0, 6, 1), (1, 8, 1), (2, 9, 1)],
            5: [(0, 7, 1), (1, 9, 1), (2, 5, -1), (2, 8, -1)],
            6: [(0, 8, 1), (1, 10, 1), (2, 11, 1)],
            7: [(0, 9, 1), (1, 11, 1), (2, 6, -1), (2, 10, -1)]}
    big = np.zeros((3, nc, 15, 8, nc), dtype=np.float32)
    for r, terms in grad.items():
        for d, q, sgn in terms:
            for k in range(nc):
                big[d, k, 3 + q, r, k] += 0.5 * sgn
    return big.reshape(3 * nc * 15, 8 * nc)


NAMES = ("A", "dG", "A_fine", "dG_fine")


def _all_names(keys) -> list:
    rz = sorted((k for k in keys if k.startswith("RZ") and k[2:].isdigit()),
                key=lambda k: int(k[2:]))
    return [k for k in NAMES if k in keys] + rz


def _prepare_rz(tables: list, metas: list, positions, rotations) -> list:
    """Per coil type, what :func:`interpolate_rz` needs (numpy only)."""
    prepared = []
    for tab, m in zip(tables, metas):
        idx = np.asarray(m["coils"], dtype=np.intp)
        rot = np.asarray(rotations, float)[idx]
        pos = np.asarray(positions, float)[idx]
        identity = bool(np.all(rot == np.eye(3)))
        shared_z = identity and bool(np.all(pos[:, 2] == pos[0, 2]))
        n_rho, n_u, _ = tab.shape
        nodes = np.ascontiguousarray(tab, dtype=np.float32).reshape(-1).view(np.complex128)
        prepared.append({
            "idx": idx,
            "all": bool(len(idx) == len(positions) and np.all(idx == np.arange(len(idx)))),
            "pos32": pos.astype(np.float32), "pos": pos, "rot": None if identity else rot,
            "shared_z": shared_z, "nodes": nodes, "n_rho": n_rho, "n_u": n_u,
            "inv_h": 1.0 / m["rho_step_m"], "inv_scale": 1.0 / m["rho_scale_m"],
            "z_ref": m["z_ref_m"], "u0": m["u0"],
            "inv_du": 1.0 / m["u_step"]})
    return prepared


_WORK = threading.local()
RZ_CHUNK = 4096
"""Points per block of :func:`interpolate_rz` (bounds its scratch memory, keeps it in cache)."""


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
    """The batch kernel: points (n, 3) inside the box -> A (n, 8, nc) float64 (a strided view:
    rows outermost in memory).

    numpy only (designkit.fieldmap imports this one definition). Per (point, coil) pair everything is
    flat and contiguous -- numpy is fast on long inner loops and slow on short ones -- and
    written into reused scratch buffers; a node's 4 float32 quantities are gathered as one
    16-byte element (viewed as complex128).
    """
    n = len(p)
    out = np.empty((8, n, nc))
    for s in range(0, n, RZ_CHUNK):
        e = min(n, s + RZ_CHUNK)
        for t in prepared:
            _rz_block(t, p[s:e], out[:, s:e])
    return out.transpose(1, 0, 2)


def _rz_block(t: dict, p: np.ndarray, out: np.ndarray) -> None:
    """One coil type, one block of points: rows into ``out`` (8, n, nc)[..., t['idx']]."""
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
            z = p[:, 2] - (t["pos"][0, 2] + t["z_ref"])
        else:
            z = (p[:, 2:3] - (t["pos"][:, 2] + t["z_ref"])).reshape(m)
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
    c = _scratch("c", 4 * m, np.complex128).reshape(4, m)
    # mode='clip' (indices are in range): with the default 'raise', out= costs a copy
    np.take(nodes, i, out=c[0], mode="clip")
    i += 1
    np.take(nodes, i, out=c[1], mode="clip")
    i += n_u
    np.take(nodes, i, out=c[3], mode="clip")
    i -= 1
    np.take(nodes, i, out=c[2], mode="clip")
    cf = c.view(f32)  # (4, 4 m): per pair the 4 quantities of a corner
    # along u on both rho rows, then along rho with the 4 quantities transposed to rows
    tzb = tz[:, None] if t["shared_z"] else np.repeat(tz, 4).reshape(m, 4)
    for lo, hi in ((0, 1), (2, 3)):
        a, b = cf[lo].reshape(n, -1), cf[hi].reshape(n, -1)
        if not t["shared_z"]:
            a, b = a.reshape(m, 4), b.reshape(m, 4)
        b -= a
        b *= tzb
        b += a
    q = _scratch("q", 4 * m, f32).reshape(4, m)
    lo_t = cf[1].reshape(m, 4).T
    np.subtract(cf[3].reshape(m, 4).T, lo_t, out=q)
    q *= tr
    q += lo_t
    bb, bz, e, w = q
    # Bx = b x, By = b y, Bz, Gxx = b + w x^2, Gxy = w x y, Gxz = e x, Gyy = b + w y^2, Gyz = e y
    rows = _scratch("rows", 8 * m, f32).reshape(8, m)
    np.multiply(bb, x, out=rows[0])
    np.multiply(bb, y, out=rows[1])
    rows[2] = bz
    np.multiply(w, x, out=rows[4])  # w x, reused
    np.multiply(rows[4], x, out=rows[3])
    rows[3] += bb
    rows[4] *= y
    np.multiply(e, x, out=rows[5])
    np.multiply(w, y, out=rows[6])
    rows[6] *= y
    rows[6] += bb
    np.multiply(e, y, out=rows[7])
    rows = rows.reshape(8, n, k)
    if t["rot"] is not None:
        rows = _rotate_rows(rows, t["rot"])
    if t["all"]:
        out[...] = rows
    else:
        out[:, :, t["idx"]] = rows


def _rotate_rows(rows: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Local rows (8, n, k) of coils with rotations (k, 3, 3) -> global rows (8, n, k)."""
    b = rows[:3].astype(np.float64)
    gxx, gxy, gxz, gyy, gyz = rows[3:].astype(np.float64)
    g = np.stack([np.stack([gxx, gxy, gxz]), np.stack([gxy, gyy, gyz]),
                  np.stack([gxz, gyz, -gxx - gyy])])  # (3, 3, n, k)
    bg = np.einsum("kia,ank->ink", rot, b)
    gg = np.einsum("kia,abnk,kjb->ijnk", rot, g, rot)
    return np.stack([bg[0], bg[1], bg[2], gg[0, 0], gg[0, 1], gg[0, 2], gg[1, 1], gg[1, 2]])


def _pack(a, dg, nc):
    return np.ascontiguousarray(np.concatenate([a, dg], axis=3).transpose(0, 1, 2, 4, 3)
                                .reshape(a.shape[:3] + (15 * nc,)))


def _interp(data, grid, p, nc, corr):
    """(n, 3) points -> (n, 8, nc): trilinear weights + half the gradient . offset terms."""
    lo = np.asarray(grid["lower_m"], float)
    step = np.asarray(grid["spacing_m"], float)
    shape = np.asarray(grid["shape"])
    nx, ny, nz = (int(x) for x in shape)
    f = (p - lo) / step
    i = np.clip(np.floor(f).astype(np.intp), 0, shape - 2)
    t = f - i
    n = len(p)
    w = (np.stack([1 - t[:, 0], t[:, 0]], 1)[:, :, None, None]
         * np.stack([1 - t[:, 1], t[:, 1]], 1)[:, None, :, None]
         * np.stack([1 - t[:, 2], t[:, 2]], 1)[:, None, None, :]).reshape(n, 8)
    wd = w[:, None, :] * ((t[:, None, :] - _CORNERS[None]) * step).transpose(0, 2, 1)
    wall = np.concatenate([w[:, None, :], wd], axis=1).astype(np.float32)  # (n, 4, 8)
    base = (i[:, 0] * ny + i[:, 1]) * nz + i[:, 2]
    offs = np.array([0, 1, nz, nz + 1, ny * nz, ny * nz + 1, ny * nz + nz, ny * nz + nz + 1])
    corners = np.take(data.reshape(nx * ny * nz, -1), base[:, None] + offs, axis=0)
    s = np.matmul(wall, corners)  # (n, 4, nc * 15)
    c = s[:, 1:, :].reshape(n, -1) @ corr  # (n, 8 * nc)
    res = s[:, 0, :].reshape(n, nc, 15)[:, :, :8].transpose(0, 2, 1) + c.reshape(n, 8, nc)
    return res.astype(np.float64)


@dataclass(frozen=True)
class MapFile:
    """A validated map: ``bounds`` (lower, upper) corners in m, ``meta`` dict, ``actuation``."""

    data: np.ndarray  # (nx, ny, nz, n_coils * 15) float32
    fine: np.ndarray | None  # the same on the bottom slab (meta['fine_grid']) or None
    meta: dict
    bounds: tuple
    n_coils: int
    corr: np.ndarray
    rz: tuple = ()  # prepared (rho, z) tables of the batch path

    @classmethod
    def load(cls, path, expected_design_sha256: str | None = None) -> "MapFile":
        p = Path(path)
        if not p.is_file():
            raise BadInputError("map file", "a path to an existing .npz map", str(p))
        try:
            with np.load(p, allow_pickle=False) as z:
                if not {"A", "dG", "meta"} <= set(z.files):
                    raise _bad(p, f"arrays A, dG, meta; found {sorted(z.files)}")
                meta = json.loads(str(z["meta"]))
                arrays = {k: z[k] for k in _all_names(z.files)}
        except BadInputError:
            raise
        except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as exc:
            raise _bad(p, f"readable npz; {type(exc).__name__}: {exc} -- truncated or foreign")
        if not isinstance(meta, dict) or meta.get("format") != FORMAT or \
                meta.get("version") != FORMAT_VERSION:
            raise _bad(p, f"format {FORMAT!r} version {FORMAT_VERSION}")
        if meta.get("units") != UNITS or tuple(meta.get("rows", ())) != ROWS:
            raise _bad(p, f"units {UNITS}, rows {ROWS}")
        nc = int(meta["n_coils"])
        levels = [("", meta["grid"])]
        if meta.get("fine_grid") is not None:
            levels.append(("_fine", meta["fine_grid"]))
        for suffix, grid in levels:
            shape = tuple(grid["shape"])
            a, dg = arrays.get("A" + suffix), arrays.get("dG" + suffix)
            if a is None or dg is None or a.shape != shape + (8, nc) or \
                    dg.shape != shape + (7, nc) or min(shape) < 2:
                raise _bad(p, f"A{suffix} {shape + (8, nc)}, dG{suffix} {shape + (7, nc)}")
            if not (np.all(np.isfinite(a)) and np.all(np.isfinite(dg))):
                raise _bad(p, "finite values only")
        tabs = meta.get("rz_tables")
        if not isinstance(tabs, list):
            raise _bad(p, "meta.rz_tables (a list)")
        for k, t in enumerate(tabs):
            try:
                shape = tuple(t["shape"])
                tab = arrays.get(t["name"])
                ok = (t["name"] == f"RZ{k}" and tab is not None and tab.shape == shape
                      and tab.dtype == np.float32 and len(shape) == 3 and shape[2] == 4
                      and min(shape) >= 2 and t["rho_step_m"] > 0 and t["u_step"] > 0
                      and t["rho_scale_m"] > (shape[0] - 1) * t["rho_step_m"]
                      and len(t["coils"]) > 0 and all(0 <= c < nc for c in t["coils"]))
            except (KeyError, TypeError):
                ok = False
            if not ok:
                raise _bad(p, f"rz_tables[{k}] describing a float32 array RZ{k} (n_rho, n_u, 4)")
            if not np.all(np.isfinite(tab)):
                raise _bad(p, "finite values only")
        h = hashlib.sha256()
        for name in _all_names(arrays):
            h.update(np.ascontiguousarray(arrays[name]).tobytes())
        if h.hexdigest() != meta.get("data_sha256"):
            raise _bad(p, "data matching its recorded SHA-256 (corrupted)")
        if expected_design_sha256 is not None and meta["design_sha256"] != expected_design_sha256:
            raise _bad(p, f"design SHA-256 {expected_design_sha256[:12]}..., got "
                       f"{meta['design_sha256'][:12]}...")
        fine = (_pack(arrays["A_fine"], arrays["dG_fine"], nc)
                if meta.get("fine_grid") is not None else None)
        g = meta["grid"]
        rz = _prepare_rz([arrays[t["name"]] for t in tabs], tabs, meta["coil_positions_m"],
                         meta["coil_rotations"])
        return cls(_pack(arrays["A"], arrays["dG"], nc), fine, meta,
                   (np.asarray(g["lower_m"], float), np.asarray(g["upper_m"], float)), nc,
                   _correction(nc), tuple(rz))

    def actuation(self, points, extrapolate: bool = False) -> np.ndarray:
        """A at points (3,) -> (8, n_coils) or (n, 3) -> (n, 8, n_coils), float64.

        Outside the box: BadInputError unless ``extrapolate`` (nearest cell's polynomial).
        Batches of >= BATCH_MIN points inside the box use the (rho, z) tables (result: a
        strided view), the rest the 3-D grid.
        """
        p = np.asarray(points, dtype=float)
        single = p.ndim == 1
        p = p.reshape(-1, 3)
        if not np.all(np.isfinite(p)):
            raise BadInputError("points", "finite (no NaN or Inf)", points)
        lo, hi = self.bounds
        step = np.asarray(self.meta["grid"]["spacing_m"], float)
        if not extrapolate:
            bad = np.any((p < lo - 1e-9 * step) | (p > hi + 1e-9 * step), axis=1)
            if bad.any():
                raise BadInputError("points", f"inside {lo.tolist()} .. {hi.tolist()} m",
                                    p[int(np.argmax(bad))].tolist())
        if (len(p) >= BATCH_MIN and self.rz
                and sum(len(t["idx"]) for t in self.rz) == self.n_coils
                and (not extrapolate or np.all((p >= lo) & (p <= hi)))):
            res = interpolate_rz(self.rz, p, self.n_coils)
            return res[0] if single else res
        res = np.empty((len(p), 8, self.n_coils))
        infine = np.zeros(len(p), dtype=bool)
        if self.fine is not None:
            g = self.meta["fine_grid"]
            infine = np.all((p >= g["lower_m"]) & (p <= g["upper_m"]), axis=1)
            if infine.any():
                res[infine] = _interp(self.fine, g, p[infine], self.n_coils, self.corr)
        if not infine.all():
            res[~infine] = _interp(self.data, self.meta["grid"], p[~infine], self.n_coils,
                                   self.corr)
        return res[0] if single else res

    def currents_for(self, point, wanted: np.ndarray, rows=slice(None)) -> np.ndarray:
        """Least-norm currents (A) with A[rows] I = wanted at ``point`` (pseudo-inverse)."""
        a = self.actuation(point)[rows]
        return np.linalg.lstsq(a, np.asarray(wanted, float), rcond=None)[0]


def _self_check():  # pragma: no cover - manual use on the target host
    import sys

    m = MapFile.load(sys.argv[1])
    lo, hi = m.bounds
    print(m.meta["grid"], m.actuation((lo + hi) / 2).shape)


if __name__ == "__main__":  # pragma: no cover
    _self_check()
