"""Read the force-current map written by ``designkit map`` -- numpy and the standard library only.

The file (``.npz``): ``A`` (nx, ny, nz, 8, n_coils) float32 with rows Bx, By, Bz, dBx/dx,
dBx/dy, dBx/dz, dBy/dy, dBy/dz (T/A and T/(m A)); ``dG`` (nx, ny, nz, 7, n_coils) float32, the
third derivatives T_xxx, T_xxy, T_xxz, T_xyy, T_xyz, T_yyy, T_yyz (T/(m^2 A)); ``meta``, a JSON
string (grid, units, coil poses, magnet moment, limits, hashes). designkit.fieldmap documents the
format and the interpolation; this module repeats the interpolation so the runner never imports
designkit.

    m = MapFile.load("fieldmap.npz")
    a = m.actuation((0.0, 0.0, 0.03))        # (8, n_coils)
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import BadInputError

FORMAT = "designkit-fieldmap"
FORMAT_VERSION = 1
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
                arrays = {k: z[k] for k in NAMES if k in z.files}
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
        h = hashlib.sha256()
        for name in NAMES:
            if name in arrays:
                h.update(np.ascontiguousarray(arrays[name]).tobytes())
        if h.hexdigest() != meta.get("data_sha256"):
            raise _bad(p, "data matching its recorded SHA-256 (corrupted)")
        if expected_design_sha256 is not None and meta["design_sha256"] != expected_design_sha256:
            raise _bad(p, f"design SHA-256 {expected_design_sha256[:12]}..., got "
                       f"{meta['design_sha256'][:12]}...")
        fine = (_pack(arrays["A_fine"], arrays["dG_fine"], nc)
                if meta.get("fine_grid") is not None else None)
        g = meta["grid"]
        return cls(_pack(arrays["A"], arrays["dG"], nc), fine, meta,
                   (np.asarray(g["lower_m"], float), np.asarray(g["upper_m"], float)), nc,
                   _correction(nc))

    def actuation(self, points, extrapolate: bool = False) -> np.ndarray:
        """A at points (3,) -> (8, n_coils) or (n, 3) -> (n, 8, n_coils), float64.

        Outside the box: BadInputError unless ``extrapolate`` (nearest cell's polynomial).
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
