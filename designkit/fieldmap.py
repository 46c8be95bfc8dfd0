"""Map file v2: build it from a design, write it, load it (:class:`FieldMap`).

The format -- array names, shapes, validation, interpolation -- is defined once, in the
numpy-only reader :mod:`firmware_io.mapfile` (read its docstring for the file's contents);
this module computes the arrays from a :class:`~designkit.array.CoilArray`, writes them
atomically, and :class:`FieldMap` wraps :class:`firmware_io.mapfile.MapFile` with designkit's
errors. All the physics the map samples comes through one function, :func:`map_physics`.

Representation and error budget (target: <= 1e-3 of each row's largest |A| over the box)
-----------------------------------------------------------------------------------------
The coupled A is not axisymmetric, but much of its sharp structure is: near a core's rim the
field is dominated by that core, magnetized mostly along its axis. So

* tables: per coil type, exact axisymmetric (rho, z) tables of one coil alone and of its core
  alone (1.4 MB; interpolation error ~1.3e-4 of each row's maximum: steps 0.1 mm in rho near
  the axis, growing as (1 + rho / 50 mm)^2, and 2.5 % of the height above the core's top in z);
* ``MIX``: ``A_core @ MIX`` adds to column k the extra axial magnetization of every core by
  coil k, with that core's own field shape (least squares over the residual grid's nodes);
* residual: the rest, sampled from the coupled model on a coarse 3-D grid (15 mm in x, y; z
  steps growing with the height above the cores), SVD-compressed, trilinear.

Measured on the default 3 x 3 iron-core array (designkit.coupling, November 2026): the rest is
NOT small -- the transverse (m = 1, 2) magnetization of the neighbour cores reaches ~15 % of
each row's maximum near the bottom of the box and is as sharp as the rims -- so this map is
within ~4-12 % of the coupled model, not 1e-3 (``studies/bench_map.py``; the build records its
own check in ``meta['errors']``). Sampling the coupled model costs ~10-100 ms per point, which
rules out a finer residual grid within the build budget. The fix is structural: tabulate the
cores' coupled modes themselves (per core type, the SVD of the solved unknowns of all cores for
all coils: rank 3 for m = 0 at 8e-5; for m = 1, 2 the potential x G(rho^2, z) resp.
(x^2 - y^2) H(rho^2, z), so 5 smooth (rho, z) quantities per mode give all 8 rows) and mix them
per column -- exact up to the tables, with no 3-D grid for A.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import _validate as v
from .array import ROWS, CoilArray
from .errors import BadInputError
from firmware_io import mapfile as mf
from firmware_io.errors import BadInputError as _FirmwareBadInput

FORMAT, FORMAT_VERSION, UNITS, BATCH_MIN = mf.FORMAT, mf.FORMAT_VERSION, mf.UNITS, mf.BATCH_MIN


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
RZ_QUANTITIES = ("Br/rho", "Bz", "(dBr/dz)/rho", "(dBr/drho - Br/rho)/rho^2")
"""Per-ampere quantities of a (rho, z) table, units T/(m A), T/A, T/(m^2 A), T/(m^3 A)."""


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


def compute_rz_table(coil, spec: dict, *, chunk: int = 8192) -> np.ndarray:
    """The table (n_rho, n_u, 8) float64 of ``spec``: b, Bz, e, w (see
    :data:`RZ_QUANTITIES`) of the whole coil, then of its core alone (whole minus the winding),
    by direct evaluation (Coil.field, rtol 1e-10) on the nodes; e and w on the axis by
    Richardson extrapolation (both are even in rho)."""
    from .scene import _rz_direct

    rho, z = _spec_nodes(spec)
    n_rho, n_u = len(rho), len(z)
    R, Z = np.meshgrid(rho[1:], z, indexing="ij")
    r, zz = R.ravel(), Z.ravel()
    out = np.zeros((n_rho, n_u, 8))
    flat = out[1:].reshape(-1, 8)
    parts = [coil] + ([coil.replace(core=None)] if coil.core is not None else [])
    for part, c in enumerate(parts):
        for s in range(0, len(r), chunk):
            sl = slice(s, s + chunk)
            d = _rz_direct(c, r[sl], zz[sl], True)
            b = d["br_over_rho"]
            flat[sl, 4 * part + 0] = b
            flat[sl, 4 * part + 1] = d["bz"]
            flat[sl, 4 * part + 2] = d["dbr_dz"] / r[sl]
            flat[sl, 4 * part + 3] = (d["dbr_drho"] - b) / r[sl] ** 2
        d0 = _rz_direct(c, np.zeros(n_u), z, True)
        out[0, :, 4 * part] = d0["br_over_rho"]
        out[0, :, 4 * part + 1] = d0["bz"]
        _even_on_axis(out, rho, [4 * part + 2, 4 * part + 3])
    if len(parts) == 2:  # core alone = whole - winding alone
        out[..., 4:] = out[..., :4] - out[..., 4:]
    return out


def compute_magnet_table(phys: "MapPhysics", coil, spec: dict) -> np.ndarray:
    """The magnet table (n_rho, n_u, 3) float64 of one coil alone at the origin: F_rho/rho and
    F_z of the magnet's pull on its core (N/m, N) and a, the z field of the core magnetized by
    the magnet at the coil's upper sensor (T), for the magnet at (rho, 0, z)."""
    from .pose import Pose

    alone = CoilArray((coil.replace(pose=Pose()),))
    rho, z = _spec_nodes(spec)
    R, Z = np.meshgrid(rho, z, indexing="ij")
    pts = np.c_[R.ravel(), np.zeros(R.size), Z.ravel()]
    f, amp = phys.magnet_alone(alone, pts)
    out = np.empty((len(rho), len(z), 3))
    with np.errstate(divide="ignore", invalid="ignore"):
        out[..., 0] = (f[:, 0] / pts[:, 0]).reshape(R.shape)
    out[..., 1] = f[:, 2].reshape(R.shape)
    out[..., 2] = amp.reshape(R.shape)
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

    def magnet_alone(self, alone: CoilArray, points):
        """One coil alone: F0 (n, 3) N and the z field (n,) T of its magnetized core at its
        upper sensor, for the magnet at ``points``."""
        return self.bias_force(alone, points), self.sensor_induced(alone, points)[:, 0, 0, 2]

    def sensor_coil_field(self, array: CoilArray) -> np.ndarray:
        """(2, n_coils, 3, n_coils) T/A: the coupled field of each coil at the sensors."""
        s = self.sensor_positions(array).reshape(-1, 3)
        nc = array.n_coils
        return self.actuation(array, s)[:, :3, :].reshape(2, nc, 3, nc)

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


