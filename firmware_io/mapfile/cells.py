"""A(p) from the harmonic cells: the cell of a point and the per-cell products (numpy only).

:func:`prepare_cells` expands every cell's potential coefficients once, at load, into its rows'
coefficients on the solid harmonics of degree <= L - 1, (L^2, 8 n_coils) float32 per cell. One
point (:func:`cells_one`) finds its cell with Python arithmetic (its layer by z, then two floor
divisions) and takes its monomials @ the harmonics' monomial coefficients @ the cell's matrix.
Blocks of points (:func:`cells_many`) get their cells and cell-local coordinates in one pass
(:func:`cell_local`), are sorted by cell, their solid harmonics computed once, then one float32
product per occupied cell; the rows are gathered back to the caller's order. Outside the box a
point takes its nearest layer's and grid's cell. Points in m, A in T/A and T/(m A) (rows
``ROWS``). Costs and their measurement: docs/mapfile_format.md.
"""

from __future__ import annotations

import bisect
import threading

import numpy as np

from .harmonics import monomial_exponents, rows_on_harmonics, solid_harmonics

def prepare_cells(layers: list, tables: list, nc: int) -> dict:
    """What the A lookups need: per cell its rows on the solid harmonics of degree <= L - 1,
    (L^2, 8 nc) float32 (coefficients x :func:`rows_on_harmonics`, in T/A and T/(m A) per
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
        ops, hc = rows_on_harmonics(deg)  # (8, H, K), (M, H)
        scale = np.array([r] * 3 + [r * r] * 5)[:, None, None]
        h = ops.shape[1]
        # (n_cells, K, nc) -> (n_cells, H, 8, nc): every row of every coil per harmonic
        rows = np.einsum("rhk,ckn->chrn", ops / scale, tab.astype(np.float64),
                         optimize=True)
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
points are split): larger products go multi-threaded in the BLAS, and on a shared machine each
such call can wait for a busy core (measurement: docs/mapfile_format.md)."""


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
    # 16-bit keys sort by radix, far cheaper than a merge sort of intp
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
