"""Question: can A(p) of the coupled default array be stored as per-cell polynomials (fast
lookups: one small matmul per cell) within the map file's targets -- interpolation error
<= 1e-3 of each row's largest |A| over the box, file <= 5 MB, build <= 30 s -- and how large
may a cell be at each height?

Two per-cell forms of all 8 rows x n_coils outputs, on cells above a core's axis, its rim,
between cores and at the box corner, against the coupled model (``CoilArray.actuation_matrix``):

* ``tensor``: tensor-product Chebyshev interpolation of degree d per axis of every output
  ((d + 1)^3 coefficients per output; the lookup a basis row @ (.., 8 n_coils));
* ``harmonic``: the magnetic scalar potential of each coil (the box is current-free, so
  B = grad phi with phi harmonic) as a harmonic polynomial of degree L ((L + 1)^2 - 1
  coefficients per coil, constant dropped), least squares on Chebyshev nodes of all 8 rows
  (each row weighted by 1 / its row max); the 8 rows are its first and second derivatives, so
  a cell stores (L + 1)^2 - 1 numbers per coil instead of the tensor form's 8 (d + 1)^3.

Per configuration it prints the worst error over the sites and check points, relative to each
row's largest |A| over a box sample (the map's acceptance measure), the bytes per cell at int16
(what the file would hold), how many such cells tile one layer of the box, and the
multiply-adds per point of a batch lookup in monomial form (float32 matmul). References, in
the same process: the direct model's cost per point (which sets what a build can afford to fit
against within 30 s), one (1e4, K) @ (K, 8 n_coils) float32 matmul against the per-cell
loop of a batch lookup (50 .. 1400 cells), one 8 x n_coils matvec against a harmonic lookup.

    python studies/map_cells.py [OUT_DIR]        (default out/map_cells)
"""

from __future__ import annotations

import argparse
import itertools
import math
import sys
import time
from pathlib import Path
from timeit import repeat

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
from numpy.polynomial import chebyshev as cheb

from designkit import default_design, fieldmap
from designkit.support.atomic import write_json_atomic
from designkit.model.array import CoilArray

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "map_cells"
"""Default output folder (git-ignored), whatever the working directory."""

# (z of the cell bottom above the coil tops m, cell height m, lateral cell size m, kind, degree)
CONFIGS = (
    (0.010, 0.005, 0.005, "tensor", 3), (0.010, 0.0025, 0.0025, "tensor", 3),
    (0.010, 0.005, 0.005, "tensor", 5), (0.015, 0.005, 0.005, "tensor", 3),
    (0.020, 0.010, 0.010, "tensor", 3), (0.030, 0.010, 0.010, "tensor", 3),
    (0.010, 0.005, 0.005, "harmonic", 8), (0.010, 0.005, 0.005, "harmonic", 10),
    (0.015, 0.010, 0.010, "harmonic", 10), (0.030, 0.025, 0.025, "harmonic", 8),
    (0.050, 0.030, 0.025, "harmonic", 6))
QUICK = ((0.030, 0.010, 0.010, "tensor", 2), (0.030, 0.010, 0.010, "harmonic", 4))


def _cheb_nodes(n: int) -> np.ndarray:
    return np.cos(np.pi * (np.arange(n) + 0.5) / n)


def exponents(degree: int) -> np.ndarray:
    """(M, 3) exponents of the monomials x^a y^b z^c of total degree <= ``degree``."""
    return np.array([e for n in range(degree + 1)
                     for e in itertools.product(range(n + 1), repeat=3) if sum(e) == n])


def harmonic_rows(degree: int) -> tuple[np.ndarray, list]:
    """Monomial exponents (M, 3) and, per row of A, the (M, K) map from the K = (L + 1)^2 - 1
    harmonic-polynomial coefficients of the potential to that row's monomial coefficients
    (rows: d/dx, d/dy, d/dz, d2/dx2, d2/dxdy, d2/dxdz, d2/dy2, d2/dydz)."""
    e = exponents(degree)
    index = {tuple(x): i for i, x in enumerate(e)}
    e2 = exponents(degree - 2)
    index2 = {tuple(x): i for i, x in enumerate(e2)}
    lap = np.zeros((len(e2), len(e)))
    for i, x in enumerate(e):
        for ax in range(3):
            if x[ax] >= 2:
                y = list(x)
                y[ax] -= 2
                lap[index2[tuple(y)], i] += x[ax] * (x[ax] - 1)
    # null space of the Laplacian without the constant: the harmonic polynomials
    _, _, vt = np.linalg.svd(np.vstack([lap, np.eye(len(e))[:1]]))
    h = vt[len(e2) + 1:].T

    def d(ax):
        m = np.zeros((len(e), len(e)))
        for i, x in enumerate(e):
            if x[ax] >= 1:
                y = list(x)
                y[ax] -= 1
                m[index[tuple(y)], i] = x[ax]
        return m

    dx, dy, dz = d(0), d(1), d(2)
    return e, [op @ h for op in (dx, dy, dz, dx @ dx, dy @ dx, dz @ dx, dy @ dy, dz @ dy)]