# ============================================================================ build
def build(design, *, spacing: float = 0.015, coupling_log_step: float = 0.35,
          magnet_spacing: float = 0.025, magnet_log_step: float = 0.5,
          svd_tolerance: float = 1e-4, rz_step: float = 1e-4, rz_log_step: float = 0.025,
          rz_rho_scale: float = 0.05, magnet_rz_step: float = 2e-3,
          magnet_rz_log_step: float = 0.15, box=None, n_check: int = 100,
          progress: bool = True, array: CoilArray | None = None) -> dict:
    """Compute the map v2 of ``design``: ``{"arrays": {...}, "meta": {...}}`` (not yet written).

    Parameters
    ----------
    spacing : float, m
        x, y step of the coupling residual grid (its z steps grow from ``coupling_log_step``
        x the height above the cores' tops, never above ``spacing``).
    magnet_spacing, magnet_log_step : float
        The same for the residual grids over magnet positions (bias force, sensor fields).
    svd_tolerance : float
        Largest error of the rank-truncated coupling residual at its nodes, relative to each
        row's max |A|.
    rz_step : float, m
        rho step of the (rho, z) tables on the axis (default 0.1 mm, growing as
        (1 + rho / rz_rho_scale)^2 with rz_rho_scale 50 mm: ~0.4 mm at 50 mm from the axis);
        ``rz_log_step`` is the step in log(z - z_ref) (default 0.025: 2.5 % of the height
        above the core's top). ``magnet_rz_step``, ``magnet_rz_log_step``: the same for the
        magnet tables (2 mm, 15 %).
    box : (lower, upper) or None
        Corners, m; default :func:`default_box`.
    n_check : int
        Random points where the finished map is compared with direct evaluation (meta 'errors').
    """
    from ._progress import tqdm

    from . import __version__

    spacing = v.in_range("spacing", spacing, 5e-4, 0.05, "m")
    magnet_spacing = v.in_range("magnet_spacing", magnet_spacing, 5e-4, 0.05, "m")
    coupling_log_step = v.in_range("coupling_log_step", coupling_log_step, 1e-3, 1.0)
    magnet_log_step = v.in_range("magnet_log_step", magnet_log_step, 1e-3, 1.0)
    svd_tolerance = v.in_range("svd_tolerance", svd_tolerance, 1e-7, 1e-2)
    rz_step = v.in_range("rz_step", rz_step, 1e-5, 0.01, "m")
    rz_log_step = v.in_range("rz_log_step", rz_log_step, 1e-3, 0.5)
    rz_rho_scale = v.in_range("rz_rho_scale", rz_rho_scale, 1e-3, 10.0, "m")
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

    def specs(step, log_step, n_q):
        out = []
        for _, idx in types:
            s = [rz_table_spec(arr.coils[k], lower, upper, step, log_step, rz_rho_scale, n_q)
                 for k in idx]
            if any(x is None for x in s):
                raise BadInputError("box", "above every coil's winding and core (the map's "
                                    "(rho, z) tables cover only points above the sources), m",
                                    (lower.tolist(), upper.tolist()))
            out.append(_union_spec(s))
        return out

    a_specs = specs(rz_step, rz_log_step, 8)
    m_specs = specs(magnet_rz_step, magnet_rz_log_step, 3)
    z_ref = max(arr.coils[k].pose.position[2] + s["z_ref_m"] for (_, idx), s in zip(types, a_specs)
                for k in idx)
    c_axes = box_axes(lower, upper, spacing, z_ref, coupling_log_step)
    m_axes = box_axes(lower, upper, magnet_spacing, z_ref, magnet_log_step)
    c_nodes, m_nodes = _nodes(c_axes), _nodes(m_axes)
    rng = np.random.default_rng(20261123)
    check = rng.uniform(lower, upper, (n_check, 3))
    n_mcheck = min(n_check, 500)
    chunk = 512
    work = ([("tables", k) for k in range(len(types))]
            + [("coupled A", s) for s in range(0, len(c_nodes), chunk)]
            + [("magnet", s) for s in range(0, len(m_nodes), chunk)]
            + [("check", s) for s in range(0, n_check, chunk)] + [("magnet check", 0)])
    arrays: dict = {}
    rz_meta, mrz_meta = [], []
    a_c = np.empty((len(c_nodes), 8, nc))
    f0 = np.empty((len(m_nodes), 3))
    sind = np.empty((len(m_nodes), 2, nc, 3))
    a_check = np.empty((n_check, 8, nc))
    seconds: dict = {}
    bar = tqdm(work, desc="map", unit="step", disable=not progress, leave=False)
    for kind, s in bar:
        bar.set_postfix_str(kind, refresh=False)
        t0 = time.perf_counter()
        if kind == "tables":
            proto, idx = types[s]
            arrays[f"RZ{s}"] = compute_rz_table(proto, a_specs[s]).astype(np.float32)
            rz_meta.append({"name": f"RZ{s}", "coils": [int(k) for k in idx], **a_specs[s]})
            arrays[f"MRZ{s}"] = compute_magnet_table(phys, proto, m_specs[s]).astype(np.float32)
            mrz_meta.append({"name": f"MRZ{s}", "coils": [int(k) for k in idx], **m_specs[s]})
        elif kind == "coupled A":
            a_c[s:s + chunk] = phys.actuation(arr, c_nodes[s:s + chunk])
        elif kind == "magnet":
            f0[s:s + chunk] = phys.bias_force(arr, m_nodes[s:s + chunk])
            sind[s:s + chunk] = phys.sensor_induced(arr, m_nodes[s:s + chunk])
        elif kind == "check":
            a_check[s:s + chunk] = phys.actuation(arr, check[s:s + chunk])
        else:
            f0_check = phys.bias_force(arr, check[:n_mcheck])
            sind_check = phys.sensor_induced(arr, check[:n_mcheck])
        seconds[kind] = seconds.get(kind, 0.0) + time.perf_counter() - t0
    bar.close()
    t0 = time.perf_counter()
    positions = arr.positions()
    rotations = [list(map(list, c.pose.rotation)) for c in arr.coils]
    # the tables' part as the reader computes it (so the fits absorb the table error at nodes)
    prep = mf.prepare_rz([arrays[t["name"]] for t in rz_meta], rz_meta, positions, rotations)
    whole, core = (np.ascontiguousarray(x.transpose(2, 1, 0), dtype=np.float64)
                   for x in mf.interpolate_rz(prep, c_nodes, nc))
    scale = np.maximum(np.abs(a_c).max(axis=(0, 2)), 1e-300)  # (8,) per-row max
    mix = _fit_mix(whole, core, a_c, scale)
    resid = a_c - whole - np.einsum("nrj,jk->nrk", core, mix)
    phi, modes, rank = _compress(resid, scale, svd_tolerance)
    mprep = mf.prepare_magnet([arrays[t["name"]] for t in mrz_meta], mrz_meta, positions,
                              rotations)
    f_pair, amp = mf.magnet_terms(mprep, m_nodes, nc)
    sind_flat = sind.reshape(len(m_nodes), -1)
    sind_mix = np.linalg.lstsq(amp, sind_flat, rcond=None)[0] if np.abs(amp).max() > 0 else \
        np.zeros((nc, 6 * nc))
    m_shape = tuple(len(a) for a in m_axes)
    sat_i, sat_f = phys.saturation(arr)
    arrays.update({
        "MIX": mix, "PHI": phi.reshape(tuple(len(a) for a in c_axes) + (rank,)).astype(np.float16),
        "MODES": modes.astype(np.float32),
        "C_X": c_axes[0], "C_Y": c_axes[1], "C_Z": c_axes[2],
        "F0_RES": (f0 - f_pair).reshape(m_shape + (3,)).astype(np.float32),
        "SIND_MIX": sind_mix.reshape(nc, 2, nc, 3),
        "SIND_RES": (sind_flat - amp @ sind_mix).reshape(m_shape + (2, nc, 3)).astype(np.float16),
        "M_X": m_axes[0], "M_Y": m_axes[1], "M_Z": m_axes[2],
        "SENSOR_POS": phys.sensor_positions(arr).astype(np.float64),
        "SENSOR_COIL": phys.sensor_coil_field(arr).astype(np.float64),
        "MOMENT": phys.moment_a_m2.astype(np.float64),
        "SAT_I": sat_i.astype(np.float64), "SAT_FACTOR": sat_f.astype(np.float64),
    })
    meta = {
        "format": FORMAT, "version": FORMAT_VERSION, "designkit_version": __version__,
        "design_name": design.name, "design_sha256": design.spec_hash(),
        "rows": list(ROWS), "units": UNITS, "n_coils": nc, "coupling_rank": rank,
        "box_m": [lower.tolist(), upper.tolist()],
        "rz_tables": rz_meta, "rz_quantities": list(RZ_QUANTITIES),
        "magnet_tables": mrz_meta,
        "coil_positions_m": positions.tolist(), "coil_rotations": rotations,
        "max_current_a": design.drive.max_current_a,
        "total_current_a": design.drive.total_current_a,
        "physics": phys.source,
        "settings": {"spacing_m": spacing, "coupling_log_step": coupling_log_step,
                     "magnet_spacing_m": magnet_spacing, "magnet_log_step": magnet_log_step,
                     "svd_tolerance": svd_tolerance, "rz_step_m": rz_step,
                     "rz_log_step": rz_log_step, "rz_rho_scale_m": rz_rho_scale,
                     "magnet_rz_step_m": magnet_rz_step,
                     "magnet_rz_log_step": magnet_rz_log_step},
    }
    reader = mf.MapFile.from_arrays(arrays, meta)
    err = np.abs(reader.actuation(check) - a_check) / scale[None, :, None]

    def rel(got, ref):
        return float(np.abs(got - ref).max() / max(np.abs(ref).max(), 1e-300))

    meta["errors"] = {
        "n_points": n_check,
        "actuation_max_rel_per_row": dict(zip(ROWS, err.max(axis=(0, 2)).tolist())),
        "actuation_rms_rel": float(np.sqrt((err ** 2).mean())),
        "n_magnet_points": n_mcheck,
        "bias_force_max_rel": rel(reader.bias_force(check[:n_mcheck]), f0_check),
        "sensor_induced_max_rel": rel(reader.sensor_induced_field(check[:n_mcheck]),
                                      sind_check)}
    seconds["fits and check"] = time.perf_counter() - t0
    meta["build_seconds"] = seconds
    return {"arrays": arrays, "meta": meta}


