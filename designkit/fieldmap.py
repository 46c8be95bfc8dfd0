"""Map file v2: build it from a design, write it, load it (:class:`FieldMap`).

The format -- array names, shapes, validation, interpolation -- is defined once, in the
numpy-only reader :mod:`firmware_io.mapfile` (read its docstring for the file's contents);
this module computes the arrays from a :class:`~designkit.array.CoilArray`, writes them
atomically, and :class:`FieldMap` wraps :class:`firmware_io.mapfile.MapFile` with designkit's
errors. All the physics the map samples comes through one function, :func:`map_physics`.

Representation and error budget (target: <= 1e-3 of each row's largest |A| over the box)
-----------------------------------------------------------------------------------------
A is stored as harmonic cells (format in firmware_io.mapfile): the box is current-free, so per
cell and coil one harmonic polynomial potential of degree L carries all 8 rows, each an exact
derivative of it. A polynomial's error in a cell falls like (cell size / distance to the
nearest source)^L, the sources being the cores' tops and rims below the box; so the cells grow
with the height d of their layer's floor above the sources' top (:func:`cell_layers`): in the
lowest layer, which holds every row's maximum, degree 12 on cells no wider than 1.0 d in a
layer 0.7 d thick; above, degree 7 on 0.5 d cells in 0.5 d layers. On the default box (20-80
mm above the coil tops, 15 mm above the cores' tops) that is 10 x 10, 12 x 12, 8 x 8 and 6 x 6
cells (344; 1.2 MB of float32 coefficients, 2.3 MB file with the bias-force and sensor-field
tables). Each cell is a least-squares fit, every row weighted by 1 / its maximum, to the
coupled model on 4 x 4 x 4 Chebyshev-Lobatto nodes shared across cell faces: 13,264
evaluations of the coupled model for the default box (~0.4 ms each on a quiet machine).

Measured (these choices; per layer, relative to the rows' maxima over the whole sample of
``studies/bench_map.py``): the lowest layer 2.4e-4 with degree 12 on 1.0 d cells, 0.7 d thick
(100 cells; 3.2e-4 with degree 11 on 0.9 d cells, 144; 3.4e-4 with degree 9 on 0.67 d cells,
0.5 d thick, 225, the former layout; 1.3e-4 with degree 13 on 1.1 d cells, 0.8 d thick, but
slower batches: more multiply-adds); the layers above 3.3e-4 with degree 7 on 0.5 d cells
(4.5e-4 on 0.55 d cells, up to 9.3e-4 in one random 2 x 2 geometry; 9.1e-4 with degree 6 on
0.42 d cells, no faster: more cells; 2.1e-4 with degree 8 on 0.62 d cells, 5 % slower). The
float32 coefficients and products add ~1e-6 of a row's maximum. ``studies/bench_map.py``
(default design, 1e4 points, half in the lowest 10 mm): max 3.3e-4 (Bx 5.9e-5, Bz 4.3e-5,
dBx/dy 3.3e-4); tests/test_fieldmap_accuracy.py (slow, random geometries, floors 18-24 mm, 1e4
points each): 2.3e-4, 2.9e-4, 4.5e-4 for its 1 x 2, 2 x 2, 3 x 3 cases (3.5e-4, 4.7e-4, 3.0e-4
with the former layout). A design with a lower floor gets more, smaller cells (a longer build
and slower batches, the same error); the old 10 mm floor is 5 mm above the cores' tops, where
studies/map_cells.py measured that 5 mm cells of degree 8-10 are needed for this error.

Cost (bench_map.py, median of 3 runs; two cores shared with other busy processes, load average
~3: the coupled model ran at 0.53-0.57 ms/point instead of ~0.4): one point 9.6 us as (3,), 9.8
us as (1, 3) in the lowest layer (14 x one 8 x 9 numpy matvec: its 364 monomials @ the (364,
144) harmonics' monomial coefficients @ the cell's (144, 72); 6.4 us above it); 1e4 points 3.2
ms (min of 21; median 3.4), under the 5 ms target (6.4 ms, median 6.6, in the same conditions
before: 538 cells, rows on monomials); build 44 s, of which the cell nodes 5.5 s (were 9-10 s),
the sensor field's core modes 14 s and the saturation solves 9 s, both of those BLAS-heavy and
several times slower than at load ~1 (~21 s for the whole build then, with the former 20,440
cell nodes). A batch lookup of A (firmware_io.mapfile.cells_many), 1e4 uniform points: ~2.1 ms
in the ~350 small float32 GEMMs (one per occupied cell, capped at 4e5 multiply-adds each:
firmware_io.mapfile.GEMM_CAP; ~2-4 us each for the 15-20 points of a lower cell, mostly per
call and the packing of the cell's (L^2, 72) matrix; the upper layers' 50-80 points per cell
run at ~30 GMAC/s), 0.5 ms for the solid harmonics, 0.5 ms to gather the rows back to the
caller's order as float64 (a random permutation of 5.8 MB), 0.25 ms for the cells and local
coordinates, 0.15 ms for the sort and the rest. On the monomials (C(L + 2, 3) per point instead
of L^2) the products took 3.7 ms: 1.8 x the multiply-adds and 2.4 x the matrices' bytes (18 MB
instead of 7.6). Tried without gain: fewer, larger cells of degree 8-9 above the lowest layer
(their products are bound by the multiply-adds: 5-10 % slower), the harmonics point-major for
the products (faster products, but the extra copy and cache traffic cost more), np.dot (5 %
slower than np.matmul here).

The build checks itself: it evaluates the coupled model directly at ``n_check`` random points
in the box (default 400) and records the errors of the finished map in ``meta['errors']``, with
the largest error at the fit nodes themselves.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import _validate as v
from .array import ROWS, CoilArray
from .electrical import drive_data
from .errors import BadInputError
from firmware_io import mapfile as mf
from firmware_io.errors import BadInputError as _FirmwareBadInput

FORMAT, FORMAT_VERSION, UNITS = mf.FORMAT, mf.FORMAT_VERSION, mf.UNITS


# ============================================================================ grids
def default_box(design) -> tuple[np.ndarray, np.ndarray]:
    """Workspace box (lower, upper corners, m): the footprint, z_min..z_max above the tops."""
    ws = design.workspace
    h = ws.half_width_m
    return np.array([-h, -h, ws.z_min_m]), np.array([h, h, ws.z_max_m])


def uniform_axis(lo: float, hi: float, spacing: float) -> np.ndarray:
    """Nodes covering [lo, hi] exactly with steps <= ``spacing`` (m)."""
    n = max(2, int(math.ceil((hi - lo) / spacing - 1e-9)) + 1)
    return np.linspace(lo, hi, n)


def graded_axis(lo: float, hi: float, z_ref: float, log_step: float, max_step: float) -> np.ndarray:
    """Nodes on [lo, hi] uniform in log(z - z_ref) (steps ~ ``log_step`` x the height above
    ``z_ref``, fine just above the cores), no step above ``max_step`` (m). Uniform when
    lo <= z_ref."""
    if lo - z_ref <= 1e-6:
        return uniform_axis(lo, hi, max_step)
    u_lo, u_hi = math.log(lo - z_ref), math.log(hi - z_ref)
    n = max(2, int(math.ceil((u_hi - u_lo) / log_step - 1e-9)) + 1)
    z = z_ref + np.exp(np.linspace(u_lo, u_hi, n))
    z[0], z[-1] = lo, hi
    out = [z[:1]]
    for a, b in zip(z[:-1], z[1:]):
        out.append(np.linspace(a, b, max(2, int(math.ceil((b - a) / max_step - 1e-9)) + 1))[1:])
    return np.concatenate(out)


def box_axes(lower, upper, spacing: float, z_ref: float, log_step: float) -> list[np.ndarray]:
    """x, y uniform at ``spacing``; z graded from ``z_ref`` (:func:`graded_axis`)."""
    return [uniform_axis(lower[0], upper[0], spacing), uniform_axis(lower[1], upper[1], spacing),
            graded_axis(lower[2], upper[2], z_ref, log_step, spacing)]


def _nodes(axes) -> np.ndarray:
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


# ============================================================================ (rho, z) tables
# per core type, on a grid uniform in v = rho / (1 + rho / rho_scale) and log(z - z_ref): the
# magnet's pull on one core and the sensor field's core modes
def rz_table_spec(coil, lower, upper, rho_step: float, log_step: float,
                  rho_scale: float = 0.05, n_q: int = 8) -> dict | None:
    """Grid of the (v, u) table covering the box for ``coil``'s pose.

    v = rho / (1 + rho / rho_scale) (uniform steps ``rho_step``: the rho step is ``rho_step``
    on the axis and grows as (1 + rho / rho_scale)^2, like the distance to the sources) and
    u = log(z - z_ref) (uniform steps ``log_step``), z_ref the top of the coil's sources.

    None when some box point is not above all of the coil's sources (z_local <= their top):
    the tables cannot cover such a box.
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
            "u0": float(u_lo - log_step), "u_step": float(log_step), "shape": [n_rho, n_u, n_q]}


