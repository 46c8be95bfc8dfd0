"""Building the map of a design: :func:`build`, in named phases.

settings (validate every argument) -> plan (box, cell layers, fit lattices, table grids, check
points: :mod:`.plan`) -> samples (the coupled model at every node, the per-core tables, the
saturation; one progress bar) -> arrays (cell fits :mod:`.cells`, the bias force's residual
grid, the sensor constants) -> meta -> check (the finished map against the coupled model at
random points, recorded in ``meta['errors']``). Lengths in m, A in T/A and T/(m A), forces in
N. What the choices cost and how accurate the result is: docs/fieldmap.md.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from firmware_io import mapfile as mf

from .. import __version__
from ..errors import BadInputError
from ..model.array import ROWS, CoilArray
from ..model.electrical import drive_data
from ..support import validate as v
from ..support.blas import one_blas_thread
from ..support.progress import tqdm
from .cells import fit_layers
from .physics import MapPhysics, map_physics
from .plan import N_CHECK, _nodes, box_axes, cell_layers, default_box, layer_nodes, sources_top, table_specs
from .symmetry import Orbits, array_symmetries, random_orbits
from .tables import (compute_magnet_table, coupled_modes, finite_size_correction,
                     mode_table_entry)

FORMAT, FORMAT_VERSION, UNITS = mf.FORMAT, mf.FORMAT_VERSION, mf.UNITS
CHUNK = 64
"""Magnet positions / check points per coupled-model call of the sampling phase."""
FIT_CHUNK = 512
"""Fit nodes per coupled-model call of the sampling phase."""
CHECK_SEED = 20261123
"""Seed of the random check points (the same points for every build of a box)."""
N_F0_CHECK = 16
"""Check points where the map's F0 is compared with the finite cylinder's (meta 'errors';
~15-30 ms each, the dipole's ~1 ms: the first of the magnet check points)."""


def build(design, *, spacing: float = 0.01, log_step: float = 0.25,
          cell_ratio=(1.0, 0.5), layer_ratio=(0.7, 0.5), degree=(12, 7),
          fit_nodes: int = 4, sensor_mode_tolerance: float = 1e-3,
          rz_rho_scale: float = 0.05, sensor_mode_rz_step: float = 2.5e-4,
          sensor_mode_rz_log_step: float = 0.04, magnet_rz_step: float = 5e-4,
          magnet_rz_log_step: float = 0.02, box=None, n_check: int = N_CHECK,
          progress: bool = True, array: CoilArray | None = None,
          region: dict | None = None) -> dict:
    """Compute the map v2 of ``design``: ``{"arrays": {...}, "meta": {...}}`` (not yet written).

    Parameters
    ----------
    spacing, log_step : float
        x, y step (m) of the grids over magnet positions that carry what the per-core magnet
        tables miss (the bias force's core-to-core part, trilinear); their z steps grow from
        ``log_step`` x the height above the cores' tops, never above ``spacing``. The defaults'
        F0 error against the coupled model: docs/fieldmap.md.
    cell_ratio, layer_ratio, degree, fit_nodes
        A's harmonic cells (:func:`~designkit.fieldmap.plan.cell_layers`): cells no wider than
        ``cell_ratio`` and layers ``layer_ratio`` x the height of their floor above the sources'
        top, potentials of degree ``degree`` (K = (degree + 1)^2 - 1 coefficients per cell and
        coil); each a sequence per layer from the lowest (the last entry for the layers above;
        ``layer_ratio`` may be one number); fitted on ``fit_nodes``^3 Chebyshev-Lobatto nodes
        per cell (shared across faces; each node is one evaluation of the coupled model).
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
        of one core falls ~z^-7 near it, so coarse bilinear steps in z leave large errors).
    box : (lower, upper) or None
        Corners, m; default :func:`~designkit.fieldmap.plan.default_box`.
    n_check : int
        Random points where the finished map is compared with the coupled model (meta
        'errors'): n_check / |G| uniform points evaluated directly and their images under the
        box's symmetries G filled exactly (:func:`.symmetry.random_orbits`).
    region : dict or None
        What ``box`` was made for (a scene map: :mod:`.region`), stored as meta 'region'.
    """
    s = BuildSettings.checked(spacing, log_step, cell_ratio, layer_ratio, degree, fit_nodes,
                              sensor_mode_tolerance, rz_rho_scale, sensor_mode_rz_step,
                              sensor_mode_rz_log_step, magnet_rz_step, magnet_rz_log_step,
                              n_check)
    arr = array or CoilArray.from_design(design)
    lower, upper = _box(design, box)
    phys = map_physics(design)
    plan = _plan(arr, lower, upper, s, phys.moment_a_m2)
    smp = _sample(phys, arr, plan, s, progress)
    t0, c0 = time.perf_counter(), time.process_time()
    arrays, row_max = _arrays(phys, arr, plan, smp, s.fit_nodes)
    meta = _meta(design, arr, phys, plan, s, arrays, smp)
    if region is not None:
        meta["region"] = dict(region)
    with one_blas_thread():  # the reader's small pseudo-inverses: threads would only spin
        meta["errors"] = _errors(mf.MapFile.from_arrays(arrays, meta), plan, smp, row_max)
    smp.seconds["fits and check"] = time.perf_counter() - t0
    smp.cpu_seconds["fits and check"] = time.process_time() - c0
    meta["build_seconds"] = smp.seconds
    meta["build_cpu_seconds"] = smp.cpu_seconds
    return {"arrays": arrays, "meta": meta}


# ============================================================================ settings
@dataclass(frozen=True)
class BuildSettings:
    """The validated arguments of :func:`build` (same names and units)."""

    spacing: float
    log_step: float
    cell_ratio: tuple
    layer_ratio: tuple
    degree: tuple
    fit_nodes: int
    sensor_mode_tolerance: float
    rz_rho_scale: float
    sensor_mode_rz_step: float
    sensor_mode_rz_log_step: float
    magnet_rz_step: float
    magnet_rz_log_step: float
    n_check: int

    @classmethod
    def checked(cls, spacing, log_step, cell_ratio, layer_ratio, degree, fit_nodes,
                sensor_mode_tolerance, rz_rho_scale, sensor_mode_rz_step,
                sensor_mode_rz_log_step, magnet_rz_step, magnet_rz_log_step,
                n_check) -> "BuildSettings":
        """Every argument checked, in this order (BadInputError naming it and its range)."""
        spacing = v.in_range("spacing", spacing, 5e-4, 0.1, "m")
        log_step = v.in_range("log_step", log_step, 1e-3, 2.0)
        if np.ndim(layer_ratio) == 0:
            layer_ratio = (layer_ratio,)
        if (np.ndim(cell_ratio) != 1 or np.ndim(degree) != 1 or np.ndim(layer_ratio) != 1
                or not len(cell_ratio) or not len(degree) or not len(layer_ratio)):
            raise BadInputError("cell_ratio, layer_ratio, degree", "sequences, per layer from "
                                "the lowest (the last one for the layers above)",
                                (cell_ratio, layer_ratio, degree))
        return cls(
            spacing, log_step,
            tuple(v.in_range("cell_ratio", r, 0.05, 2.0) for r in cell_ratio),
            tuple(v.in_range("layer_ratio", r, 0.05, 2.0) for r in layer_ratio),
            tuple(int(v.in_range("degree", d, 2, 12)) for d in degree),
            int(v.in_range("fit_nodes", fit_nodes, 3, 8)),
            v.in_range("sensor_mode_tolerance", sensor_mode_tolerance, 1e-8, 1e-1),
            v.in_range("rz_rho_scale", rz_rho_scale, 1e-3, 10.0, "m"),
            v.in_range("sensor_mode_rz_step", sensor_mode_rz_step, 1e-5, 0.01, "m"),
            v.in_range("sensor_mode_rz_log_step", sensor_mode_rz_log_step, 1e-3, 0.5),
            v.in_range("magnet_rz_step", magnet_rz_step, 1e-5, 0.01, "m"),
            v.in_range("magnet_rz_log_step", magnet_rz_log_step, 1e-3, 0.5),
            v.positive_int("n_check", n_check))

    def meta(self, n_fit_points: int) -> dict:
        """The map's meta ``settings`` (lengths with their unit in the key)."""
        return {"spacing_m": self.spacing, "log_step": self.log_step,
                "cell_ratio": list(self.cell_ratio), "layer_ratio": list(self.layer_ratio),
                "degree": list(self.degree), "fit_nodes": self.fit_nodes,
                "n_fit_points": n_fit_points,
                "sensor_mode_tolerance": self.sensor_mode_tolerance,
                "rz_rho_scale_m": self.rz_rho_scale,
                "sensor_mode_rz_step_m": self.sensor_mode_rz_step,
                "sensor_mode_rz_log_step": self.sensor_mode_rz_log_step,
                "magnet_rz_step_m": self.magnet_rz_step,
                "magnet_rz_log_step": self.magnet_rz_log_step}


def _box(design, box) -> tuple[np.ndarray, np.ndarray]:
    """The map's box (lower (3,), upper (3,)), m: ``box`` checked, or the design's default."""
    lower, upper = default_box(design) if box is None else (np.asarray(box[0], float),
                                                            np.asarray(box[1], float))
    if lower.shape != (3,) or upper.shape != (3,) or not np.all(upper > lower):
        raise BadInputError("box", "lower < upper in x, y and z, m",
                            (lower.tolist(), upper.tolist()))
    return lower, upper


# ============================================================================ plan
@dataclass(frozen=True)
class _Plan:
    """Where the build samples (m): see :func:`_plan`."""

    lower: np.ndarray
    upper: np.ndarray
    types: list            # [(prototype coil, [coil indices])] per coil type
    m_specs: list          # the magnet tables' grids, per coil type
    z_top: float           # the top of all sources
    layers: list           # meta a_layers
    lattices: list         # per layer its fit lattice's x, y, z axes
    fit_pts: np.ndarray    # (N, 3) every layer's lattice, in layer order
    m_axes: list           # the bias force residual grid's axes
    m_nodes: np.ndarray    # (M, 3) its nodes
    check: np.ndarray      # (n_check, 3) random check points
    n_mcheck: int          # how many of them check the bias force and the sensor field
    positions: np.ndarray  # (n_coils, 3) coil positions
    rotations: list        # per coil its rotation matrix, nested lists
    fit_orbits: Orbits     # fit_pts by the array's symmetries: only fit_orbits.reps sampled
    m_orbits: Orbits       # m_nodes likewise
    check_orbits: Orbits   # check likewise (images of random points: :func:`random_orbits`)


def _plan(arr: CoilArray, lower, upper, s: BuildSettings, moment=None) -> _Plan:
    """The layout of everything the build samples, from the box and the settings; the
    array's symmetries about the box's vertical axis (:mod:`.symmetry`) pick the points
    sampled (the bias force's only with ``moment`` (3,) A m^2 along z)."""
    types = list(arr.coil_types().items())
    m_specs = table_specs(arr, [idx for _, idx in types], lower, upper, s.magnet_rz_step,
                          s.magnet_rz_log_step, s.rz_rho_scale, 2)
    z_top = sources_top(arr)
    layers = cell_layers(lower, upper, z_top, s.cell_ratio, s.layer_ratio, s.degree)
    lattices = [layer_nodes(lay, s.fit_nodes) for lay in layers]
    fit_pts = np.concatenate([_nodes(ax) for ax in lattices])
    z_ref = max(arr.coils[k].pose.position[2] + sp["z_ref_m"]
                for (_, idx), sp in zip(types, m_specs) for k in idx)
    m_axes = box_axes(lower, upper, s.spacing, z_ref, s.log_step)
    centre = 0.5 * (lower[:2] + upper[:2])
    group = array_symmetries(arr, centre)
    check, check_orbits = random_orbits(lower, upper, s.n_check, group, centre,
                                        np.random.default_rng(CHECK_SEED))
    m_nodes = _nodes(m_axes)
    upright = moment is not None and not np.any(np.asarray(moment, float)[:2])
    return _Plan(lower, upper, types, m_specs, z_top, layers, lattices, fit_pts, m_axes,
                 m_nodes, check, min(s.n_check, max(10, s.n_check // 8)), arr.positions(),
                 [list(map(list, c.pose.rotation)) for c in arr.coils],
                 Orbits.of(fit_pts, group, centre),
                 Orbits.of(m_nodes, group if upright else group[:1], centre), check_orbits)


# ============================================================================ samples
@dataclass
class _Samples:
    """What the sampling phase computes (SI): the coupled model at the plan's points and the
    per-core tables, with the seconds each kind of step took."""

    a_fit: np.ndarray                 # (N, 8, nc) A at the fit nodes
    a_check: np.ndarray               # (n_check, 8, nc) A at the check points
    f0: np.ndarray                    # (M, 3) N, F0 at the residual grid's nodes
    tables: dict = field(default_factory=dict)   # MRZ<k>, SM<k>
    mrz_dipole: dict = field(default_factory=dict)   # MRZ<k> of the point dipole (residual)
    mrz_meta: list = field(default_factory=list)
    sm_meta: list = field(default_factory=list)
    modes: dict | None = None         # coupled_modes
    f0_check: np.ndarray | None = None
    sind_check: np.ndarray | None = None
    sat_i: np.ndarray | None = None
    sat_f: np.ndarray | None = None
    seconds: dict = field(default_factory=dict)
    cpu_seconds: dict = field(default_factory=dict)  # process CPU time (all threads)


def _steps(plan: _Plan, n_check: int) -> list:
    """The sampling phase's steps (kind, index), in order: one progress-bar tick each."""
    return ([("coupled solve", 0)]
            + [("cell nodes", s) for s in range(0, len(plan.fit_orbits.reps), FIT_CHUNK)]
            + [("magnet tables", k) for k in range(len(plan.types))] + [("mode tables", 0)]
            + [("magnet", s) for s in range(0, len(plan.m_orbits.reps), CHUNK)]
            + [("check", s) for s in range(0, len(plan.check_orbits.reps), CHUNK)]
            + [("magnet check", 0), ("saturation", 0)])


def _sample(phys: MapPhysics, arr: CoilArray, plan: _Plan, s: BuildSettings,
            progress: bool) -> _Samples:
    """Every evaluation of the coupled model the map needs, under one progress bar."""
    nc = arr.n_coils
    # a_fit, a_check and f0 hold the orbits' representatives until the loop is done
    smp = _Samples(np.empty((len(plan.fit_orbits.reps), 8, nc)),
                   np.empty((len(plan.check_orbits.reps), 8, nc)),
                   np.empty((len(plan.m_orbits.reps), 3)))
    bar = tqdm(_steps(plan, s.n_check), desc="map", unit="step", disable=not progress,
               leave=False)
    for kind, k in bar:
        bar.set_postfix_str(kind, refresh=False)
        t0, c0 = time.perf_counter(), time.process_time()
        _step(kind, k, smp, phys, arr, plan, s, bar)
        smp.seconds[kind] = smp.seconds.get(kind, 0.0) + time.perf_counter() - t0
        smp.cpu_seconds[kind] = smp.cpu_seconds.get(kind, 0.0) + time.process_time() - c0
    bar.close()
    smp.a_fit = plan.fit_orbits.expand_actuation(smp.a_fit)
    smp.a_check = plan.check_orbits.expand_actuation(smp.a_check)
    smp.f0 = plan.m_orbits.expand_force(smp.f0)
    return smp


def _step(kind: str, k: int, smp: _Samples, phys: MapPhysics, arr: CoilArray, plan: _Plan,
          s: BuildSettings, bar) -> None:
    """One step of :func:`_steps` into ``smp``."""
    if kind == "coupled solve":
        arr.actuation_matrix(plan.fit_pts[:1])  # the coupled solve, once
        smp.modes = coupled_modes(arr, s.sensor_mode_tolerance)
    elif kind == "cell nodes":
        reps = plan.fit_orbits.reps[k:k + FIT_CHUNK]
        smp.a_fit[k:k + FIT_CHUNK] = phys.actuation(arr, plan.fit_pts[reps])
    elif kind == "magnet tables":
        proto, idx = plan.types[k]
        spec = plan.m_specs[k]
        # the point dipole's table carries the grid's residual; the stored one adds what the
        # magnet's finite size changes in each core's own pull (docs/fieldmap.md)
        dipole = compute_magnet_table(phys, proto, spec).astype(np.float32)
        smp.mrz_dipole[f"MRZ{k}"] = dipole
        smp.tables[f"MRZ{k}"] = (dipole + finite_size_correction(phys, proto, spec)
                                 ).astype(np.float32)
        smp.mrz_meta.append({"name": f"MRZ{k}", "coils": [int(c) for c in idx], **spec})
    elif kind == "mode tables":
        for j, t in enumerate(smp.modes["types"] if smp.modes else []):
            spec = table_specs(arr, [t["coils"]], plan.lower, plan.upper, s.sensor_mode_rz_step,
                               s.sensor_mode_rz_log_step, s.rz_rho_scale, 1)[0]
            smp.tables[f"SM{j}"], entry = mode_table_entry(t, spec, j, _postfix(bar, j))
            smp.sm_meta.append(entry)
    elif kind == "magnet":
        reps = plan.m_orbits.reps[k:k + CHUNK]
        smp.f0[k:k + CHUNK] = phys.bias_force(arr, plan.m_nodes[reps])
    elif kind == "check":
        reps = plan.check_orbits.reps[k:k + CHUNK]
        smp.a_check[k:k + CHUNK] = phys.actuation(arr, plan.check[reps])
    elif kind == "magnet check":
        # the truth: the finite cylinder (~20 x a dipole's cost: the first few points)
        smp.f0_check = phys.bias_force_finite(arr, plan.check[:min(plan.n_mcheck,
                                                                    N_F0_CHECK)])
        smp.sind_check = phys.sensor_induced(arr, plan.check[:plan.n_mcheck])
    else:
        smp.sat_i, smp.sat_f = phys.saturation(arr)


def _postfix(bar, k: int):
    """Progress callback of mode table ``k``: a postfix line per 10 %, not per chunk."""
    last = [-1]

    def show(frac):
        if int(frac * 10) != last[0]:
            last[0] = int(frac * 10)
            bar.set_postfix_str(f"mode tables {k + 1}: {frac:.0%}")

    return show


# ============================================================================ arrays, meta, check
def _arrays(phys: MapPhysics, arr: CoilArray, plan: _Plan, smp: _Samples,
            fit_nodes: int) -> tuple[dict, np.ndarray]:
    """Every array of the map file, and the rows' largest |A| (8,) the cells were fitted with."""
    nc = arr.n_coils
    arrays = dict(smp.tables)
    cells, row_max = fit_layers(plan.layers, plan.lattices, smp.a_fit, fit_nodes)
    arrays.update(cells)
    mprep = mf.prepare_magnet([smp.mrz_dipole[t["name"]] for t in smp.mrz_meta], smp.mrz_meta,
                              plan.positions, plan.rotations)
    f_pair = mf.magnet_terms(mprep, plan.m_nodes)
    m_shape = tuple(len(a) for a in plan.m_axes)
    sensor_rows = phys.sensor_coil_rows(arr)
    arrays.update({
        "SCOEF": (smp.modes["sensor_coef"] if smp.modes
                  else np.zeros((nc, 0, len(sensor_rows), 3))),
        "F0_RES": (smp.f0 - f_pair).reshape(m_shape + (3,)).astype(np.float32),
        "M_X": plan.m_axes[0], "M_Y": plan.m_axes[1], "M_Z": plan.m_axes[2],
        "SENSOR_POS": phys.sensor_positions(arr).astype(np.float64),
        "SENSOR_ROT": phys.sensor_rotations(arr).astype(np.float64),
        "SENSOR_COIL": sensor_rows[:, :3].astype(np.float64),
        "SENSOR_COIL_GRAD": sensor_rows[:, 3:].astype(np.float64),
        "MOMENT": phys.moment_a_m2.astype(np.float64),
        "SAT_I": smp.sat_i.astype(np.float64), "SAT_FACTOR": smp.sat_f.astype(np.float64),
    })
    return arrays, row_max


def _meta(design, arr: CoilArray, phys: MapPhysics, plan: _Plan, s: BuildSettings,
          arrays: dict, smp: _Samples) -> dict:
    """The map's meta (without 'errors' and 'build_seconds')."""
    return {
        "format": FORMAT, "version": FORMAT_VERSION, "designkit_version": __version__,
        "design_name": design.name, "design_sha256": design.spec_hash(),
        "rows": list(ROWS), "units": UNITS, "n_coils": arr.n_coils,
        "n_sensors": int(len(arrays["SENSOR_POS"])),
        "n_sensor_basis": int(arrays["SCOEF"].shape[1]),
        "box_m": [plan.lower.tolist(), plan.upper.tolist()],
        "a_layers": plan.layers, "sources_top_m": plan.z_top,
        "sensor_mode_tables": smp.sm_meta, "magnet_tables": smp.mrz_meta,
        "coil_positions_m": plan.positions.tolist(), "coil_rotations": plan.rotations,
        "max_current_a": design.drive.max_current_a,
        # the finger magnet's cylinder (the localizer's exact magnet field; MOMENT is its moment)
        "magnet_radius_m": design.magnet.radius_m, "magnet_length_m": design.magnet.length_m,
        "total_current_a": design.drive.total_current_a,
        # the drive record firmware_io.runner.config_from_map reads (firmware_io.mapfile.drive)
        "drive": drive_data(design, _drive_coils(arr)).to_dict(),
        "physics": phys.source,
        "settings": s.meta(len(plan.fit_pts)),
    }


def _rel(got, ref) -> float:
    """max |got - ref| / max |ref|."""
    return float(np.abs(got - ref).max() / max(np.abs(ref).max(), 1e-300))


def _errors(reader: mf.MapFile, plan: _Plan, smp: _Samples, row_max: np.ndarray) -> dict:
    """The finished map against the coupled model: meta 'errors' (relative to each row's
    largest |A| at the check points, resp. at the fit nodes)."""
    scale = np.maximum(np.abs(smp.a_check).max(axis=(0, 2)), 1e-300)
    err = np.abs(reader.actuation(plan.check) - smp.a_check) / scale[None, :, None]
    fit_err = np.abs(reader.actuation(plan.fit_pts, True) - smp.a_fit) / row_max[None, :, None]
    check = plan.check[:plan.n_mcheck]
    return {
        "n_points": len(plan.check),
        "actuation_max_rel_per_row": dict(zip(ROWS, err.max(axis=(0, 2)).tolist())),
        "actuation_rms_rel": float(np.sqrt((err ** 2).mean())),
        "n_fit_points": len(plan.fit_pts),
        "actuation_fit_nodes_max_rel": float(fit_err.max()),
        "n_magnet_points": plan.n_mcheck,
        "n_bias_force_points": len(smp.f0_check),
        "bias_force_max_rel": _rel(reader.bias_force(check[:len(smp.f0_check)]),
                                   smp.f0_check),
        "sensor_induced_max_rel": _rel(reader.sensor_induced_field(check), smp.sind_check)}


def _drive_coils(arr: CoilArray) -> list:
    """One coil model per channel for the drive data: R and L do not depend on the pose, so
    each coil type's prototype stands for its coils (one inductance solve per type)."""
    out = [None] * arr.n_coils
    for proto, idx in arr.coil_types().items():
        for k in idx:
            out[k] = proto
    return out
