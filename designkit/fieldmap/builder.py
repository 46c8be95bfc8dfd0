"""Building the map of a design: :func:`build`, in named phases.

settings (validate every argument) -> plan (box, cell layers, fit lattices, table grids, check
points: :mod:`.plan`) -> samples (the coupled model at every node, the per-core tables, the
saturation; one progress bar) -> arrays (cell fits :mod:`.cells`, the bias force's residual
grid, the sensor constants) -> meta -> check (the finished map against the coupled model at
random points, recorded in ``meta['errors']``). Lengths in m, A in T/A and T/(m A), forces in
N. What the choices cost and how accurate the result is: docs/fieldmap.md.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import time
from dataclasses import dataclass, field

import numpy as np

from firmware_io import mapfile as mf

from .. import __version__
from ..errors import BadInputError
from ..model.array import ROWS, CoilArray
from ..model.electrical import drive_data
from ..support.blas import one_blas_thread
from ..support.parallel import quiet_pool
from ..support.progress import tqdm
from .cells import fit_layers
from .clearance import Clearance
from .physics import MapPhysics, map_physics
from .plan import box_axes, cell_layers, default_box, layer_nodes, lattice_nodes, table_specs
from .settings import BuildSettings
from .symmetry import Orbits, random_orbits, sampling_group
from .tables import (compute_magnet_table, coupled_modes, finite_size_correction,
                     mode_table_entry)

FORMAT, FORMAT_VERSION, UNITS = mf.FORMAT, mf.FORMAT_VERSION, mf.UNITS
CHUNK = 64
"""Magnet positions / check points per coupled-model call of the sampling phase."""
FIT_CHUNK = 512
"""Fit nodes per coupled-model call of the sampling phase."""
WORKERS = min(2, os.cpu_count() or 1)
"""Processes of the sampling phase after the coupled solve (docs/fieldmap.md, "Costs")."""
CHECK_SEED = 20261123
"""Seed of the random check points (the same points for every build of a box)."""
N_F0_CHECK = 16
"""Check points where the map's F0 is compared with the finite cylinder's (meta 'errors';
~15-30 ms each, the dipole's ~1 ms: the first of the magnet check points)."""


def build(design, settings: BuildSettings | None = None, *, box=None, progress: bool = True,
          array: CoilArray | None = None, region: dict | None = None, **changes) -> dict:
    """Compute the map v2 of ``design``: ``{"arrays": {...}, "meta": {...}}`` (not yet written).

    Parameters
    ----------
    settings : BuildSettings or None
        How densely the map samples (:class:`.settings.BuildSettings`; None: its defaults);
        ``changes``: fields of it to replace (``build(d, n_check=20)``), checked alike.
    box : (lower, upper) or None
        Corners, m; default :func:`~designkit.fieldmap.plan.default_box`.
    progress : bool
        One progress bar over the sampling.
    array : CoilArray or None
        The design's array when already built (its coupled solve is reused).
    region : dict or None
        What ``box`` was made for (a scene map: :mod:`.region`), stored as meta 'region'.
    """
    s = BuildSettings.with_changes(settings, changes)
    arr = array or CoilArray.from_design(design)
    phys = map_physics(design)
    s = s.resolved(tilted_pull(arr, phys.moment_a_m2))
    lower, upper = _box(design, box)
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


def tilted_pull(arr: CoilArray, moment) -> bool:
    """Whether some coupled core's axis is not along the magnet's ``moment`` (3,): its pull is
    then not axisymmetric about it, and the magnet tables hold only a part of it."""
    m = np.asarray(moment, float) / max(float(np.linalg.norm(moment)), 1e-300)
    return any(c.core is not None and abs(abs(float(c.pose.matrix[:, 2] @ m)) - 1.0) > 1e-9
               for c in arr.coils)


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
    z_top: float           # the sources' effective top (the box's floor less its clearance)
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
    array's symmetries (:func:`.symmetry.sampling_group`) pick the points sampled (the bias
    force's only those that keep the line of ``moment`` (3,) A m^2)."""
    types = list(arr.coil_types().items())
    m_specs = table_specs(arr, [idx for _, idx in types], lower, upper, s.magnet_rz_step,
                          s.magnet_rz_log_step, s.rz_rho_scale, 2)
    clear = Clearance(arr)
    z_top = float(lower[2]) - clear(lower, np.r_[upper[:2], lower[2]])
    layers = cell_layers(lower, upper, clear.slab(lower, upper), s.cell_ratio, s.layer_ratio,
                         s.degree)
    lattices = [layer_nodes(lay, s.fit_nodes) for lay in layers]
    fit_pts = np.concatenate([lattice_nodes(ax) for ax in lattices])
    # the residual grid's z steps grow with the distance from the sources, as the cells
    m_axes = box_axes(lower, upper, s.spacing, z_top, s.log_step)
    group = sampling_group(arr)
    check, check_orbits = random_orbits(lower, upper, s.n_check, group,
                                        np.random.default_rng(CHECK_SEED))
    m_nodes = lattice_nodes(m_axes)
    f_group = (sampling_group(arr, moment) if moment is not None
               else group.subgroup(lambda e, s: False))
    return _Plan(lower, upper, types, m_specs, z_top, layers, lattices, fit_pts, m_axes,
                 m_nodes, check, min(s.n_check, max(10, s.n_check // 8)), arr.positions(),
                 [list(map(list, c.pose.rotation)) for c in arr.coils],
                 Orbits.of(fit_pts, group), Orbits.of(m_nodes, f_group), check_orbits)


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
    sensor_coef: np.ndarray | None = None  # coupled_modes' sensor_coef (None: no cores)
    sensor_rows: np.ndarray | None = None  # (n_sensors, 8, nc) the coils' rows at the sensors
    f0_check: np.ndarray | None = None
    sind_check: np.ndarray | None = None
    sat_i: np.ndarray | None = None
    sat_f: np.ndarray | None = None
    seconds: dict = field(default_factory=dict)
    cpu_seconds: dict = field(default_factory=dict)  # process CPU time (all threads)


def _steps(plan: _Plan, n_check: int) -> list:
    """The sampling phase's steps (kind, index), in order: one progress-bar tick each. After the
    coupled solve the single long steps go first and the chunks last, so that the workers
    finish together (longest first: no long step is left to run alone at the end)."""
    return ([("coupled solve", 0)]
            + [("magnet tables", k) for k in range(len(plan.types))]
            + [("magnet check", 0), ("mode tables", 0), ("saturation", 0), ("sensor rows", 0)]
            + [("cell nodes", s) for s in range(0, len(plan.fit_orbits.reps), FIT_CHUNK)]
            + [("magnet", s) for s in range(0, len(plan.m_orbits.reps), CHUNK)]
            + [("check", s) for s in range(0, len(plan.check_orbits.reps), CHUNK)])


def _sample(phys: MapPhysics, arr: CoilArray, plan: _Plan, s: BuildSettings,
            progress: bool) -> _Samples:
    """Every evaluation of the coupled model the map needs, under one progress bar: the
    coupled solve first, then the other steps, on :data:`WORKERS` forked processes where the
    platform forks (they inherit the solved system; threads cannot share the single-threaded
    LAPACK calls of the BLAS numpy ships, which then return wrong solves: docs/fieldmap.md).
    Per stage: the summed wall seconds of its steps and their CPU seconds, in whichever
    process ran them."""
    nc = arr.n_coils
    # a_fit, a_check and f0 hold the orbits' representatives until the loop is done
    smp = _Samples(np.empty((len(plan.fit_orbits.reps), 8, nc)),
                   np.empty((len(plan.check_orbits.reps), 8, nc)),
                   np.empty((len(plan.m_orbits.reps), 3)))
    smp.mrz_meta = [None] * len(plan.types)
    steps = _steps(plan, s.n_check)
    bar = tqdm(total=len(steps), desc="map", unit="step", disable=not progress, leave=False)
    _CONTEXT.update(phys=phys, arr=arr, plan=plan, settings=s)
    try:
        for kind, k, value, wall, cpu in _run_steps(steps):
            _store(smp, kind, k, value)
            smp.seconds[kind] = smp.seconds.get(kind, 0.0) + wall
            smp.cpu_seconds[kind] = smp.cpu_seconds.get(kind, 0.0) + cpu
            bar.set_postfix_str(kind, refresh=False)
            bar.update()
    finally:
        _CONTEXT.clear()
        bar.close()
    smp.a_fit = plan.fit_orbits.expand_actuation(smp.a_fit)
    smp.a_check = plan.check_orbits.expand_actuation(smp.a_check)
    smp.f0 = plan.m_orbits.expand_force(smp.f0)
    return smp


_CONTEXT: dict = {}
"""What the sampling steps read (the physics, the array with its solved system, the plan, the
settings): set by :func:`_sample` before the workers fork, so they
inherit it."""


def _forks() -> bool:
    """Whether the sampling may fork :data:`WORKERS` processes: more than one worker, the
    platform forks, and this process is not itself a pool's daemon worker."""
    return (WORKERS > 1 and "fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon)


BEFORE_SOLVE = ("magnet tables",)
"""Steps that do not read the array's coupled solve (each core type alone in its own frame):
they run on a worker forked before the solve, beside it."""


def _run_steps(steps: list):
    """(kind, k, value, wall s, CPU s) of every step: the coupled solve here, the steps of
    :data:`BEFORE_SOLVE` on a worker forked before it, the others on workers forked after it
    (in completion order); without forking, here, one after the other."""
    if not _forks():
        for st in steps:
            yield _timed_step(st)
        return
    early = [st for st in steps[1:] if st[0] in BEFORE_SOLVE]
    late = [st for st in steps[1:] if st[0] not in BEFORE_SOLVE]
    # the workers ignore Ctrl-C, which the parent answers by terminating them
    with quiet_pool(1, "fork") as first:
        try:
            beside = first.map_async(_timed_step, early)
            yield _timed_step(steps[0])  # the coupled solve: the late steps need it
            # forked after the solve: these workers inherit it
            with quiet_pool(WORKERS, "fork") as pool:
                try:
                    yield from pool.imap_unordered(_timed_step, late)
                except BaseException:
                    pool.terminate()
                    raise
            yield from beside.get()
        except BaseException:
            first.terminate()
            raise


def _timed_step(step):
    kind, k = step
    t0, c0 = time.perf_counter(), time.process_time()
    with one_blas_thread():
        value = _step(kind, k, _CONTEXT)
    return kind, k, value, time.perf_counter() - t0, time.process_time() - c0


def _step(kind: str, k: int, ctx: dict):
    """The value of one step of :func:`_steps` (:func:`_store` puts it into the samples)."""
    phys, arr, plan, s = ctx["phys"], ctx["arr"], ctx["plan"], ctx["settings"]
    if kind == "coupled solve":
        arr.actuation_matrix(plan.fit_pts[:1])  # the coupled solve, once
        return None
    if kind == "cell nodes":
        return phys.actuation(arr, plan.fit_pts[plan.fit_orbits.reps[k:k + FIT_CHUNK]])
    if kind == "magnet tables":
        proto, idx = plan.types[k]
        spec = plan.m_specs[k]
        # each core alone in its own frame, the moment along its axis: the part of its pull
        # the (rho, z) table can hold (tilted_pull: the residual grid carries the rest). The
        # point dipole's table carries the grid's residual; the stored one adds what the
        # magnet's finite size changes in each core's own pull (docs/fieldmap.md)
        axial = dataclasses.replace(phys, moment_a_m2=np.array(
            [0.0, 0.0, float(np.linalg.norm(phys.moment_a_m2))]))
        dipole = compute_magnet_table(axial, proto, spec).astype(np.float32)
        stored = (dipole + finite_size_correction(axial, proto, spec)).astype(np.float32)
        return dipole, stored, {"name": f"MRZ{k}", "coils": [int(c) for c in idx], **spec}
    if kind == "mode tables":  # the sensor field's adjoint modes and their tables
        modes = coupled_modes(arr, s.sensor_mode_tolerance)
        out = []
        for j, t in enumerate(modes["types"] if modes else []):
            spec = table_specs(arr, [t["coils"]], plan.lower, plan.upper, s.sensor_mode_rz_step,
                               s.sensor_mode_rz_log_step, s.rz_rho_scale, 1)[0]
            out.append(mode_table_entry(t, spec, j))
        return (None if modes is None else modes["sensor_coef"]), out
    if kind == "sensor rows":
        return phys.sensor_coil_rows(arr)
    if kind == "magnet":
        return phys.bias_force(arr, plan.m_nodes[plan.m_orbits.reps[k:k + CHUNK]])
    if kind == "check":
        return phys.actuation(arr, plan.check[plan.check_orbits.reps[k:k + CHUNK]])
    if kind == "magnet check":
        # the truth: the finite cylinder (~20 x a dipole's cost: the first few points)
        return (phys.bias_force_finite(arr, plan.check[:min(plan.n_mcheck, N_F0_CHECK)]),
                phys.sensor_induced(arr, plan.check[:plan.n_mcheck]))
    return phys.saturation(arr)


def _store(smp: _Samples, kind: str, k: int, value) -> None:
    """Put the value of step (kind, k) into ``smp``."""
    if kind == "coupled solve":
        pass
    elif kind == "sensor rows":
        smp.sensor_rows = value
    elif kind == "cell nodes":
        smp.a_fit[k:k + FIT_CHUNK] = value
    elif kind == "magnet tables":
        smp.mrz_dipole[f"MRZ{k}"], smp.tables[f"MRZ{k}"], smp.mrz_meta[k] = value
    elif kind == "mode tables":
        smp.sensor_coef, tables = value
        for j, (tab, entry) in enumerate(tables):
            smp.tables[f"SM{j}"] = tab
            smp.sm_meta.append(entry)
    elif kind == "magnet":
        smp.f0[k:k + CHUNK] = value
    elif kind == "check":
        smp.a_check[k:k + CHUNK] = value
    elif kind == "magnet check":
        smp.f0_check, smp.sind_check = value
    else:
        smp.sat_i, smp.sat_f = value


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
    sensor_rows = smp.sensor_rows  # (n_sensors, 8, nc)
    n_s = len(sensor_rows)
    arrays.update({
        "SCOEF": smp.sensor_coef if smp.sensor_coef is not None else np.zeros((nc, 0, n_s, 3)),
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
        "sensor_induced_max_rel": _rel(reader.sensor_induced_field(check).reshape(
            smp.sind_check.shape), smp.sind_check)}


def _drive_coils(arr: CoilArray) -> list:
    """One coil model per channel for the drive data: R and L do not depend on the pose, so
    each coil type's prototype stands for its coils (one inductance solve per type)."""
    out = [None] * arr.n_coils
    for proto, idx in arr.coil_types().items():
        for k in idx:
            out[k] = proto
    return out