def _spec_nodes(spec: dict):
    """rho (n_rho,) and z (n_u,) nodes of a table spec, m (local frame)."""
    n_rho, n_u, _ = spec["shape"]
    vn = spec["rho_step_m"] * np.arange(n_rho)
    rho = vn / (1 - vn / spec["rho_scale_m"])  # inverse of v = rho / (1 + rho / rho_scale)
    z = spec["z_ref_m"] + np.exp(spec["u0"] + spec["u_step"] * np.arange(n_u))
    return rho, z


def _even_on_axis(out: np.ndarray, rho: np.ndarray, cols) -> None:
    """Fill row 0 (rho = 0) of ``out[..., cols]`` for quantities even in rho:
    f = f0 + f2 rho^2 + O(rho^4) -> f0 = (r2^2 f(r1) - r1^2 f(r2)) / (r2^2 - r1^2)."""
    r1, r2 = rho[1] ** 2, rho[2] ** 2
    out[0, :, cols] = ((r2 * out[1, :, cols] - r1 * out[2, :, cols]) / (r2 - r1))


def compute_magnet_table(phys: "MapPhysics", coil, spec: dict) -> np.ndarray:
    """The magnet table (n_rho, n_u, 2) float64 of one coil alone at the origin: F_rho/rho and
    F_z of the magnet's pull on its core (N/m, N) for the magnet at (rho, 0, z)."""
    from .pose import Pose

    alone = CoilArray((coil.replace(pose=Pose()),))
    rho, z = _spec_nodes(spec)
    R, Z = np.meshgrid(rho, z, indexing="ij")
    pts = np.c_[R.ravel(), np.zeros(R.size), Z.ravel()]
    f = phys.bias_force(alone, pts)
    out = np.empty((len(rho), len(z), 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        out[..., 0] = (f[:, 0] / pts[:, 0]).reshape(R.shape)
    out[..., 1] = f[:, 2].reshape(R.shape)
    _even_on_axis(out, rho, [0])
    return out


def _union_spec(specs: list) -> dict:
    """One table grid covering several specs of the same coil type (same steps and z_ref)."""
    if len(specs) == 1:
        return specs[0]
    s0 = specs[0]
    u0 = min(s["u0"] for s in specs)
    u_top = max(s["u0"] + s["u_step"] * (s["shape"][1] - 1) for s in specs)
    n_u = int(math.ceil((u_top - u0) / s0["u_step"] - 1e-9)) + 1
    return {**s0, "u0": u0, "shape": [max(s["shape"][0] for s in specs), n_u, s0["shape"][2]]}




# ============================================================================ the physics
@dataclass(frozen=True)
class MapPhysics:
    """What the map samples, for one design (all SI); every method takes the CoilArray it is
    about (the design's array, or one coil alone for the per-type tables). All of it comes from
    the coupled array model (:mod:`designkit.coupling` through :class:`CoilArray`).
    """

    moment_a_m2: np.ndarray
    max_current_a: float
    source: str = "designkit.coupling (all cores solved together, linear cores)"

    def sensor_positions(self, array: CoilArray) -> np.ndarray:
        """(2, n_coils, 3) m: upper array then lower array, one sensor per coil axis."""
        return array.sensor_positions_m()

    def actuation(self, array: CoilArray, points) -> np.ndarray:
        """Coupled A (n, 8, n_coils), T/A and T/(m A)."""
        return array.actuation_matrix(np.asarray(points, float))

    def bias_force(self, array: CoilArray, points) -> np.ndarray:
        """F0 (n, 3) N on the magnet at ``points`` at zero current."""
        return array.bias_force(np.asarray(points, float), self.moment_a_m2)

    def sensor_induced(self, array: CoilArray, magnet_positions, chunk: int = 64) -> np.ndarray:
        """(n, 2, n_coils, 3) T: the field of the magnet-magnetized cores at the sensors."""
        p = np.asarray(magnet_positions, float)
        sens = array.sensor_positions_m()
        system = array.coupled()
        out = np.zeros((len(p),) + sens.shape)
        if system is None:
            return out
        for a in range(0, len(p), chunk):  # one back-substitution per magnet position
            x = system.magnet_solution(p[a:a + chunk], self.moment_a_m2)
            b = system.core_field(sens.reshape(-1, 3), x)  # (n_sensors, 3, k)
            out[a:a + chunk] = np.moveaxis(b, -1, 0).reshape((-1,) + sens.shape)
        return out

    def sensor_coil_rows(self, array: CoilArray) -> np.ndarray:
        """(2, n_coils, 8, n_coils): the coupled field (T/A) and gradient rows (T/(m A),
        :data:`~designkit.array.ROWS`) of each coil at the sensors."""
        s = self.sensor_positions(array).reshape(-1, 3)
        nc = array.n_coils
        return self.actuation(array, s).reshape(2, nc, 8, nc)

    def sensor_coil_field(self, array: CoilArray) -> np.ndarray:
        """(2, n_coils, 3, n_coils) T/A: the coupled field of each coil at the sensors."""
        return self.sensor_coil_rows(array)[:, :, :3]

    def saturation(self, array: CoilArray) -> tuple[np.ndarray, np.ndarray]:
        """Currents (n_s,) A and per-coil factors (n_s, n_coils) on the columns of A
        (:meth:`CoilArray.saturation_correction`; 1 for air coils)."""
        if array.coupled() is None:  # no iron: nothing saturates (and no solve to pay for)
            cur = np.array([0.0, 1.0])
            return cur, np.ones((2, array.n_coils))
        # 7 currents: linear interpolation between them is within 0.3 % of the 13-point
        # curve (the factor bends only above ~4 A), for half the nonlinear solves
        s = array.saturation_correction(currents_a=np.linspace(0.0, self.max_current_a, 7))
        return s["saturation_current_a"], s["saturation_factor"]


def map_physics(design) -> MapPhysics:
    """The one place the map's physics comes from (see :class:`MapPhysics`)."""
    return MapPhysics(np.asarray(design.magnet.moment_vector_a_m2, float), design.drive.max_current_a)


# ============================================================================ coupled core modes
N_MODE_Q = {0: 4, 1: 5, 2: 5}
"""Table quantities per core mode: m = 0 (b = Br/rho, Bz, e = (dBr/dz)/rho,
w = (dBr/drho - Br/rho)/rho^2), m = 1, 2 (the
potential x G resp. (x^2 - y^2) H with G(rho^2, z): a, a1, a2, az, a1z = -mu0 (G, G', G'', G_z,
G'_z), ' = d/d(rho^2))."""


def coupled_modes(arr: CoilArray, sensor_tolerance: float = 1e-3) -> dict | None:
    """The field the magnet-magnetized cores give at the sensors, as a few core modes per core
    type (None without coupled cores).

    By reciprocity (linear cores) the field at sensor s along e_c of the cores magnetized by
    the magnet m at p is m . B(p) of the cores magnetized by a unit dipole e_c at s: fixed
    sources, 3 x 2 x n_coils columns of core unknowns X_j (m = 0 surface currents, m = 1, 2
    cos and sin charges; :mod:`designkit.coupling`). Per core type and mode order m, the SVD of
    all X blocks gives the shapes U_m (kept while the singular values are above
    ``sensor_tolerance`` x the largest of their order); the coefficients C[j, b, (s, c)] =
    U_m^T X_j[:, (s, c)].

    Returns {"types": [{"model", "coils", "sets": [sensors] ({"U": {m: (n_m, R_m)},
    "basis": [(m, r, c)]})}], "sensor_coef": (n_coils, n_basis_max, 2, n_coils, 3)}; basis
    entries (m, r, c): mode order, shape index, c = 0 cos / 1 sin (m = 0: c = 0).
    """
    system = arr.coupled()
    if system is None:
        return None
    nc = arr.n_coils
    sens = arr.sensor_positions_m().reshape(-1, 3)
    x = np.stack([system.magnet_solution(sens, e) for e in np.eye(3)], axis=-1)  # (nu, ns, 3)
    x = x.reshape(len(x), -1)  # columns (sensor, component)
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
    return {"types": types, "sensor_coef": coef.reshape(nc, nb, 2, nc, 3)}


def compute_mode_tables(t: dict, spec: dict, progress=None) -> list:
    """The mode tables (n_rho, n_u, Q) float64 of one core type, one per shape set of ``t``
    (the sensor field's): for each shape, the quantities of :data:`N_MODE_Q` from the core model's
    basis fields at (rho, 0, z), local frame (one evaluation of the basis for all sets)."""
    from .constants import MU0

    model = t["model"]
    t_sets = t["sets"]
    rho, z = _spec_nodes(spec)
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
        # the fine charge quadrature where the compressed rules are not accurate (near the
        # core), as the coupled model's own field evaluation does
        near = ~model.far_mask(np.hypot(p[:, 0], p[:, 1]), p[:, 2])
        h = np.zeros((len(p), 3, model.n_unknowns))
        g = np.zeros((len(p), 3, 3, model.n_unknowns))
        for sel, fine in ((near, True), (~near, False)):
            if np.any(sel):
                h[sel], g[sel] = model.basis_field(p[sel], gradient=True, fine=fine)
        r_ = p[:, 0]
        col = 0
        for m, r in shapes:
            u = t["U"][m][:, r]
            if m == 0:
                b = MU0 * h[:, :, :n0] @ u
                gg = MU0 * g[:, :, :, :n0] @ u
                with np.errstate(divide="ignore", invalid="ignore"):
                    bb = gg[:, 1, 1]  # Br/rho = dBy/dy on the x axis
                    out[s:s + chunk, col:col + 4] = np.c_[
                        bb, b[:, 2], gg[:, 0, 2] / r_, (gg[:, 0, 0] - bb) / r_ ** 2]
            else:
                cs = [slice(n0 + (2 * (m - 1) + c) * n1, n0 + (2 * (m - 1) + c + 1) * n1)
                      for c in range(2)]
                bc, gc = MU0 * h[:, :, cs[0]] @ u, MU0 * g[:, :, :, cs[0]] @ u
                bs, gs = MU0 * h[:, :, cs[1]] @ u, MU0 * g[:, :, :, cs[1]] @ u
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
    r1, r2 = rho[1] ** 2, rho[2] ** 2
    out[0] = (r2 * out[1] - r1 * out[2]) / (r2 - r1)
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


# ============================================================================ build
def cell_layers(lower, upper, z_top: float, cell_ratio: tuple, layer_ratio,
                degree: tuple) -> list:
    """The harmonic-cell layout of A over the box (meta ``a_layers``): layers from the floor
    up, each ``layer_ratio`` x its floor's height d above the sources' top ``z_top`` (m) thick,
    cut into a uniform grid of cells no wider than ``cell_ratio`` x d, potentials of degree
    ``degree``; all three are sequences per layer from the lowest, the last entry serving every
    layer above (``layer_ratio`` may be one number for all). A polynomial's error in a cell
    grows with (cell size / distance to the sources)^degree, so fixed ratios keep it about even
    and the cells grow upwards (the default box: 10 x 10 cells of degree 12, then 12 x 12,
    8 x 8 and 6 x 6 of degree 7). The lowest layer holds every row's maximum, where the error
    measure is tightest; with a higher degree there its cells are larger and thicker: fewer
    cells (a batch lookup's products cost ~2-4 us each, mostly per call, for the ~5-10 points a
    small cell gets of 1e4) and fewer fit nodes. A thin remainder at the top is shared with the
    layer below."""
    layer_ratio = tuple(np.atleast_1d(layer_ratio).tolist())
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    if lo[2] - z_top < 1e-4:
        raise BadInputError("box", f"above the top of every coil's sources (z > {z_top} m; the "
                            "map's potential is harmonic only there), m",
                            (lo.tolist(), hi.tolist()))
    wx, wy = hi[0] - lo[0], hi[1] - lo[1]
    layers, z = [], float(lo[2])
    while z < hi[2] - 1e-12:
        d = z - z_top
        dz = layer_ratio[min(len(layers), len(layer_ratio) - 1)] * d
        rest = float(hi[2]) - z
        if rest <= 1.5 * dz:
            dz = rest if rest <= dz else rest / 2
        z1 = float(hi[2]) if hi[2] - (z + dz) < 1e-9 else z + dz
        ratio = cell_ratio[min(len(layers), len(cell_ratio) - 1)]
        nx = max(1, math.ceil(wx / (ratio * d) - 1e-9))
        ny = max(1, math.ceil(wy / (ratio * d) - 1e-9))
        layers.append({"name": f"AH{len(layers)}", "z_lo_m": z, "z_hi_m": z1,
                       "x0_m": float(lo[0]), "y0_m": float(lo[1]), "nx": nx, "ny": ny,
                       "cell_x_m": float(wx / nx), "cell_y_m": float(wy / ny),
                       "degree": int(degree[min(len(layers), len(degree) - 1)])})
        z = z1
    return layers


def _lobatto(n: int) -> np.ndarray:
    """n Chebyshev-Lobatto nodes on [0, 1] (both ends: neighbouring cells share them)."""
    return (1.0 - np.cos(np.pi * np.arange(n) / (n - 1))) / 2


def layer_nodes(lay: dict, n: int) -> list:
    """The fit lattice of a layer: x, y, z node axes (m), ``n`` Chebyshev-Lobatto nodes per
    cell and axis, shared across cell faces."""
    t = _lobatto(n)[:-1]

    def axis(x0, h, count):
        return np.r_[(x0 + h * (np.arange(count)[:, None] + t)).ravel(), x0 + h * count]

    return [axis(lay["x0_m"], lay["cell_x_m"], lay["nx"]),
            axis(lay["y0_m"], lay["cell_y_m"], lay["ny"]),
            lay["z_lo_m"] + (lay["z_hi_m"] - lay["z_lo_m"]) * _lobatto(n)]


def fit_layer(lay: dict, values: np.ndarray, row_max: np.ndarray, n: int) -> np.ndarray:
    """Harmonic coefficients (nx * ny, K, nc) float32 of one layer from A on its fit lattice
    (NX, NY, n, 8, nc): per cell the least-squares potential over its n^3 nodes, every row
    weighted by 1 / its largest |A| over the box (the error measure); one pseudo-inverse per
    layer (every cell has the same local nodes)."""
    nx, ny, deg = lay["nx"], lay["ny"], lay["degree"]
    hx, hy = lay["cell_x_m"], lay["cell_y_m"]
    dz = lay["z_hi_m"] - lay["z_lo_m"]
    r = max(hx, hy, dz) / 2
    t = _lobatto(n) - 0.5
    s = np.stack(np.meshgrid(t * hx / r, t * hy / r, t * dz / r, indexing="ij"), -1)
    ops = mf.harmonic_rows(deg)  # (8, M, K)
    scale = np.array([r] * 3 + [r * r] * 5) * row_max
    g = np.einsum("mp,rmk->prk", mf.monomials(s.reshape(-1, 3), deg - 1), ops)
    g /= scale[None, :, None]
    pinv = np.linalg.pinv(g.reshape(-1, g.shape[2]))  # (K, n^3 * 8)
    nc = values.shape[-1]
    out = np.empty((nx * ny, g.shape[2], nc), np.float32)
    w = (1.0 / row_max)[:, None]
    for i in range(nx):
        for j in range(ny):
            a = values[i * (n - 1):i * (n - 1) + n, j * (n - 1):j * (n - 1) + n]
            out[i * ny + j] = pinv @ (a * w).reshape(-1, nc)
    return out


def build(design, *, spacing: float = 0.01, log_step: float = 0.25,
          cell_ratio=(1.0, 0.5), layer_ratio=(0.7, 0.5), degree=(12, 7),
          fit_nodes: int = 4, sensor_mode_tolerance: float = 1e-3,
          rz_rho_scale: float = 0.05, sensor_mode_rz_step: float = 2.5e-4,
          sensor_mode_rz_log_step: float = 0.04, magnet_rz_step: float = 5e-4,
          magnet_rz_log_step: float = 0.02, box=None, n_check: int = 400,
          progress: bool = True, array: CoilArray | None = None) -> dict:
    """Compute the map v2 of ``design``: ``{"arrays": {...}, "meta": {...}}`` (not yet written).

    Parameters
    ----------
    spacing, log_step : float
        x, y step (m) of the grids over magnet positions that carry what the per-core magnet
        tables miss (the bias force's core-to-core part, trilinear); their z steps grow from
        ``log_step`` x the height above the cores' tops, never above ``spacing``. Defaults
        (10 mm, 25 %) with the magnet tables' (0.5 mm, 2 %): F0 within 0.9 mN of the coupled
        model over a 20-80 mm box (0.2 % of its largest |F0|, 0.42 N at 20 mm; ~1 mN is the
        perception threshold); the former 25 mm, 50 % with 2 mm, 15 % left 12 % (15 mN).
    cell_ratio, layer_ratio, degree, fit_nodes
        A's harmonic cells (:func:`cell_layers`): cells no wider than ``cell_ratio`` and layers
        ``layer_ratio`` x the height of their floor above the sources' top, potentials of
        degree ``degree`` (K = (degree + 1)^2 - 1 coefficients per cell and coil); each a
        sequence per layer from the lowest (the last entry for the layers above;
        ``layer_ratio`` may be one number); fitted on ``fit_nodes``^3 Chebyshev-Lobatto nodes
        per cell (shared across faces; each node is one evaluation of the coupled model,
        ~0.4 ms).
    sensor_mode_tolerance : float
        The sensor field's core modes are kept while their singular value is above this
        fraction of the largest of their order (m = 0, 1, 2) (the unit dipoles ~9 mm from a
        core's end need many; 1e-3 keeps the file small for an error of ~2 % of the field,
        itself a few mT).
    rz_rho_scale : float, m
        The (rho, z) tables' rho steps grow as (1 + rho / rz_rho_scale)^2.
        ``sensor_mode_rz_step``, ``sensor_mode_rz_log_step``: rho step on the axis (m) and step
        in log(z - z_ref) of the sensor field's mode tables (0.25 mm, 4 %);
        ``magnet_rz_step``, ``magnet_rz_log_step`` for the magnet tables (0.5 mm, 2 %: the pull
        of one core falls ~z^-7 near it, so bilinear steps of 15 % in z left ~10 % errors).
    box : (lower, upper) or None
        Corners, m; default :func:`default_box`.
    n_check : int
        Random points where the finished map is compared with direct evaluation of the coupled
        model (meta 'errors'; each costs a full coupled evaluation, ~0.4 ms).
    """
    from ._progress import tqdm

    from . import __version__
    from .scene import source_box

    spacing = v.in_range("spacing", spacing, 5e-4, 0.1, "m")
    log_step = v.in_range("log_step", log_step, 1e-3, 2.0)
    if np.ndim(layer_ratio) == 0:
        layer_ratio = (layer_ratio,)
    if (np.ndim(cell_ratio) != 1 or np.ndim(degree) != 1 or np.ndim(layer_ratio) != 1
            or not len(cell_ratio) or not len(degree) or not len(layer_ratio)):
        raise BadInputError("cell_ratio, layer_ratio, degree", "sequences, per layer from the "
                            "lowest (the last one for the layers above)",
                            (cell_ratio, layer_ratio, degree))
    cell_ratio = tuple(v.in_range("cell_ratio", r, 0.05, 2.0) for r in cell_ratio)
    layer_ratio = tuple(v.in_range("layer_ratio", r, 0.05, 2.0) for r in layer_ratio)
    degree = tuple(int(v.in_range("degree", d, 2, 12)) for d in degree)
    fit_nodes = int(v.in_range("fit_nodes", fit_nodes, 3, 8))
    sensor_mode_tolerance = v.in_range("sensor_mode_tolerance", sensor_mode_tolerance, 1e-8,
                                       1e-1)
    rz_rho_scale = v.in_range("rz_rho_scale", rz_rho_scale, 1e-3, 10.0, "m")
    sensor_mode_rz_step = v.in_range("sensor_mode_rz_step", sensor_mode_rz_step, 1e-5, 0.01, "m")
    sensor_mode_rz_log_step = v.in_range("sensor_mode_rz_log_step", sensor_mode_rz_log_step,
                                         1e-3, 0.5)
    magnet_rz_step = v.in_range("magnet_rz_step", magnet_rz_step, 1e-5, 0.01, "m")
    magnet_rz_log_step = v.in_range("magnet_rz_log_step", magnet_rz_log_step, 1e-3, 0.5)
    n_check = v.positive_int("n_check", n_check)
    arr = array or CoilArray.from_design(design)
    lower, upper = default_box(design) if box is None else (np.asarray(box[0], float),
                                                            np.asarray(box[1], float))
    if lower.shape != (3,) or upper.shape != (3,) or not np.all(upper > lower):
        raise BadInputError("box", "lower < upper in x, y and z, m",
                            (lower.tolist(), upper.tolist()))
    phys = map_physics(design)
    nc = arr.n_coils
    types = list(arr.coil_types().items())

    def specs(idx_lists, step, log_step_, n_q):
        out = []
        for idx in idx_lists:
            s = [rz_table_spec(arr.coils[k], lower, upper, step, log_step_, rz_rho_scale, n_q)
                 for k in idx]
            if any(x is None for x in s):
                raise BadInputError("box", "above every coil's winding and core (the map's "
                                    "(rho, z) tables cover only points above the sources), m",
                                    (lower.tolist(), upper.tolist()))
            out.append(_union_spec(s))
        return out

    m_specs = specs([idx for _, idx in types], magnet_rz_step, magnet_rz_log_step, 2)
    # the top of all sources (any pose): the cells' potentials are harmonic above it
    corners = [np.array([[x, y, z] for x in (-r, r) for y in (-r, r) for z in (zl, zh)])
               for r, zl, zh in (source_box(c) for c in arr.coils)]
    z_top = max(float((c.pose.vectors_to_global(k)[:, 2] + c.pose.position[2]).max())
                for c, k in zip(arr.coils, corners))
    layers = cell_layers(lower, upper, z_top, cell_ratio, layer_ratio, degree)
    lattices = [layer_nodes(lay, fit_nodes) for lay in layers]
    fit_pts = np.concatenate([_nodes(ax) for ax in lattices])
    z_ref = max(arr.coils[k].pose.position[2] + s["z_ref_m"] for (_, idx), s in zip(types, m_specs)
                for k in idx)
    m_axes = box_axes(lower, upper, spacing, z_ref, log_step)
    m_nodes = _nodes(m_axes)
    rng = np.random.default_rng(20261123)
    check = rng.uniform(lower, upper, (n_check, 3))
    n_mcheck = min(n_check, 50)
    chunk = 64
    fit_chunk = 512
    work = ([("coupled solve", 0)] + [("cell nodes", s) for s in range(0, len(fit_pts), fit_chunk)]
            + [("magnet tables", k) for k in range(len(types))] + [("mode tables", 0)]
            + [("magnet", s) for s in range(0, len(m_nodes), chunk)]
            + [("check", s) for s in range(0, n_check, chunk)] + [("magnet check", 0),
                                                                  ("saturation", 0)])
    arrays: dict = {}
    mrz_meta, sm_meta = [], []
    f0 = np.empty((len(m_nodes), 3))
    a_fit = np.empty((len(fit_pts), 8, nc))
    a_check = np.empty((n_check, 8, nc))
    seconds: dict = {}
    modes = None
    bar = tqdm(work, desc="map", unit="step", disable=not progress, leave=False)
    for kind, s in bar:
        bar.set_postfix_str(kind, refresh=False)
        t0 = time.perf_counter()
        if kind == "coupled solve":
            arr.actuation_matrix(fit_pts[:1])  # the coupled solve, once
            modes = coupled_modes(arr, sensor_mode_tolerance)
        elif kind == "cell nodes":
            a_fit[s:s + fit_chunk] = phys.actuation(arr, fit_pts[s:s + fit_chunk])
        elif kind == "magnet tables":
            proto, idx = types[s]
            arrays[f"MRZ{s}"] = compute_magnet_table(phys, proto, m_specs[s]).astype(np.float32)
            mrz_meta.append({"name": f"MRZ{s}", "coils": [int(k) for k in idx], **m_specs[s]})
        elif kind == "mode tables":
            for k, t in enumerate(modes["types"] if modes else []):
                spec = specs([t["coils"]], sensor_mode_rz_step, sensor_mode_rz_log_step, 1)[0]

                def show(frac, k=k, last=[-1]):
                    if int(frac * 10) != last[0]:  # a line per 10 %, not per chunk
                        last[0] = int(frac * 10)
                        bar.set_postfix_str(f"mode tables {k + 1}: {frac:.0%}")

                tab = compute_mode_tables(t, spec, show)[0]
                st = t["sets"][0]
                shapes = [[m, r] for m in sorted(st["U"]) for r in range(st["U"][m].shape[1])]
                cols = np.cumsum([0] + [N_MODE_Q[m] for m, _ in shapes])[:-1].tolist()
                # float16, each column scaled to its largest |value|: the sensor field is a
                # few mT, its budget ~2 %
                col_scale = np.maximum(np.abs(tab).max(axis=(0, 1)), 1e-300)
                arrays[f"SM{k}"] = (tab / col_scale).astype(np.float16)
                sm_meta.append({"name": f"SM{k}", "coils": [int(c) for c in t["coils"]],
                                **spec, "shape": list(tab.shape), "shapes": shapes,
                                "column_scale": col_scale.tolist(),
                                "columns": [int(c) for c in cols],
                                "basis": [list(b) for b in st["basis"]]})
        elif kind == "magnet":
            f0[s:s + chunk] = phys.bias_force(arr, m_nodes[s:s + chunk])
        elif kind == "check":
            a_check[s:s + chunk] = phys.actuation(arr, check[s:s + chunk])
        elif kind == "magnet check":
            f0_check = phys.bias_force(arr, check[:n_mcheck])
            sind_check = phys.sensor_induced(arr, check[:n_mcheck])
        else:
            sat_i, sat_f = phys.saturation(arr)
        seconds[kind] = seconds.get(kind, 0.0) + time.perf_counter() - t0
    bar.close()
    t0 = time.perf_counter()
    row_max = np.maximum(np.abs(a_fit).max(axis=(0, 2)), 1e-300)
    start = 0
    for lay, axes in zip(layers, lattices):
        shape = tuple(len(a) for a in axes)
        stop = start + int(np.prod(shape))
        arrays[lay["name"]] = fit_layer(lay, a_fit[start:stop].reshape(shape + (8, nc)),
                                        row_max, fit_nodes)
        start = stop
    positions = arr.positions()
    rotations = [list(map(list, c.pose.rotation)) for c in arr.coils]
    mprep = mf.prepare_magnet([arrays[t["name"]] for t in mrz_meta], mrz_meta, positions,
                              rotations)
    f_pair = mf.magnet_terms(mprep, m_nodes)
    m_shape = tuple(len(a) for a in m_axes)
    sensor_rows = phys.sensor_coil_rows(arr)
    arrays.update({
        "SCOEF": modes["sensor_coef"] if modes else np.zeros((nc, 0, 2, nc, 3)),
        "F0_RES": (f0 - f_pair).reshape(m_shape + (3,)).astype(np.float32),
        "M_X": m_axes[0], "M_Y": m_axes[1], "M_Z": m_axes[2],
        "SENSOR_POS": phys.sensor_positions(arr).astype(np.float64),
        "SENSOR_COIL": sensor_rows[:, :, :3].astype(np.float64),
        "SENSOR_COIL_GRAD": sensor_rows[:, :, 3:].astype(np.float64),
        "MOMENT": phys.moment_a_m2.astype(np.float64),
        "SAT_I": sat_i.astype(np.float64), "SAT_FACTOR": sat_f.astype(np.float64),
    })
    meta = {
        "format": FORMAT, "version": FORMAT_VERSION, "designkit_version": __version__,
        "design_name": design.name, "design_sha256": design.spec_hash(),
        "rows": list(ROWS), "units": UNITS, "n_coils": nc,
        "n_sensor_basis": int(arrays["SCOEF"].shape[1]),
        "box_m": [lower.tolist(), upper.tolist()],
        "a_layers": layers, "sources_top_m": z_top,
        "sensor_mode_tables": sm_meta, "magnet_tables": mrz_meta,
        "coil_positions_m": positions.tolist(), "coil_rotations": rotations,
        "max_current_a": design.drive.max_current_a,
        # the finger magnet's cylinder (the localizer's exact magnet field; MOMENT is its moment)
        "magnet_radius_m": design.magnet.radius_m, "magnet_length_m": design.magnet.length_m,
        "total_current_a": design.drive.total_current_a,
        # what firmware_io.runner.config_from_map needs (R, L, supply, limits, I^2 t guard)
        "drive": drive_data(design, _drive_coils(arr)),
        "physics": phys.source,
        "settings": {"spacing_m": spacing, "log_step": log_step,
                     "cell_ratio": list(cell_ratio), "layer_ratio": list(layer_ratio),
                     "degree": list(degree), "fit_nodes": fit_nodes,
                     "n_fit_points": len(fit_pts),
                     "sensor_mode_tolerance": sensor_mode_tolerance,
                     "rz_rho_scale_m": rz_rho_scale,
                     "sensor_mode_rz_step_m": sensor_mode_rz_step,
                     "sensor_mode_rz_log_step": sensor_mode_rz_log_step,
                     "magnet_rz_step_m": magnet_rz_step,
                     "magnet_rz_log_step": magnet_rz_log_step},
    }
    reader = mf.MapFile.from_arrays(arrays, meta)
    scale = np.maximum(np.abs(a_check).max(axis=(0, 2)), 1e-300)
    err = np.abs(reader.actuation(check) - a_check) / scale[None, :, None]
    fit_err = np.abs(reader.actuation(fit_pts, True) - a_fit) / row_max[None, :, None]

    def rel(got, ref):
        return float(np.abs(got - ref).max() / max(np.abs(ref).max(), 1e-300))

    meta["errors"] = {
        "n_points": n_check,
        "actuation_max_rel_per_row": dict(zip(ROWS, err.max(axis=(0, 2)).tolist())),
        "actuation_rms_rel": float(np.sqrt((err ** 2).mean())),
        "n_fit_points": len(fit_pts),
        "actuation_fit_nodes_max_rel": float(fit_err.max()),
        "n_magnet_points": n_mcheck,
        "bias_force_max_rel": rel(reader.bias_force(check[:n_mcheck]), f0_check),
        "sensor_induced_max_rel": rel(reader.sensor_induced_field(check[:n_mcheck]),
                                      sind_check)}
    seconds["fits and check"] = time.perf_counter() - t0
    meta["build_seconds"] = seconds
    return {"arrays": arrays, "meta": meta}


def _drive_coils(arr: CoilArray) -> list:
    """One coil model per channel for the drive data: R and L do not depend on the pose, so
    each coil type's prototype stands for its coils (one inductance solve per type)."""
    out = [None] * arr.n_coils
    for proto, idx in arr.coil_types().items():
        for k in idx:
            out[k] = proto
    return out


# ============================================================================ write / load
def check_output(path) -> Path:
    """Refuse an output path that cannot take a map file, before any computation."""
    path = Path(path)
    if path.is_dir():
        raise BadInputError("--out", "a file path (a map file is one .npz file)",
                            f"{path} (an existing folder)",
                            f"Give a file name, e.g. {path / 'fieldmap.npz'}.")
    if path.suffix != ".npz":
        raise BadInputError("--out", "a path ending in .npz", str(path))
    parent = path.parent if str(path.parent) else Path(".")
    if parent.exists() and not parent.is_dir():
        raise BadInputError("--out", "a path whose folder is a folder",
                            f"{path} ({parent} is a file)")
    return path


def write(path, data: dict) -> Path:
    """Write the map atomically (never a half-written file at ``path``)."""
    from ._io import atomic_path

    path = check_output(path)
    try:
        with atomic_path(path, suffix=".npz") as tmp:
            mf.write(tmp, data["arrays"], data["meta"])
    except _FirmwareBadInput as exc:
        raise _translate(exc) from None
    return path


def _translate(exc: _FirmwareBadInput) -> BadInputError:
    return BadInputError(exc.name, exc.valid, exc.received, exc.hint)


class FieldMap:
    """A loaded map v2: :class:`firmware_io.mapfile.MapFile` with designkit's errors.

    Attributes and methods are the MapFile's (``actuation``, ``bias_force``,
    ``sensor_induced_field``, ``sensor_coil_field``, ``sensor_coil_gradient``,
    ``saturation_factor``, ``bounds``, ``meta``,
    ``n_coils``, ``sensor_positions_m``, ``moment_a_m2``, ``design_sha256``, ``max_current_a``,
    ``total_current_a``); ``outside='extrapolate'`` is the MapFile's ``extrapolate=True``.
    """

    def __init__(self, mapfile: "mf.MapFile"):
        self.file = mapfile

    def __getattr__(self, name):
        return getattr(self.file, name)

    def _call(self, fn, *args):
        try:
            return fn(*args)
        except _FirmwareBadInput as exc:
            raise _translate(exc) from None

    @staticmethod
    def _outside(outside: str) -> bool:
        if outside not in ("error", "extrapolate"):
            raise BadInputError("outside", "'error' or 'extrapolate'", outside)
        return outside == "extrapolate"

    def actuation(self, points, *, outside: str = "error", rows=None,
                  coils=None) -> np.ndarray:
        """Coupled A: (3,) -> (8, n_coils), (n, 3) -> (n, 8, n_coils); T/A, T/(m A).
        ``rows``, ``coils``: index subsets (MapFile.actuation), shapes (.., len(rows),
        len(coils))."""
        try:
            return self.file.actuation(points, self._outside(outside), rows=rows, coils=coils)
        except _FirmwareBadInput as exc:
            raise _translate(exc) from None

    def bias_force(self, points, *, outside: str = "error") -> np.ndarray:
        """F0 at zero current, N: (3,) -> (3,), (n, 3) -> (n, 3)."""
        return self._call(self.file.bias_force, points, self._outside(outside))

    def sensor_induced_field(self, magnet_position_m, *, outside: str = "error") -> np.ndarray:
        """Magnet-induced core field at the sensors, T: (3,) -> (2, n_coils, 3)."""
        return self._call(self.file.sensor_induced_field, magnet_position_m,
                          self._outside(outside))

    def sensor_coil_field(self, currents=None) -> np.ndarray:
        """(2, n_coils, 3, n_coils) T/A, or (2, n_coils, 3) T for ``currents`` (A)."""
        return self._call(self.file.sensor_coil_field, currents)

    def saturation_factor(self, currents) -> np.ndarray:
        """Per-coil factors (n_coils,) on the columns of A at ``currents`` (A)."""
        return self._call(self.file.saturation_factor, currents)


def load(path, design=None) -> FieldMap:
    """Load and validate a map file; with ``design``, also check it was built from it.

    Raises BadInputError for a missing, non-map, truncated, foreign, pre-v2, corrupted or
    mismatched file, saying how to rebuild it where that helps.
    """
    try:
        f = mf.MapFile.load(path)
    except _FirmwareBadInput as exc:
        raise _translate(exc) from None
    if design is not None and f.design_sha256 != design.spec_hash():
        raise BadInputError("map file", f"built from design {design.name!r} (SHA-256 "
                            f"{design.spec_hash()[:12]}...)",
                            f"{path} (design {f.meta.get('design_name')!r}, SHA-256 "
                            f"{f.design_sha256[:12]}...)",
                            "Rebuild it: designkit map --design <design.toml> --out <file.npz>")
    return FieldMap(f)
