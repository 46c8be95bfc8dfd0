"""The map's per-core (rho, z) tables: the magnet's pull on one core (``MRZ<k>``) and the core
modes of the sensor field (``SM<k>``, with their coefficients ``SCOEF``).

Each table is computed for one coil alone at the origin (local frame) on the grid of a spec
(:func:`designkit.fieldmap.plan.rz_table_spec`); the reader (:mod:`firmware_io.mapfile.modes`)
evaluates it for every coil of its type. Forces in N, fields in T, lengths in m. The sensor
field is the discrete system's adjoint (linear cores): the field at sensor s along e_c of the
cores magnetized by the magnet m at p is Y_sc^T (F * projection of the magnet's field), Y =
M^-T E^T (:meth:`designkit.cores.coupled.ArraySystem.adjoint`), and that projection is m . the
field at p of the rows' adjoint dipole rings (:func:`adjoint_basis_field`): the same value as
the coupled model's direct evaluation, where a unit dipole at the sensor and reciprocity
differed from it by ~1 % (the collocation's error for a source that near a core).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import RectBivariateSpline

from firmware_io.mapfile import N_MODE_Q

from ..geometry.pose import Pose
from ..model.array import CoilArray
from ..support.blas import one_blas_thread
from .physics import MapPhysics
from .plan import spec_nodes


def _even_on_axis(out: np.ndarray, rho: np.ndarray, cols) -> None:
    """Fill row 0 (rho = 0) of ``out[..., cols]`` for quantities even in rho:
    f = f0 + f2 rho^2 + O(rho^4) -> f0 = (r2^2 f(r1) - r1^2 f(r2)) / (r2^2 - r1^2)."""
    r1, r2 = rho[1] ** 2, rho[2] ** 2
    out[0, :, cols] = ((r2 * out[1, :, cols] - r1 * out[2, :, cols]) / (r2 - r1))


FINITE_SIZE_STRIDE = 6
"""Node stride of the magnet's finite-size correction (:func:`finite_size_correction`): within
1.1e-3 / 0.6e-3 of each column's largest value of the correction computed on every 2nd node
(stride 4: 2e-4, ~2 x the cost; docs/fieldmap.md)."""


def compute_magnet_table(phys: "MapPhysics", coil, spec: dict, stride: int = 2,
                         force=None) -> np.ndarray:
    """The magnet table (n_rho, n_u, 2) float64 of one coil alone at the origin: F_rho/rho and
    F_z of the magnet's pull on its core (N/m, N) for the magnet at (rho, 0, z).

    The coupled model (``force(array, points)``, default ``phys.bias_force``: the point
    dipole) is evaluated on every ``stride``-th node of both axes (and the last); the other
    nodes come from a bicubic spline in the grid's (v, u) coordinates, in which the pull is
    smooth: stride 2 is within 1e-4 of the largest value of each column of the table computed
    at every node (docs/fieldmap.md), far below the reader's bilinear steps."""
    alone = CoilArray((coil.replace(pose=Pose()),))
    rho, z = spec_nodes(spec)
    i, j = _sub_nodes(len(rho), stride), _sub_nodes(len(z), stride)
    R, Z = np.meshgrid(rho[i], z[j], indexing="ij")
    pts = np.c_[R.ravel(), np.zeros(R.size), Z.ravel()]
    f = (phys.bias_force if force is None else force)(alone, pts)
    sub = np.empty((len(i), len(j), 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        sub[..., 0] = (f[:, 0] / pts[:, 0]).reshape(R.shape)
    sub[..., 1] = f[:, 2].reshape(R.shape)
    _even_on_axis(sub, rho[i], [0])
    return _to_full_grid(sub, i, j, len(rho), len(z))


def finite_size_correction(phys: "MapPhysics", coil, spec: dict,
                           stride: int = FINITE_SIZE_STRIDE) -> np.ndarray:
    """The magnet table of the cylinder minus the dipole's (:func:`compute_magnet_table`'s
    layout): what the magnet's finite size changes in its pull on one core, up to 4 % of the
    pull 15 mm above the core's top, falling ~ (size / distance)^2. Smooth and small, so a
    coarse stride carries it."""
    cyl = compute_magnet_table(phys, coil, spec, stride, force=phys.bias_force_finite)
    return cyl - compute_magnet_table(phys, coil, spec, stride)


def _sub_nodes(n: int, stride: int) -> np.ndarray:
    """Every ``stride``-th index of range(n) and the last."""
    return np.unique(np.r_[np.arange(0, n, stride), n - 1])


def _to_full_grid(sub: np.ndarray, i: np.ndarray, j: np.ndarray, n_rho: int,
                  n_u: int) -> np.ndarray:
    """A table (len(i), len(j), Q) known at the grid indices i x j, on the whole
    (n_rho, n_u) grid: bicubic splines in the grid's index coordinates (uniform in v and u)."""
    if len(i) == n_rho and len(j) == n_u:
        return sub
    k = (min(3, len(i) - 1), min(3, len(j) - 1))
    ii, jj = np.arange(n_rho), np.arange(n_u)
    return np.stack([RectBivariateSpline(i, j, sub[..., q], kx=k[0], ky=k[1])(ii, jj)
                     for q in range(sub.shape[-1])], axis=-1)


def coupled_modes(arr: CoilArray, sensor_tolerance: float = 1e-3) -> dict | None:
    """The field the magnet-magnetized cores give at the sensors, as a few core modes per core
    type (None without coupled cores).

    The field at sensor s along e_c of the cores magnetized by the magnet m at p is m . the
    field at p of the adjoint columns X = M^-T E^T (module docstring; 3 n_sensors columns,
    X_j core j's rows: m = 0 rings, m = 1, 2 cos and sin rings; the adjoint sources' fields:
    :func:`adjoint_basis_field`). Per core type and mode order m, the SVD of
    all X blocks gives the shapes U_m (kept while the singular values are above
    ``sensor_tolerance`` x the largest of their order); the coefficients C[j, b, (s, c)] =
    U_m^T X_j[:, (s, c)].

    Returns {"types": [{"model", "coils", "sets": [sensors] ({"U": {m: (n_m, R_m)},
    "basis": [(m, r, c)]})}], "sensor_coef": (n_coils, n_basis_max, n_sensors, 3)}; basis
    entries (m, r, c): mode order, shape index, c = 0 cos / 1 sin (m = 0: c = 0).
    """
    system = arr.coupled()
    if system is None:
        return None
    nc = arr.n_coils
    sens = arr.sensor_poses()[0]
    # columns (sensor, component); the tables' (cos, sin) modes are read in the coils' frames
    x = system.in_coil_frames(system.adjoint(sens))  # (nu, ns * 3)
    blocks = {}
    for jj, k in enumerate(system.core_index):
        model = system.models[jj]
        blocks.setdefault(id(model), (model, []))[1].append((jj, k))
    types = []
    for model, members in blocks.values():
        n0, n1, m_max = model.n0, model.n1, model.m_max
        dx = {k: x[system.offsets[jj]:system.offsets[jj + 1]] for jj, k in members}
        parts = {0: [(slice(0, n0), 0)]}
        # the tables hold m <= 2 (N_MODE_Q); the core solve's m = 3 part of the field at the
        # sensors is left out (bench_map: sensor_field error against the full model)
        for m in range(1, min(m_max, max(N_MODE_Q)) + 1):
            parts[m] = [(slice(n0 + (2 * (m - 1) + c) * n1, n0 + (2 * (m - 1) + c + 1) * n1), c)
                        for c in range(2)]
        U = {}
        for m in parts:
            mat = np.concatenate([dx[k][sl] for k in dx for sl, _ in parts[m]], axis=1)
            with one_blas_thread():  # small: BLAS threads would wait longer than compute
                u, sv, _ = np.linalg.svd(mat, full_matrices=False)
            if sv[0] > 0:
                U[m] = u[:, :max(1, int(np.sum(sv > sensor_tolerance * sv[0])))]
        basis = [(m, r, c) for m in sorted(U) for r in range(U[m].shape[1])
                 for c in ((0,) if m == 0 else (0, 1))]
        types.append({"model": model, "coils": [k for _, k in members],
                      "sets": [{"U": U, "basis": basis}], "parts": parts, "dx": dx})
    nb = max(len(t["sets"][0]["basis"]) for t in types)
    coef = np.zeros((nc, nb, x.shape[1]))
    for t in types:
        st = t["sets"][0]
        for k, d in t["dx"].items():
            for b, (m, r, c) in enumerate(st["basis"]):
                sl = [s for s, cc in t["parts"][m] if cc == c][0]
                coef[k, b] = st["U"][m][:, r] @ d[sl]
    return {"types": types, "sensor_coef": coef.reshape(nc, nb, len(sens), 3)}


def adjoint_basis_field(model, pts: np.ndarray, n_phi: int = 12, m_top: int | None = None):
    """H (n, 3, n_unknowns) 1/m^3 and G (n, 3, 3, n_unknowns) 1/m^4 at local ``pts`` of each
    row's adjoint source: a magnet m at p drives row u by F_u proj_u(H_m) (the projection of
    its field on the row's collocation ring, :meth:`CoreModel.project`), and t . H_m(x) =
    m . H_t(p) for point dipoles, so that drive is m . (this field of row u at p): the row's
    ring of unit dipoles along the projected direction t (side rings: +z for m = 0, rho-hat
    for m >= 1; end faces: -rho-hat for m = 0, the outward normal +-z for m >= 1), weighted
    1 / n_phi (m = 0) or 2 cos(m phi) / n_phi, 2 sin(m phi) / n_phi, times F_u. ``n_phi``
    dipoles per ring (12: within 2e-4 of 32 at 15 mm above a core's top); rows of mode order
    above ``m_top`` (default all) are left zero."""
    p = np.asarray(pts, float)
    m_top = model.m_max if m_top is None else min(m_top, model.m_max)
    phi = 2.0 * np.pi * np.arange(n_phi) / n_phi
    rr, zz = np.r_[model.rho0, model.rho1], np.r_[model.z0, model.z1]
    n0, n1, ns = model.n0, model.n1, len(model.side)
    kind = model.kind1
    # weights per azimuth: 1 / n_phi, then 2 cos(m phi) / n_phi, 2 sin(m phi) / n_phi
    w = np.stack([np.full(n_phi, 0.5)] + [f(m * phi) for m in range(1, m_top + 1)
                                          for f in (np.cos, np.sin)], axis=1) * (2.0 / n_phi)
    h = np.zeros((len(p), 3, model.n_unknowns))
    g = np.zeros((len(p), 3, 3, model.n_unknowns))
    # the rings of each direction: m = 0 side rings and m >= 1 face rings point along z (the
    # bottom faces' -z by a sign), m = 0 face rings (-rho-hat) and m >= 1 side rings rho-hat
    up = np.r_[np.arange(ns), n0 + np.flatnonzero(kind != 0)]
    out = np.r_[np.arange(ns, n0), n0 + np.flatnonzero(kind == 0)]
    for rings, radial in ((up, False), (out, True)):
        hw, gw = _dipole_rings(p, rr[rings], zz[rings], phi, radial, w)  # (n, 3[, 3], R, W)
        m0 = rings < n0
        sign = np.where(rings < n0, -1.0 if radial else 1.0,
                        np.where(kind[np.maximum(rings - n0, 0)] == 2, -1.0, 1.0))
        hw *= sign[:, None]
        gw *= sign[:, None]
        h[:, :, rings[m0]] = hw[:, :, m0, 0]
        g[:, :, :, rings[m0]] = gw[:, :, :, m0, 0]
        q = rings[~m0] - n0
        for col in range(1, w.shape[1]):
            rows = n0 + (col - 1) * n1 + q
            h[:, :, rows] = hw[:, :, ~m0, col]
            g[:, :, :, rows] = gw[:, :, :, ~m0, col]
    f = model.factors()
    return h * f, g * f


def _dipole_rings(p, rr, zz, phi, radial: bool, w):
    """Per ring (radius rr, height zz, m) of unit point dipoles at the azimuths ``phi``, along
    rho-hat (``radial``) or z: H (n, 3, R, W) and G (n, 3, 3, R, W) at ``p`` (n, 3) m, summed
    over the azimuths with the weights ``w`` (P, W): the weights' columns are even or odd in
    phi (1, cos, sin). Points on the x axis (y = 0, the tables' nodes) see the dipoles at -phi
    as the mirror images (y -> -y) of those at phi: half the azimuths, doubled, and the
    components odd under the mirror dropped for even weights, the even ones for odd weights."""
    mirror = len(phi) % 2 == 0 and not np.any(p[:, 1])
    if mirror:
        half = len(phi) // 2
        phi = phi[:half + 1]
        w = w[:half + 1] * np.where(np.isin(np.arange(half + 1), (0, half)), 1.0, 2.0)[:, None]
    c, s = np.cos(phi), np.sin(phi)
    d = [p[:, None, None, 0] - rr[None, :, None] * c, p[:, None, None, 1] - rr[None, :, None] * s,
         np.broadcast_to(p[:, None, None, 2] - zz[None, :, None], (len(p), len(rr), len(phi)))]
    inv_r2 = 1.0 / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    inv_r5 = inv_r2 * inv_r2 * np.sqrt(inv_r2) * (1.0 / (4.0 * np.pi))
    t = (c, s, None) if radial else (None, None, 1.0)
    dt = d[0] * c + d[1] * s if radial else d[2]
    a = 3.0 * dt * inv_r5  # H_i = a d_i - t_i inv_r3;  G_ij = (3 (t_i d_j + t_j d_i + dt
    b = 5.0 * a * inv_r2   # delta_ij) - 15 dt d_i d_j / r^2) inv_r5
    h = [None] * 3
    g = [[None] * 3 for _ in range(3)]
    for i in range(3):
        hi = a * d[i]
        if t[i] is not None:
            hi = hi - t[i] * inv_r5 / inv_r2
        h[i] = hi @ w
        for j in range(i, 3):
            gij = -b * d[i] * d[j]
            if i == j:
                gij += a
            for x, y in ((i, j), (j, i)):
                if t[x] is not None:
                    gij += 3.0 * t[x] * d[y] * inv_r5
            g[i][j] = g[j][i] = gij @ w
    h, g = np.stack(h, 1), np.stack([np.stack(row, 1) for row in g], 1)
    if mirror:
        odd = (np.arange(w.shape[1]) % 2 == 0) & (np.arange(w.shape[1]) > 0)  # the sin columns
        flip = np.array([1.0, -1.0, 1.0])  # the mirror y -> -y
        for comp in range(3):
            h[:, comp, ..., odd if flip[comp] > 0 else ~odd] = 0.0
            for k in range(3):
                g[:, comp, k, ..., odd if flip[comp] * flip[k] > 0 else ~odd] = 0.0
    return h, g


def compute_mode_tables(t: dict, spec: dict, progress=None, stride: int = 2) -> list:
    """The mode tables (n_rho, n_u, Q) float64 of one core type, one per shape set of ``t``
    (the sensor field's): for each shape, the quantities of :data:`N_MODE_Q` from the core model's
    basis fields at (rho, 0, z), local frame (one evaluation of the basis for all sets), on
    every ``stride``-th node of both axes and bicubic splines between them (as the magnet
    table, :func:`compute_magnet_table`)."""
    model = t["model"]
    t_sets = t["sets"]
    rho_all, z_all = spec_nodes(spec)
    i_sub, j_sub = _sub_nodes(len(rho_all), stride), _sub_nodes(len(z_all), stride)
    rho, z = rho_all[i_sub], z_all[j_sub]
    R, Z = np.meshgrid(rho, z, indexing="ij")
    pts = np.c_[R.ravel(), np.zeros(R.size), Z.ravel()]
    n0, n1 = model.n0, model.n1
    # all shapes of all sets side by side; split at the end
    U = {}
    for st in t["sets"]:
        for m, u in st["U"].items():
            U[m] = u if m not in U else np.concatenate([U[m], u], axis=1)
    t = {"U": U}
    shapes = [(m, r) for m in sorted(t["U"]) for r in range(t["U"][m].shape[1])]
    q_tot = sum(N_MODE_Q[m] for m, _ in shapes)
    out = np.zeros((R.size, q_tot))
    chunk = 256
    for s in range(0, len(pts), chunk):
        if progress is not None:  # the longest step of a build: show how far it is
            progress(s / len(pts))
        p = pts[s:s + chunk]
        h, g = adjoint_basis_field(model, p, m_top=max(N_MODE_Q))  # T per adjoint unit
        r_ = p[:, 0]
        col = 0
        for m, r in shapes:
            u = t["U"][m][:, r]
            if m == 0:
                b = h[:, :, :n0] @ u
                gg = g[:, :, :, :n0] @ u
                with np.errstate(divide="ignore", invalid="ignore"):
                    bb = gg[:, 1, 1]  # Br/rho = dBy/dy on the x axis
                    out[s:s + chunk, col:col + 4] = np.c_[
                        bb, b[:, 2], gg[:, 0, 2] / r_, (gg[:, 0, 0] - bb) / r_ ** 2]
            else:
                cs = [slice(n0 + (2 * (m - 1) + c) * n1, n0 + (2 * (m - 1) + c + 1) * n1)
                      for c in range(2)]
                bc, gc = h[:, :, cs[0]] @ u, g[:, :, :, cs[0]] @ u
                bs, gs = h[:, :, cs[1]] @ u, g[:, :, :, cs[1]] @ u
                with np.errstate(divide="ignore", invalid="ignore"):
                    if m == 1:  # cos: x G, sin: y G (formulas in firmware_io.mapfile)
                        a = bs[:, 1]
                        az = gs[:, 1, 2]
                        a1 = gc[:, 1, 1] / (2 * r_)
                        a2 = (gc[:, 0, 0] - 6 * r_ * a1) / (4 * r_ ** 3)
                        a1z = (gc[:, 0, 2] - az) / (2 * r_ ** 2)
                    else:  # cos: (x^2 - y^2) H, sin: 2 x y H
                        a = bs[:, 1] / (2 * r_)
                        az = gs[:, 1, 2] / (2 * r_)
                        a1 = (gc[:, 1, 1] + 2 * a) / (2 * r_ ** 2)
                        a2 = (gc[:, 0, 0] - 2 * a - 10 * r_ ** 2 * a1) / (4 * r_ ** 4)
                        a1z = (gc[:, 0, 2] - 2 * r_ * az) / (2 * r_ ** 3)
                out[s:s + chunk, col:col + 5] = np.c_[a, a1, a2, az, a1z]
            col += N_MODE_Q[m]
    out = out.reshape(len(rho), len(z), q_tot)
    # rho = 0: every quantity is even in rho -> Richardson from the next two nodes
    _even_on_axis(out, rho, slice(None))
    out = _to_full_grid(out, i_sub, j_sub, len(rho_all), len(z_all))
    # split per set, in each set's own shape order (m ascending, r ascending)
    col = {}
    c0 = 0
    for m, r in shapes:
        col[(m, r)] = c0
        c0 += N_MODE_Q[m]
    tables, offset = [], {m: 0 for m in U}
    for st in t_sets:
        cols = []
        for m in sorted(st["U"]):
            for r in range(st["U"][m].shape[1]):
                c = col[(m, offset[m] + r)]
                cols.extend(range(c, c + N_MODE_Q[m]))
            offset[m] += st["U"][m].shape[1]
        tables.append(out[..., cols])
    return tables


def mode_table_entry(t: dict, spec: dict, k: int, progress=None) -> tuple[np.ndarray, dict]:
    """Core type ``k``'s sensor-field mode table as stored, (n_rho, n_u, Q) float16 with each
    column scaled to its largest |value| (the sensor field is a few mT, its budget ~2 %), and
    its entry of meta ``sensor_mode_tables``."""
    tab = compute_mode_tables(t, spec, progress)[0]
    st = t["sets"][0]
    shapes = [[m, r] for m in sorted(st["U"]) for r in range(st["U"][m].shape[1])]
    cols = np.cumsum([0] + [N_MODE_Q[m] for m, _ in shapes])[:-1].tolist()
    col_scale = np.maximum(np.abs(tab).max(axis=(0, 1)), 1e-300)
    meta = {"name": f"SM{k}", "coils": [int(c) for c in t["coils"]],
            **spec, "shape": list(tab.shape), "shapes": shapes,
            "column_scale": col_scale.tolist(),
            "columns": [int(c) for c in cols],
            "basis": [list(b) for b in st["basis"]]}
    return (tab / col_scale).astype(np.float16), meta