"""The force-current map: A(p) on a regular workspace grid -> one file -> fast interpolator.

File (``.npz``, written atomically): ``A`` (nx, ny, nz, 8, n_coils) float32, rows
:data:`designkit.array.ROWS`; ``dG`` (nx, ny, nz, 7, n_coils) float32, the 7 independent
third derivatives of the scalar potential, T_ijk = d(dB_i/dx_j)/dx_k, in the order
(xxx, xxy, xxz, xyy, xyz, yyy, yyz) (T is fully symmetric and traceless outside the sources);
``RZ0``, ``RZ1``, ...: one axisymmetric table per identical coil type (meta ``rz_tables``),
(n_rho, n_u, 4) float32, the per-ampere quantities (b, Bz, e, w) of :data:`RZ_QUANTITIES` on a
grid in the coil's local frame uniform in v = rho / (1 + rho / rho_scale) and in
u = log(z - z_ref) (z_ref: the top of the coil's sources), so both steps grow with the distance
from the core's rim (0.075 mm in rho near the axis, 2.5 % of the height in z: ~1 MB);
``meta``: a JSON string (format, version, grid, units, rows, coil poses, magnet moment, drive
limits, the design's SHA-256, designkit version, SHA-256 of the arrays). The controller side
reads it with numpy alone (:mod:`firmware_io.mapfile`).

Two interpolators, the same answer to ~1e-3 of each row's maximum:

* one point or fewer than :data:`BATCH_MIN` points, or points outside the box: the 3-D grid
  (below); a 15-us call that reads 8 nodes.
* batches of >= :data:`BATCH_MIN` points inside the box: the (rho, z) tables. For every
  (point, coil) pair: local coordinates, bilinear interpolation in (v, u) of
  b = Br/rho, Bz, e = (dBr/dz)/rho and w = (dBr/drho - Br/rho)/rho^2 (all smooth and even in
  rho, finite on the axis), then, with x, y the local horizontal offsets,

      Bx = b x, By = b y, Bz,  dBx/dx = b + w x^2, dBx/dy = w x y, dBx/dz = e x,
      dBy/dy = b + w y^2, dBy/dz = e y

  (= designkit.field.cylindrical_to_cartesian with Br = b rho, dBr/drho = b + w rho^2,
  c = x/rho, s = y/rho: no division, no special case on the axis), rotated to the global
  frame for tilted coils. dBz/dz = -2 b - w rho^2 is implied by the 5-row form, and the
  full gradient rebuilt from the 5 rows is symmetric and traceless by construction. Memory
  per pair: 4 nodes x 16 bytes from a ~1 MB table that stays in cache, instead of 8 nodes x
  15 floats per coil from the 3-D grid (~40 ms for 1e4 points, memory-bound).

Interpolation (``order='quadratic'``, default): in the grid cell around p, with trilinear
weights w_c of the 8 corners and offsets d_c = p - x_c,

    f(p) = sum_c w_c [ f_c + 1/2 grad f_c . d_c ],

which reproduces every quadratic exactly (error O(h^3) instead of trilinear's O(h^2)) while
still reading only the 8 corners. grad f is known at the nodes: for the B rows it is grad B
itself (the G rows); for the G rows it is the stored tensor T. ``order='linear'`` is plain
trilinear (faster, ~5e-3 of the maximum at 2 mm).

Physics kept by construction: only the 5 independent entries of grad B are interpolated and
:func:`designkit.array.gradient_from_g5` rebuilds dBy/dx = dBx/dy, dBz/dx = dBx/dz,
dBz/dy = dBy/dz and dBz/dz = -dBx/dx - dBy/dy, so every interpolated gradient is exactly
symmetric (curl-free) and traceless (divergence-free), whatever the interpolation error.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from . import _validate as v
from .array import ROWS, CoilArray
from .errors import BadInputError

# The file format constants and the batch (rho, z) kernel have one definition, in the
# numpy-only reader the hardware runner uses; designkit imports them from there.
from firmware_io.mapfile import (  # noqa: E402
    _CORNERS,
    BATCH_MIN,
    FORMAT,
    FORMAT_VERSION,
    UNITS,
    _prepare_rz,
    interpolate_rz,
)

T_ORDER = ("xxx", "xxy", "xxz", "xyy", "xyz", "yyy", "yyz")


# ============================================================================ grid and build
def default_box(design) -> tuple[np.ndarray, np.ndarray]:
    """Workspace box (lower, upper corners, m): the footprint, z_min..z_max above the tops."""
    ws = design.workspace
    h = ws.half_width_m
    return np.array([-h, -h, ws.z_min_m]), np.array([h, h, ws.z_max_m])


def grid_axes(lower, upper, spacing: float) -> list[np.ndarray]:
    """Regular axes covering [lower, upper] exactly with spacing <= ``spacing`` (m)."""
    out = []
    for lo, hi in zip(lower, upper):
        n = max(2, int(math.ceil((hi - lo) / spacing - 1e-9)) + 1)
        out.append(np.linspace(lo, hi, n))
    return out


def _fd4(a: np.ndarray, h: float, axis: int) -> np.ndarray:
    """4th-order finite-difference derivative along ``axis`` (one-sided 5-point at the ends)."""
    a = np.moveaxis(a, axis, 0)
    n = a.shape[0]
    d = np.empty_like(a)
    if n < 5:
        d[:] = np.gradient(a, h, axis=0, edge_order=min(2, n - 1) if n > 2 else 1)
        return np.moveaxis(d, 0, axis)
    d[2:-2] = (a[:-4] - 8 * a[1:-3] + 8 * a[3:-1] - a[4:]) / (12 * h)
    d[0] = (-25 * a[0] + 48 * a[1] - 36 * a[2] + 16 * a[3] - 3 * a[4]) / (12 * h)
    d[1] = (-3 * a[0] - 10 * a[1] + 18 * a[2] - 6 * a[3] + a[4]) / (12 * h)
    d[-1] = (25 * a[-1] - 48 * a[-2] + 36 * a[-3] - 16 * a[-4] + 3 * a[-5]) / (12 * h)
    d[-2] = (3 * a[-1] + 10 * a[-2] - 18 * a[-3] + 6 * a[-4] - a[-5]) / (12 * h)
    return np.moveaxis(d, 0, axis)


def third_derivatives(a_grid: np.ndarray, spacing) -> np.ndarray:
    """T (nx, ny, nz, 7, nc) from the gradient rows of A on the grid (4th-order differences)."""
    g = a_grid[:, :, :, 3:, :]  # gxx, gxy, gxz, gyy, gyz
    d = [[_fd4(g[:, :, :, q], spacing[ax], ax) for ax in range(3)] for q in range(5)]
    gxx, gxy, gxz, gyy, gyz = range(5)
    x, y, z = range(3)
    t = [d[gxx][x],
         (d[gxx][y] + d[gxy][x]) / 2,
         (d[gxx][z] + d[gxz][x]) / 2,
         (d[gxy][y] + d[gyy][x]) / 2,
         (d[gxy][z] + d[gxz][y] + d[gyz][x]) / 3,
         d[gyy][y],
         (d[gyy][z] + d[gyz][y]) / 2]
    return np.stack(t, axis=3)


def compute_grid(array: CoilArray, axes, *, tolerance: float = 4e-4, progress: bool = True,
                 tables: dict | None = None, cover=()):
    """A (nx, ny, nz, 8, n_coils) and T (nx, ny, nz, 7, n_coils) on the grid ``axes`` (m).

    One (rho, z) table per coil type (designkit.scene) covering the whole box, refined until its
    error is below ``tolerance`` / 4 of each component's maximum; T comes from the splines'
    derivatives. Coil types whose sources reach into the box are evaluated directly and T is
    then None (the caller falls back to finite differences of the grid). Returns
    ``(A, T, tables)``; pass ``tables`` back in to reuse them for another grid. ``cover``:
    more grids (lists of 3 axes) the new tables must also cover.
    """
    from ._progress import tqdm

    from .scene import _COMP, _rz_direct, assemble, build_table

    X, Y, Z = np.meshgrid(*axes, indexing="ij")
    pts = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    n, nc = len(pts), array.n_coils
    per = {"B": np.zeros((n, 3, nc)), "gradient": np.zeros((n, 5, nc))}
    tables = dict(tables or {})
    todo = []
    every = np.vstack([pts] + [np.stack(np.meshgrid(*ax, indexing="ij"), -1).reshape(-1, 3)
                               for ax in cover])
    for proto, idx in array.coil_types().items():
        locs = [array.coils[k].pose.to_local(every) for k in idx]
        rho = np.concatenate([np.hypot(l[:, 0], l[:, 1]) for l in locs])
        zl = np.concatenate([l[:, 2] for l in locs])
        old = tables.get(proto)
        if proto in tables and (old is None or old.covers(rho, zl)):
            continue
        if old is not None:  # widen a table built for another grid to cover this one too
            rho = np.r_[rho, old.rho_nodes[[0, -1]]]
            zl = np.r_[zl, old.z_nodes[[0, -1]]]
        todo.append((proto, (rho.min(), rho.max()), (zl.min(), zl.max())))
    for proto, r_range, z_range in tqdm(todo, desc="map: (rho, z) tables", unit="type",
                                        disable=not progress, leave=False):
        tables[proto] = build_table(proto, r_range, z_range, _COMP, 0.25 * tolerance)
    chunk = 20000
    t_all = np.zeros((n, 7, nc))
    have_t = True
    work = [(proto, k, s) for proto, idx in array.coil_types().items() for k in idx
            for s in range(0, n, chunk)]
    for proto, k, s0 in tqdm(work, desc="map", unit="chunk", disable=not progress,
                             leave=False):
        sl = slice(s0, min(n, s0 + chunk))
        coil = array.coils[k]
        loc = coil.pose.to_local(pts[sl])
        rho, zl = np.hypot(loc[:, 0], loc[:, 1]), loc[:, 2]
        tb = tables[proto]
        if tb is None:
            part = _rz_direct(proto, rho, zl, True)
            have_t = False
        else:
            part = tb(rho, zl, _COMP)
            part["dbr_drho"] = -part["dbz_dz"] - part["br_over_rho"]
            part["dbz_drho"] = part["dbr_dz"]
            t_all[sl, :, k] = _third_from_table(tb, loc, rho, zl, coil)
        assemble(per, coil, k, np.arange(sl.start, sl.stop), loc, part, True, None)
    a = np.concatenate([per["B"], per["gradient"]], axis=1)
    return (a.reshape(X.shape + (8, nc)), (t_all.reshape(X.shape + (7, nc)) if have_t else None),
            tables)


def _third_from_table(tb, loc, rho, zl, coil) -> np.ndarray:
    """T (n, 7) in the global frame from the spline derivatives of Br/rho and dBz/dz.

    With b = Br/rho, f = dBz/dz, q = dBr/drho - b = -f - 2b (traceless) and c, s = cos, sin of
    the azimuth: Gxx = b + q c^2, Gxy = q c s, Gyy = b + q s^2; differentiating with
    d/dx = c d/drho - (s/rho) d/dphi, d/dy = s d/drho + (c/rho) d/dphi gives the 7 entries.
    """
    sb, sf = tb.splines["br_over_rho"], tb.splines["dbz_dz"]
    b_r, b_z = sb.ev(rho, zl, dx=1), sb.ev(rho, zl, dy=1)
    f_r, f_z = sf.ev(rho, zl, dx=1), sf.ev(rho, zl, dy=1)
    b, f = sb.ev(rho, zl), sf.ev(rho, zl)
    q = -f - 2 * b
    q_r, q_z = -f_r - 2 * b_r, -f_z - 2 * b_z
    pos = rho > 1e-9
    safe = np.where(pos, rho, 1.0)
    c = np.where(pos, loc[:, 0] / safe, 1.0)
    s = np.where(pos, loc[:, 1] / safe, 0.0)
    q_over = np.where(pos, q / safe, 0.0)  # q = O(rho^2) near the axis
    t = np.empty((len(rho), 7))
    t[:, 0] = c * b_r + c**3 * q_r + 2 * q_over * c * s * s            # xxx
    t[:, 1] = s * b_r + s * c * c * q_r - 2 * q_over * c * c * s       # xxy
    t[:, 2] = b_z + q_z * c * c                                        # xxz
    t[:, 3] = q_r * c * s * s + q_over * c * (c * c - s * s)           # xyy
    t[:, 4] = q_z * c * s                                              # xyz
    t[:, 5] = s * b_r + s**3 * q_r + 2 * q_over * s * c * c            # yyy
    t[:, 6] = b_z + q_z * s * s                                        # yyz
    if coil.pose.is_identity_rotation:
        return t
    full = _t_full(t)
    r = coil.pose.matrix
    full = np.einsum("ia,jb,kc,nabc->nijk", r, r, r, full, optimize=True)
    return np.stack([full[:, 0, 0, 0], full[:, 0, 0, 1], full[:, 0, 0, 2], full[:, 0, 1, 1],
                     full[:, 0, 1, 2], full[:, 1, 1, 1], full[:, 1, 1, 2]], 1)


def _t_full(t):
    """(n, 7) -> (n, 3, 3, 3) fully symmetric traceless tensor."""
    xxx, xxy, xxz, xyy, xyz, yyy, yyz = t.T
    xzz, yzz, zzz = -xxx - xyy, -xxy - yyy, -xxz - yyz
    val = {(0, 0, 0): xxx, (0, 0, 1): xxy, (0, 0, 2): xxz, (0, 1, 1): xyy, (0, 1, 2): xyz,
           (1, 1, 1): yyy, (1, 1, 2): yyz, (0, 2, 2): xzz, (1, 2, 2): yzz, (2, 2, 2): zzz}
    out = np.empty((len(t), 3, 3, 3))
    for i in range(3):
        for j in range(3):
            for k in range(3):
                out[:, i, j, k] = val[tuple(sorted((i, j, k)))]
    return out


# ============================================================================ (rho, z) tables
RZ_QUANTITIES = ("Br/rho", "Bz", "(dBr/dz)/rho", "(dBr/drho - Br/rho)/rho^2")
"""Per-ampere quantities of a (rho, z) table, units T/(m A), T/A, T/(m^2 A), T/(m^3 A)."""
"""Batches of at least this many points (all inside the box) use the (rho, z) tables."""


def rz_table_spec(coil, lower, upper, rho_step: float, log_step: float,
                  rho_scale: float = 0.04) -> dict | None:
    """Grid of the (v, u) table covering the box for ``coil``'s pose.

    v = rho / (1 + rho / rho_scale) (uniform steps ``rho_step``: the rho step is ``rho_step``
    on the axis and grows as (1 + rho / rho_scale)^2, like the distance to the sources) and
    u = log(z - z_ref) (uniform steps ``log_step``), z_ref the top of the coil's sources.

    None when some box point is not above all of the coil's sources (z_local <= their top):
    then the batch path uses the 3-D grid for this coil type.
    """
    from .scene import source_box

    corners = np.array([[x, y, z] for x in (lower[0], upper[0]) for y in (lower[1], upper[1])
                        for z in (lower[2], upper[2])])
    loc = coil.pose.to_local(corners)
    z_ref = source_box(coil)[2]
    # rho is convex and z linear in the point: their extremes over the box are at corners
    rho_max = float(np.hypot(loc[:, 0], loc[:, 1]).max())
    z_lo, z_hi = float(loc[:, 2].min()), float(loc[:, 2].max())
    if z_lo - z_ref < 1e-4:
        return None
    u_lo, u_hi = math.log(z_lo - z_ref), math.log(z_hi - z_ref)
    n_u = int(math.ceil((u_hi - u_lo) / log_step - 1e-9)) + 1 + 3  # 1 node below, 2 above
    v_max = rho_max / (1 + rho_max / rho_scale)
    n_rho = int(math.ceil(v_max / rho_step - 1e-9)) + 1 + 2
    if (n_rho - 1) * rho_step >= rho_scale:
        return None  # v saturates: rho_scale is too small for this box
    return {"rho_step_m": float(rho_step), "rho_scale_m": float(rho_scale),
            "z_ref_m": float(z_ref),
            "u0": float(u_lo - log_step), "u_step": float(log_step), "shape": [n_rho, n_u, 4]}


def compute_rz_table(coil, spec: dict, *, progress: bool = True, chunk: int = 8192,
                     desc: str = "map: (rho, z) table") -> np.ndarray:
    """The table (n_rho, n_u, 4) float64 of ``spec`` by direct evaluation (Coil.field, rtol
    1e-10) on the nodes; e and w on the axis by Richardson extrapolation (both are even in rho).
    """
    from ._progress import tqdm

    from .scene import _rz_direct

    n_rho, n_u, _ = spec["shape"]
    vn = spec["rho_step_m"] * np.arange(n_rho)
    rho = vn / (1 - vn / spec["rho_scale_m"])  # inverse of v = rho / (1 + rho / rho_scale)
    z = spec["z_ref_m"] + np.exp(spec["u0"] + spec["u_step"] * np.arange(n_u))
    R, Z = np.meshgrid(rho[1:], z, indexing="ij")
    r, zz = R.ravel(), Z.ravel()
    out = np.empty((n_rho, n_u, 4))
    flat = out[1:].reshape(-1, 4)
    for s in tqdm(range(0, len(r), chunk), desc=desc, unit="chunk", disable=not progress,
                  leave=False):
        sl = slice(s, s + chunk)
        d = _rz_direct(coil, r[sl], zz[sl], True)
        b = d["br_over_rho"]
        flat[sl, 0] = b
        flat[sl, 1] = d["bz"]
        flat[sl, 2] = d["dbr_dz"] / r[sl]
        flat[sl, 3] = (d["dbr_drho"] - b) / r[sl] ** 2
    d0 = _rz_direct(coil, np.zeros(n_u), z, True)
    out[0, :, 0] = d0["br_over_rho"]
    out[0, :, 1] = d0["bz"]
    # f(rho) = f0 + f2 rho^2 + O(rho^4): f0 = (r2^2 f(r1) - r1^2 f(r2)) / (r2^2 - r1^2)
    r1, r2 = rho[1] ** 2, rho[2] ** 2
    out[0, :, 2:] = (r2 * out[1, :, 2:] - r1 * out[2, :, 2:]) / (r2 - r1)
    return out


def build(design, *, spacing: float = 0.002, box=None, tolerance: float = 4e-4,
          fine_slab: float = 0.004, fine_factor: int = 2, rz_step: float = 7.5e-5,
          rz_log_step: float = 0.025, rz_rho_scale: float = 0.05, progress: bool = True,
          array: CoilArray | None = None) -> dict:
    """Compute the map of ``design`` (arrays and metadata, not yet written).

    Parameters
    ----------
    spacing : float, m
        Largest grid step (each axis gets the step that divides the box exactly).
    box : (lower, upper) or None
        Corners in m; default :func:`default_box`.
    tolerance : float
        Relative accuracy of the (rho, z) tables (default 4e-4: table error <~ 1e-4, below the
        grid interpolation error at 2 mm).
    fine_slab : float, m
        Height of a second, finer grid over the bottom of the box (0: none). Just above an
        iron core's rim the field varies on a ~5 mm scale; at 2 mm spacing the interpolation
        error there is ~8e-3 of the maximum, at 1 mm ~9e-4. Points in the slab use it.
    fine_factor : int
        The slab's spacing is ``spacing / fine_factor``.
    rz_step : float, m
        rho step of the (rho, z) tables of the batch path (default 0.125 mm: max error
        ~2e-4 of each row's maximum for the thesis coil with its core, 10 mm above the tops).
    rz_log_step : float
        Step in u = log(z - z_ref) (default 0.025: the z step is 2.5 % of the height above
        the top of the coil's sources, 0.125 mm at 5 mm above the core's rim).
    rz_rho_scale : float, m
        The rho step grows as (1 + rho / rz_rho_scale)^2 (default 40 mm: 0.5 mm at 40 mm from
        the axis, ~4 mm at the far corner), see :func:`rz_table_spec`.
    """
    from . import __version__

    spacing = v.in_range("spacing", spacing, 1e-4, 0.05, "m")
    fine_slab = v.nonnegative("fine_slab", fine_slab)
    fine_factor = v.positive_int("fine_factor", fine_factor)
    rz_step = v.in_range("rz_step", rz_step, 1e-5, 0.01, "m")
    rz_log_step = v.in_range("rz_log_step", rz_log_step, 1e-3, 0.5)
    rz_rho_scale = v.in_range("rz_rho_scale", rz_rho_scale, 1e-3, 10.0, "m")
    arr = array or CoilArray.from_design(design)
    lower, upper = default_box(design) if box is None else (np.asarray(box[0], float),
                                                            np.asarray(box[1], float))
    if not np.all(upper > lower):
        raise BadInputError("box", "lower < upper in x, y and z", (lower.tolist(), upper.tolist()))
    levels = [(lower, upper, spacing)]
    if fine_slab > 0:
        top = min(upper[2], lower[2] + fine_slab)
        levels.append((lower, np.array([upper[0], upper[1], top]), spacing / fine_factor))
    out_arrays = {}
    grids = []
    tables = None
    all_axes = [grid_axes(lo, hi, h) for lo, hi, h in levels]
    for k, (lo, hi, h) in enumerate(levels):
        axes = all_axes[k]
        a, dg, tables = compute_grid(arr, axes, tolerance=tolerance, progress=progress,
                                     tables=tables, cover=all_axes[1:] if k == 0 else ())
        steps = [float(ax[1] - ax[0]) for ax in axes]
        if dg is None:  # some coil evaluated directly (sources in the box): finite differences
            dg = third_derivatives(a, steps)
        suffix = "" if k == 0 else "_fine"
        out_arrays["A" + suffix] = a.astype(np.float32)
        out_arrays["dG" + suffix] = dg.astype(np.float32)
        grids.append({"lower_m": [float(x) for x in lo], "upper_m": [float(x) for x in hi],
                      "shape": [len(ax) for ax in axes], "spacing_m": steps})
    rz_meta = []
    for proto, idx in arr.coil_types().items():
        # the table lives in the local frame: any coil of the type gives its coverage spec;
        # take the union over the type's poses
        specs = [rz_table_spec(arr.coils[k], lower, upper, rz_step, rz_log_step, rz_rho_scale)
                 for k in idx]
        if any(s is None for s in specs):
            continue
        spec = _union_spec(specs)
        name = f"RZ{len(rz_meta)}"
        out_arrays[name] = compute_rz_table(proto, spec, progress=progress).astype(np.float32)
        rz_meta.append({"name": name, "coils": [int(k) for k in idx], **spec})
    meta = {
        "format": FORMAT, "version": FORMAT_VERSION, "designkit_version": __version__,
        "design_name": design.name, "design_sha256": design.spec_hash(),
        "grid": grids[0], "fine_grid": grids[1] if len(grids) > 1 else None,
        "rows": list(ROWS), "dG_order": list(T_ORDER), "units": UNITS,
        "rz_tables": rz_meta, "rz_quantities": list(RZ_QUANTITIES),
        "n_coils": arr.n_coils,
        "coil_positions_m": arr.positions().tolist(),
        "coil_rotations": [list(map(list, c.pose.rotation)) for c in arr.coils],
        "magnet_moment_a_m2": [0.0, 0.0, design.magnet.moment_a_m2],
        "max_current_a": design.drive.max_current_a,
        "total_current_a": design.drive.total_current_a,
        "core_model": None if arr.coils[0].core is None else arr.coils[0].core.model,
        "interpolation": "one point / small batches / outside the box: quadratic-exact "
                         "trilinear-weighted Taylor on the 3-D grid (points inside fine_grid "
                         f"use it); batches of >= {BATCH_MIN} points inside the box: bilinear "
                         "in (rho, log(z - z_ref)) on the rz_tables (see designkit.fieldmap)",
        "data_sha256": _data_hash(out_arrays),
    }
    return {**out_arrays, "meta": meta}


ARRAY_NAMES = ("A", "dG", "A_fine", "dG_fine")


def _union_spec(specs: list) -> dict:
    """One table grid covering several specs of the same coil type (same steps and z_ref)."""
    if len(specs) == 1:
        return specs[0]
    s0 = specs[0]
    u0 = min(s["u0"] for s in specs)
    u_top = max(s["u0"] + s["u_step"] * (s["shape"][1] - 1) for s in specs)
    n_u = int(math.ceil((u_top - u0) / s0["u_step"] - 1e-9)) + 1
    return {**s0, "u0": u0, "shape": [max(s["shape"][0] for s in specs), n_u, 4]}


def _all_names(arrays: dict) -> list[str]:
    """ARRAY_NAMES present, then the tables RZ0, RZ1, ... in order."""
    rz = sorted((k for k in arrays if k.startswith("RZ") and k[2:].isdigit()),
                key=lambda k: int(k[2:]))
    return [k for k in ARRAY_NAMES if k in arrays] + rz


def _data_hash(arrays: dict) -> str:
    """SHA-256 over the arrays present, in the order of :func:`_all_names`."""
    h = hashlib.sha256()
    for name in _all_names(arrays):
        h.update(np.ascontiguousarray(arrays[name]).tobytes())
    return h.hexdigest()


def write(path, data: dict) -> Path:
    """Write the map atomically (never a half-written file at ``path``)."""
    from ._io import atomic_path

    path = Path(path)
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **{k: data[k] for k in _all_names(data)},
                     meta=np.array(json.dumps(data["meta"])))
    return path


# ============================================================================ loading
def _bad(path, what: str) -> BadInputError:
    return BadInputError("map file", f"a designkit force-current map ({what})", str(path))


def read_arrays(path) -> tuple[dict, dict]:
    """Open and validate a map file: (arrays, meta). Raises BadInputError naming the problem."""
    p = Path(path)
    if not p.is_file():
        raise BadInputError("map file", "a path to an existing .npz map", str(p))
    try:
        with np.load(p, allow_pickle=False) as z:
            keys = set(z.files)
            if not {"A", "dG", "meta"} <= keys:
                raise _bad(p, f"arrays A, dG, meta; found {sorted(keys)} -- a foreign file")
            meta = json.loads(str(z["meta"]))
            arrays = {k: z[k] for k in _all_names(dict.fromkeys(keys))}
    except BadInputError:
        raise
    except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as exc:
        raise _bad(p, f"readable npz; {type(exc).__name__}: {exc} -- truncated or foreign")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise _bad(p, f"meta.format == {FORMAT!r}")
    if meta.get("version") != FORMAT_VERSION:
        raise _bad(p, f"format version {FORMAT_VERSION}, got {meta.get('version')!r}")
    if meta.get("units") != UNITS or meta.get("rows") != list(ROWS):
        raise _bad(p, f"units {UNITS} and rows {ROWS}")
    nc = int(meta["n_coils"])
    levels = [("", meta["grid"])]
    if meta.get("fine_grid") is not None:
        levels.append(("_fine", meta["fine_grid"]))
    elif "A_fine" in arrays:
        raise _bad(p, "meta.fine_grid describing A_fine")
    for suffix, grid in levels:
        shape = tuple(grid["shape"])
        a, dg = arrays.get("A" + suffix), arrays.get("dG" + suffix)
        if a is None or dg is None or a.shape != shape + (8, nc) or dg.shape != shape + (7, nc):
            raise _bad(p, f"A{suffix} of shape {shape + (8, nc)} and dG{suffix} of "
                       f"{shape + (7, nc)}; got {getattr(a, 'shape', None)} and "
                       f"{getattr(dg, 'shape', None)}")
        if min(shape) < 2:
            raise _bad(p, f"at least 2 nodes per axis, got {shape}")
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(dg))):
            raise _bad(p, "finite values only (found NaN or Inf)")
    tabs = meta.get("rz_tables")
    if not isinstance(tabs, list):
        raise _bad(p, "meta.rz_tables (a list)")
    for k, t in enumerate(tabs):
        try:
            name, shape = t["name"], tuple(t["shape"])
            ok = (name == f"RZ{k}" and len(shape) == 3 and shape[2] == 4 and min(shape) >= 2
                  and t["rho_step_m"] > 0 and t["u_step"] > 0
                  and t["rho_scale_m"] > (shape[0] - 1) * t["rho_step_m"]
                  and all(0 <= c < nc for c in t["coils"]) and len(t["coils"]) > 0)
        except (KeyError, TypeError):
            ok = False
        if not ok:
            raise _bad(p, f"meta.rz_tables[{k}] with name RZ{k}, shape (n_rho, n_u, 4), steps "
                       f"> 0 and coil indices < {nc}")
        tab = arrays.get(name)
        if tab is None or tab.shape != shape or tab.dtype != np.float32:
            raise _bad(p, f"{name} of shape {shape} float32; got "
                       f"{getattr(tab, 'shape', None)} {getattr(tab, 'dtype', None)}")
        if not np.all(np.isfinite(tab)):
            raise _bad(p, "finite values only (found NaN or Inf)")
    if _data_hash(arrays) != meta.get("data_sha256"):
        raise _bad(p, "data matching its recorded SHA-256 (corrupted)")
    return arrays, meta


# constant map of the corrections: corr[r] = 1/2 sum_d sum_q C[r, d, q] S_d[q], q over the
# 12 derivative-carrying quantities (gxx gxy gxz gyy gyz | T xxx xxy xxz xyy xyz yyy yyz)
def _correction_matrix() -> np.ndarray:
    c = np.zeros((8, 3, 12))
    gxx, gxy, gxz, gyy, gyz = range(5)
    txxx, txxy, txxz, txyy, txyz, tyyy, tyyz = range(5, 12)
    grad = {  # row -> [(d, q, sign)]: d(row)/dx_d in terms of the stored quantities
        0: [(0, gxx, 1), (1, gxy, 1), (2, gxz, 1)],
        1: [(0, gxy, 1), (1, gyy, 1), (2, gyz, 1)],
        2: [(0, gxz, 1), (1, gyz, 1), (2, gxx, -1), (2, gyy, -1)],
        3: [(0, txxx, 1), (1, txxy, 1), (2, txxz, 1)],
        4: [(0, txxy, 1), (1, txyy, 1), (2, txyz, 1)],
        5: [(0, txxz, 1), (1, txyz, 1), (2, txxx, -1), (2, txyy, -1)],
        6: [(0, txyy, 1), (1, tyyy, 1), (2, tyyz, 1)],
        7: [(0, txyz, 1), (1, tyyz, 1), (2, txxy, -1), (2, tyyy, -1)],
    }
    for r, terms in grad.items():
        for d, q, sgn in terms:
            c[r, d, q] += 0.5 * sgn
    return c.reshape(8, 36)


CORRECTION = _correction_matrix()
CORRECTION_T32 = np.ascontiguousarray(CORRECTION.T, dtype=np.float32)  # (36, 8)


@dataclass(frozen=True)
class FieldMap:
    """A loaded map. ``bounds``: (lower, upper) corners, m; ``meta``: the file's metadata.

    ``data`` (nx, ny, nz, n_coils * 15) float32 holds per node and coil the 8 rows of A then
    the 7 entries of T; ``fine`` the same for the optional bottom slab (``meta['fine_grid']``),
    which points inside it use. ``rz``: the (rho, z) tables prepared for
    :func:`interpolate_rz` (the batch path; empty: batches use the 3-D grid too).
    """

    data: np.ndarray
    meta: dict
    bounds: tuple
    n_coils: int
    fine: np.ndarray | None = None
    rz: tuple = ()

    @property
    def batch_uses_tables(self) -> bool:
        """True when every coil has a (rho, z) table, so batches take the 2-D path."""
        return bool(self.rz) and sum(len(t["idx"]) for t in self.rz) == self.n_coils

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.meta["grid"]["shape"])

    def actuation(self, points, *, outside: Literal["error", "extrapolate"] = "error",
                  order: Literal["quadratic", "linear"] = "quadratic",
                  method: Literal["auto", "grid", "tables"] = "auto") -> np.ndarray:
        """Interpolated A, shape (n, 8, n_coils) (or (8, n_coils) for one point), float64.

        Which interpolator: one point, fewer than :data:`BATCH_MIN` points, any point outside
        the box (``outside='extrapolate'``) or ``order='linear'``: the 3-D grid. Otherwise
        (batches inside the box, ``order='quadratic'``): the (rho, z) tables
        (:func:`interpolate_rz`), whose result is a strided view (rows outermost in memory;
        ``np.ascontiguousarray`` it if needed). Both are within ~1e-3 of each row's maximum.

        Parameters
        ----------
        points : array-like, shape (3,) or (n, 3), m
        outside : {'error', 'extrapolate'}
            Points outside ``bounds``: raise BadInputError, or extrapolate from the nearest
            cell (its polynomial, which degrades quickly away from the box).
        order : {'quadratic', 'linear'}
            Of the 3-D grid path.
        method : {'auto', 'grid', 'tables'}
            'auto' as above; 'grid' always the 3-D grid; 'tables' always the (rho, z) tables
            (BadInputError if the map has none for some coil or a point is outside the box).
        """
        if outside not in ("error", "extrapolate"):
            raise BadInputError("outside", "'error' or 'extrapolate'", outside)
        if order not in ("quadratic", "linear"):
            raise BadInputError("order", "'quadratic' or 'linear'", order)
        if method not in ("auto", "grid", "tables"):
            raise BadInputError("method", "'auto', 'grid' or 'tables'", method)
        if method == "tables":
            if not self.batch_uses_tables:
                raise BadInputError("method", "'auto' or 'grid' (this map has no (rho, z) "
                                    "table for every coil)", method)
            p, single = v.points(points)
            lo, hi = self._grid[:2]
            if not np.all((p >= lo) & (p <= hi)):
                raise BadInputError("points", f"inside the map box {lo.tolist()} .. "
                                    f"{hi.tolist()} m with method='tables'", "a point outside")
            res = interpolate_rz(self.rz, p, self.n_coils)
            return res[0] if single else res
        if method == "auto" and (isinstance(points, np.ndarray) and points.shape == (3,) or (
                isinstance(points, (tuple, list)) and len(points) == 3
                and not isinstance(points[0], (tuple, list, np.ndarray)))) or (
                method == "grid" and np.shape(points) == (3,)):
            return self._one(points, outside, order)
        p, single = v.points(points)
        lo, hi, step, _ = self._grid
        if outside == "error":
            tol = 1e-9 * step
            bad = np.any((p < lo - tol) | (p > hi + tol), axis=1)
            if bad.any():
                k = int(np.argmax(bad))
                raise BadInputError("points", f"inside the map box {lo.tolist()} .. "
                                    f"{hi.tolist()} m (or outside='extrapolate')",
                                    f"{p[k].tolist()} at row {k}")
        if method == "auto" and len(p) >= BATCH_MIN and order == "quadratic" and (
                self.batch_uses_tables) and (
                outside == "error" or np.all((p >= lo) & (p <= hi))):
            res = interpolate_rz(self.rz, p, self.n_coils)
        elif self.fine is None:
            res = interpolate(self.data, self._grid, p, self.n_coils, order)
        else:
            flo, fhi = self._fine_grid[:2]
            infine = np.all((p >= flo) & (p <= fhi), axis=1)
            res = np.empty((len(p), 8, self.n_coils))
            if not infine.all():
                res[~infine] = interpolate(self.data, self._grid, p[~infine], self.n_coils,
                                           order)
            if infine.any():
                res[infine] = interpolate(self.fine, self._fine_grid, p[infine], self.n_coils,
                                          order)
        return res[0] if single else res

    def _one(self, points, outside, order):
        """The controller's per-sample call: plain floats, no array bookkeeping."""
        try:
            q = (float(points[0]), float(points[1]), float(points[2]))
        except (TypeError, ValueError):
            raise BadInputError("points", "array-like of shape (3,) or (n, 3), m", points) from None
        lo, hi, step, shape = self._box
        for k in range(3):
            if not math.isfinite(q[k]):
                raise BadInputError("points", "finite (no NaN or Inf)", list(q))
            if outside == "error" and not (lo[k] - 1e-12 <= q[k] <= hi[k] + 1e-12):
                raise BadInputError("points", f"inside the map box {list(lo)} .. {list(hi)} m "
                                    "(or outside='extrapolate')", list(q))
        fb = self._fine_box
        if fb is not None and all(fb[0][k] <= q[k] <= fb[1][k] for k in range(3)):
            return _one_point(self.fine, fb[0], fb[2], fb[3], q, self.n_coils, order)
        return _one_point(self.data, lo, step, shape, q, self.n_coils, order)

    @staticmethod
    def _as_box(g):
        return (tuple(map(float, g["lower_m"])), tuple(map(float, g["upper_m"])),
                tuple(map(float, g["spacing_m"])), tuple(map(int, g["shape"])))

    @staticmethod
    def _as_grid(g):
        return (np.asarray(g["lower_m"]), np.asarray(g["upper_m"]), np.asarray(g["spacing_m"]),
                np.asarray(g["shape"]))

    @functools.cached_property
    def _box(self):
        return self._as_box(self.meta["grid"])

    @functools.cached_property
    def _fine_box(self):
        g = self.meta.get("fine_grid")
        return None if g is None or self.fine is None else self._as_box(g)

    @functools.cached_property
    def _grid(self):
        return self._as_grid(self.meta["grid"])

    @functools.cached_property
    def _fine_grid(self):
        return self._as_grid(self.meta["fine_grid"])




def interpolate(data, grid, p, nc, order):
    """The interpolation kernel for points (n, 3) -> (n, 8, nc) (numpy only;
    :mod:`firmware_io.mapfile` repeats it). Points outside the grid use the nearest cell.

    ``data``: (nx, ny, nz, n_coils * 15) float32, per coil the 8 rows of A then the 7 of T.
    """
    lower, upper, step, shape = grid
    nx, ny, nz = (int(x) for x in shape)
    f = (p - lower) / step
    i = np.clip(np.floor(f).astype(np.intp), 0, shape - 2)
    t = f - i
    w = (np.stack([1 - t[:, 0], t[:, 0]], 1)[:, :, None, None]
         * np.stack([1 - t[:, 1], t[:, 1]], 1)[:, None, :, None]
         * np.stack([1 - t[:, 2], t[:, 2]], 1)[:, None, None, :]).reshape(-1, 8)
    base = (i[:, 0] * ny + i[:, 1]) * nz + i[:, 2]
    offs = np.array([0, 1, nz, nz + 1, ny * nz, ny * nz + 1, ny * nz + nz, ny * nz + nz + 1])
    flat = data.reshape(nx * ny * nz, -1)
    n = len(p)
    corners = np.take(flat, base[:, None] + offs, axis=0)  # (n, 8, 15 nc)
    if order == "linear":
        s0 = np.matmul(w[:, None, :].astype(np.float32), corners).reshape(n, nc, 15)
        return s0[:, :, :8].transpose(0, 2, 1).astype(np.float64)
    wd = w[:, None, :] * ((t[:, None, :] - _CORNERS[None]) * step).transpose(0, 2, 1)
    wall = np.concatenate([w[:, None, :], wd], axis=1).astype(np.float32)  # (n, 4, 8)
    s = np.matmul(wall, corners).reshape(n, 4, nc, 15)
    deriv = s[:, 1:, :, 3:].transpose(0, 2, 1, 3).reshape(n, nc, 36)
    res = s[:, 0, :, :8] + np.matmul(deriv, CORRECTION_T32)
    return res.transpose(0, 2, 1).astype(np.float64)


def _one_point(data, lower, step, shape, q, nc, order):
    """One point without array bookkeeping (the controller's per-sample call)."""
    nx, ny, nz = shape
    fx = (q[0] - lower[0]) / step[0]
    fy = (q[1] - lower[1]) / step[1]
    fz = (q[2] - lower[2]) / step[2]
    ix = min(max(int(math.floor(fx)), 0), nx - 2)
    iy = min(max(int(math.floor(fy)), 0), ny - 2)
    iz = min(max(int(math.floor(fz)), 0), nz - 2)
    tx, ty, tz = fx - ix, fy - iy, fz - iz
    block = data[ix:ix + 2, iy:iy + 2, iz:iz + 2].reshape(8, nc, 15)
    ux, uy, uz = 1.0 - tx, 1.0 - ty, 1.0 - tz
    w = np.array([ux * uy * uz, ux * uy * tz, ux * ty * uz, ux * ty * tz,
                  tx * uy * uz, tx * uy * tz, tx * ty * uz, tx * ty * tz])
    flat = block.reshape(8, nc * 15)
    if order == "linear":
        return (w.astype(np.float32) @ flat).reshape(nc, 15)[:, :8].T.astype(np.float64)
    sx, sy, sz = step
    ax, ay, az = tx * sx, ty * sy, tz * sz
    bx, by, bz = ax - sx, ay - sy, az - sz
    wall = np.array([w, w * (ax, ax, ax, ax, bx, bx, bx, bx), w * (ay, ay, by, by, ay, ay, by, by),
                     w * (az, bz, az, bz, az, bz, az, bz)], dtype=np.float32)
    s = wall @ flat  # (4, nc * 15)
    corr = s[1:].reshape(-1) @ _big_correction(nc)  # (8 * nc,)
    return (s[0].reshape(nc, 15)[:, :8].T + corr.reshape(8, nc)).astype(np.float64)


@functools.lru_cache(maxsize=8)
def _big_correction(nc: int) -> np.ndarray:
    """CORRECTION laid out for the flat (3 x nc x 15) derivative sums -> (8 x nc) rows."""
    c = CORRECTION.reshape(8, 3, 12)
    big = np.zeros((3, nc, 15, 8, nc), dtype=np.float32)
    for k in range(nc):
        big[:, k, 3:, :, k] = c.transpose(1, 2, 0)
    return big.reshape(3 * nc * 15, 8 * nc)


def load(path, design=None) -> FieldMap:
    """Load and validate a map file; with ``design``, also check it was built from it.

    Raises BadInputError for a missing, truncated, foreign, corrupted or mismatched file.
    """
    arrays, meta = read_arrays(path)
    if design is not None and meta["design_sha256"] != design.spec_hash():
        raise BadInputError("map file", f"built from design {design.name!r} (SHA-256 "
                            f"{design.spec_hash()[:12]}...)",
                            f"{path} (design {meta.get('design_name')!r}, SHA-256 "
                            f"{meta['design_sha256'][:12]}...)", "Rebuild it: designkit map.")
    nc = int(meta["n_coils"])

    def pack(a, dg):
        return np.ascontiguousarray(np.concatenate([a, dg], axis=3).transpose(0, 1, 2, 4, 3)
                                    .reshape(a.shape[:3] + (15 * nc,)))

    fine = pack(arrays["A_fine"], arrays["dG_fine"]) if "A_fine" in arrays else None
    g = meta["grid"]
    rz = _prepare_rz([arrays[t["name"]] for t in meta["rz_tables"]], meta["rz_tables"],
                     meta["coil_positions_m"], meta["coil_rotations"])
    return FieldMap(pack(arrays["A"], arrays["dG"]), meta,
                    (np.asarray(g["lower_m"], float), np.asarray(g["upper_m"], float)), nc, fine,
                    tuple(rz))