def _monomials(e: np.ndarray, s: np.ndarray) -> np.ndarray:
    return np.prod(s[:, None, :] ** e[None], axis=2)


def cell_error(arr: CoilArray, centre, half, kind: str, degree: int, row_max: np.ndarray,
               rng, n_check: int = 40) -> float:
    """Worst |fit - direct| / row max over ``n_check`` random points of one cell."""
    half = np.asarray(half, float)
    y = rng.uniform(-1, 1, (n_check, 3))
    direct = arr.actuation_matrix(centre + y * half)
    if kind == "tensor":
        x = _cheb_nodes(degree + 1)
        xn = np.stack(np.meshgrid(x, x, x, indexing="ij"), -1).reshape(-1, 3)
        v = cheb.chebvander3d(*xn.T, [degree] * 3)
        a = arr.actuation_matrix(centre + xn * half).reshape(len(xn), -1)
        c = np.linalg.solve(v, a)
        got = (cheb.chebvander3d(*y.T, [degree] * 3) @ c).reshape(direct.shape)
    else:
        e, ops = harmonic_rows(degree)
        r = float(half.max())  # isotropic scaling keeps the polynomials harmonic
        x = _cheb_nodes(degree // 2 + 2)
        xn = np.stack(np.meshgrid(x, x, x, indexing="ij"), -1).reshape(-1, 3) * half
        scale = [r] * 3 + [r * r] * 5

        def design(pts):
            m = _monomials(e, pts / r)
            return np.stack([m @ op / s for op, s in zip(ops, scale)], 1)  # (n, 8, K)

        g = design(xn) / row_max[None, :, None]
        a = arr.actuation_matrix(centre + xn) / row_max[None, :, None]
        coef = np.linalg.lstsq(g.reshape(-1, g.shape[2]), a.reshape(-1, a.shape[2]),
                               rcond=None)[0]
        got = design(y * half) @ coef
    return float((np.abs(got - direct).max(axis=(0, 2)) / row_max).max())


def batch_cost(n_points: int, cells, widths, nc: int) -> list:
    """Time (min of 5 runs, ms) of the per-cell lookup's core -- points sorted by cell, one
    float32 (n_c, K) @ (K, 8 n_coils) matmul per occupied cell -- for ``n_points`` points
    spread evenly over ``cells`` cells, against one (n_points, K) @ (K, 8 n_coils) matmul
    (the same arithmetic without the per-cell loop)."""
    rng = np.random.default_rng(1)
    out = []
    print(f"{'cells':>6} {'K':>4} {'loop ms':>8} {'one matmul ms':>13} {'ratio':>6}")
    for k in widths:
        v = rng.random((n_points, k), dtype=np.float32)
        res = np.empty((n_points, 8 * nc), np.float32)
        c1 = rng.random((k, 8 * nc), dtype=np.float32)
        np.matmul(v, c1, out=res)  # warm-up (BLAS threads, page faults)
        one = min(repeat(lambda: np.matmul(v, c1, out=res), number=3, repeat=5)) / 3
        for n_cells in cells:
            cs = rng.random((n_cells, k, 8 * nc), dtype=np.float32)
            edges = np.linspace(0, n_points, n_cells + 1).astype(int).tolist()

            def loop():
                for i in range(n_cells):
                    s, e = edges[i], edges[i + 1]
                    np.matmul(v[s:e], cs[i], out=res[s:e])

            loop()
            t = min(repeat(loop, number=1, repeat=5))
            out.append({"cells": n_cells, "K": k, "loop_ms": t * 1e3, "one_matmul_ms": one * 1e3})
            print(f"{n_cells:6d} {k:4d} {t * 1e3:8.2f} {one * 1e3:13.2f} {t / one:6.1f}")
    return out


def one_point_cost(degrees, nc: int, n_cells: int = 900) -> list:
    """Time (min of 7, us) of one point's lookup in a harmonic cell of potential degree L in
    monomial form (random coefficients): the cell by closed-form floor divisions in Python,
    the C(L + 2, 3) monomials of degree <= L - 1 from the per-axis powers, one
    (K,) @ (K, 8 n_coils) product; against one 8 x n_coils @ n_coils numpy matvec (the cost of
    a single numpy call)."""
    rng = np.random.default_rng(2)
    a, v = rng.random((8, nc)), rng.random(nc)
    ref = min(repeat(lambda: a @ v, number=2000, repeat=7)) / 2000
    out = []
    print(f"{'L':>3} {'K':>4} {'one point us':>12} {'ref call us':>11} {'ratio':>6}")
    for deg in degrees:
        ex, ey, ez = exponents(deg - 1).T.copy()
        coef = rng.random((n_cells, len(ex), 8 * nc))
        powers = np.arange(deg)
        side = int(math.isqrt(n_cells))

        def one(q=(0.0123, -0.0311, 0.0121)):
            c = int((q[0] + 0.075) * 200.0) * side + int((q[1] + 0.075) * 200.0)
            pw = (np.array(q) * 400.0)[:, None] ** powers  # local coordinates, (3, L)
            return (pw[0, ex] * pw[1, ey] * pw[2, ez] @ coef[c]).reshape(8, nc)

        one()
        t = min(repeat(one, number=2000, repeat=7)) / 2000
        out.append({"L": deg, "K": len(ex), "one_point_us": t * 1e6, "ref_call_us": ref * 1e6})
        print(f"{deg:3d} {len(ex):4d} {t * 1e6:12.1f} {ref * 1e6:11.2f} {t / ref:6.1f}")
    return out


def sites(arr: CoilArray, lo, hi) -> list:
    """Lateral cell centres (x, y) m: above the axis and the rim of the core nearest the
    box centre, above the outer rim of the core nearest the box corner, between those two
    cores, the box corner."""
    pos = arr.positions()[:, :2]
    mid = pos[np.argmin(np.linalg.norm(pos - (lo[:2] + hi[:2]) / 2, axis=1))]
    far = pos[np.argmin(np.linalg.norm(pos - hi[:2], axis=1))]
    r = arr.coils[0].core.radius if arr.coils[0].core is not None else arr.coils[0].outer_radius
    out_dir = (far - mid) / max(np.linalg.norm(far - mid), 1e-12)
    return [mid, mid + [r, 0.0], far + out_dir * r, (mid + far) / 2, hi[:2] - 0.004]


def run(out_dir=DEFAULT_OUT, quick: bool = False) -> dict:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    # the box this study was run for: the workspace floor was 10 mm above the coil tops then
    # (20 mm since; the cells' heights below are above the coil tops either way)
    design = default_design().replace(**{"workspace.z_min_m": 0.010})
    if quick:  # air coils over a small box: no coupled solve, seconds
        design = design.replace(**{"core": None, "workspace.shape": "box",
                                   "workspace.half_width_m": 0.03, "workspace.z_max_m": 0.03})
    arr = CoilArray.from_design(design)
    lo, hi = fieldmap.default_box(design)
    rng = np.random.default_rng(20261123)
    n_sample = 60 if quick else 2000
    p = rng.uniform(lo, hi, (n_sample, 3))
    p[n_sample // 2:, 2] = rng.uniform(lo[2], lo[2] + 0.002, n_sample - n_sample // 2)
    arr.actuation_matrix(p[:4])  # the coupled solve, once
    t0 = time.perf_counter()
    row_max = np.abs(arr.actuation_matrix(p)).max(axis=(0, 2))
    direct_us = (time.perf_counter() - t0) / n_sample * 1e6
    nc = arr.n_coils
    print(f"direct coupled model: {direct_us:.0f} us/point ({n_sample} points); 1e5 fit nodes "
          f"would take {direct_us * 0.1:.0f} s (build budget 30 s)")
    print(f"{'z0 mm':>6} {'dz mm':>6} {'h mm':>5} {'kind':>9} {'deg':>3} {'max err':>8} "
          f"{'B/cell':>7} {'cells/layer':>11} {'MB/layer':>8} {'MAC/pt':>7}")
    rows = []
    for z0, dz, h, kind, deg in (QUICK if quick else CONFIGS):
        half = np.array([h / 2, h / 2, dz / 2])
        errs = [cell_error(arr, np.array([x, y, z0 + dz / 2]), half, kind, deg,
                           row_max, rng, 8 if quick else 40)
                for x, y in sites(arr, lo, hi)[:2 if quick else None]]
        if kind == "tensor":
            n_coef, n_mono = (deg + 1) ** 3 * 8 * nc, (deg + 1) ** 3
        else:
            n_coef, n_mono = ((deg + 1) ** 2 - 1) * nc, math.comb(deg + 2, 3)
        per_layer = math.ceil((hi[0] - lo[0]) / h - 1e-9) * math.ceil((hi[1] - lo[1]) / h - 1e-9)
        row = {"z0_m": z0, "dz_m": dz, "h_m": h, "kind": kind, "degree": deg,
               "max_rel": max(errs), "bytes_per_cell": 2 * n_coef, "cells_per_layer": per_layer,
               "mb_per_layer": 2 * n_coef * per_layer / 1e6, "mac_per_point": n_mono * 8 * nc}
        rows.append(row)
        print(f"{z0 * 1e3:6.1f} {dz * 1e3:6.1f} {h * 1e3:5.1f} {kind:>9} {deg:3d} "
              f"{row['max_rel']:8.1e} {row['bytes_per_cell']:7d} {per_layer:11d} "
              f"{row['mb_per_layer']:8.2f} {row['mac_per_point']:7d}")
    loop = batch_cost(n_points=2000 if quick else 10000,
                      cells=(10, 50) if quick else (50, 300, 1400), widths=(64, 220), nc=nc)
    one = one_point_cost((6,) if quick else (6, 8, 10), nc)
    res = {"direct_us_per_point": direct_us, "row_max": row_max.tolist(), "configs": rows,
           "batch_cost": loop, "one_point": one}
    write_json_atomic(out_dir / "map_cells.json", res)
    return res


def main(argv=None) -> int:

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", nargs="?", default=str(DEFAULT_OUT),
                    help="output folder (default out/map_cells)")
    run(ap.parse_args(argv).out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