def _fit_mix(whole: np.ndarray, core: np.ndarray, a_c: np.ndarray, scale: np.ndarray):
    """MIX (nc, nc) minimizing |(whole + core @ MIX - A) / scale| over the nodes."""
    n, _, nc = core.shape
    s = (core / scale[None, :, None]).reshape(n * 8, nc)
    c = ((a_c - whole) / scale[None, :, None]).reshape(n * 8, nc)
    if not np.any(s):
        return np.zeros((nc, nc))  # no cores: nothing to mix
    return np.linalg.lstsq(s, c, rcond=None)[0]


def _compress(resid: np.ndarray, scale: np.ndarray, tolerance: float):
    """Truncated SVD of the residual (n, 8, nc): PHI (n, r), MODES (r, 8, nc), r.

    r is the smallest rank whose largest error at the nodes, relative to each row's ``scale``,
    is at most ``tolerance`` (at least 1, so the arrays are never empty).
    """
    n, _, nc = resid.shape
    x = (resid / scale[None, :, None]).reshape(n, 8 * nc)
    u, sv, vt = np.linalg.svd(x, full_matrices=False)

    def err(r):
        return np.abs(x - (u[:, :r] * sv[:r]) @ vt[:r]).max()

    lo, hi = 1, len(sv)  # err(hi) ~ 0: bisect on the smallest r with err(r) <= tolerance
    if err(lo) <= tolerance:
        hi = lo
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if err(mid) <= tolerance else (mid, hi)
    rank = hi
    phi = u[:, :rank] * sv[:rank]
    modes = vt[:rank].reshape(rank, 8, nc) * scale[None, :, None]
    return phi, modes, rank


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
    ``sensor_induced_field``, ``sensor_coil_field``, ``saturation_factor``, ``bounds``, ``meta``,
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

    def actuation(self, points, *, outside: str = "error") -> np.ndarray:
        """Coupled A: (3,) -> (8, n_coils), (n, 3) -> (n, 8, n_coils); T/A, T/(m A)."""
        return self._call(self.file.actuation, points, self._outside(outside))

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
