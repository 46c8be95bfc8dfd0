"""``designkit run --simulate`` end to end: map, scene, simulated device, runner, results.

Builds (or loads) the force-current map of a design, compiles the virtual object into a scene,
closes firmware_io's runner (the code that runs on the controller) around the simulated device
and writes run.csv (one row per control step, SI), summary.json, run.png and loop_timing.png.
Every input is checked before anything is computed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from firmware_io.allocation import Allocator
from firmware_io.localization import RUNNER_SETTINGS, SensorModel, estimator_from_map
from firmware_io.mapfile import MapFile
from firmware_io.runner import ConstantVelocityTracker, Runner, RunnerConfig, SceneForce
from firmware_io.scene import Scene

from .. import electrical, fieldmap
from .._io import write_json_atomic
from ..array import CoilArray
from ..coil import Coil
from ..design import Design, load_design
from ..errors import BadInputError
from ..render.laws import ConstraintLaw
from ..render import scenefile  # called through the module: tests substitute its functions
from .device import SimulatedDevice
from .faults import FaultSchedule
from .loop import simulate
from .plot import plot_run
from .report import force_error_causes, summarize, write_run_csv
from .trajectory import Trajectory, poke_trajectory, slide_trajectory

MAX_DURATION_S = 600.0
"""Longest simulated run, s."""

SCRIPTED_DURATION_S = {"slide": 4.0, "poke": 3.0}
"""Length of the scripted trajectories at their own speed, s."""

TOP_OF_BOX_M = 0.078
"""Highest finger position of a scripted trajectory, m (inside the map box)."""


def drive_data(design) -> dict:
    """:func:`designkit.electrical.drive_data` for the design's own (identical) coils."""
    return electrical.drive_data(design, [Coil.from_design(design)]
                                 * (design.array.rows * design.array.columns))


def run_simulation(*, design=None, obj: str = "hemisphere", trajectory: str = "slide",
                   duration_s: float | None = None, faults: str = "none", map_path=None,
                   method: str = "model", period_s: float = 1e-3, unipolar: bool = False,
                   lam_n_per_m: float | None = None, rows: str = "force", seed: int = 0,
                   out=Path("run-out"), progress: bool = True, array=None,
                   calibrate: bool = True, profile: bool = False,
                   skip_force_n: float = 0.0, plant=None) -> dict:
    """Build (or load) the map, compile the scene, close the runner around the simulated device,
    and write run.csv, summary.json, run.png and loop_timing.png into ``out``. Returns the
    summary. Every input is checked before anything is computed.

    ``rows``: 'force' renders the object's 3-D force, 'fz' only its vertical component (the
    thesis' eq. 4.6; the runner then evaluates only the two rows of A(p) Fz needs). ``array``:
    the design's CoilArray when the caller has one (its coupled solve is reused).
    ``calibrate``: the start-up sensor calibration (:meth:`SimulatedDevice.calibrate_sensors`)
    before the run; the localizer then weighs the sensors as calibrated
    (:class:`firmware_io.localization.EstimatorSettings`). ``profile``: the runner times each
    stage of its step (summary ``loop_by_kind['stages']``). ``skip_force_n``: the runner's coil-skip force, N.
    ``plant``: the device that was built (a design with ``[asbuilt]``, or its path): the
    simulated device is it, while the runner uses the map of ``design``.
    """
    design = design if isinstance(design, Design) else load_design(design)
    virtual, path, duration, schedule = _checked_inputs(obj, trajectory, duration_s, faults,
                                                        rows, period_s, lam_n_per_m)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    array = array if array is not None else CoilArray.from_design(design)
    if path is None:
        path = _scripted_path(design, array, virtual, trajectory)
    map_path, fmap = _map(design, array, map_path, out, progress)
    lam = design.render.stiffness_n_per_m if lam_n_per_m is None else float(lam_n_per_m)
    scene_path = scenefile.compile_scene(virtual, out / "scene.npz", lam_n_per_m=lam,
                                         law=ConstraintLaw(lam),
                                         map_design_sha256=fmap.design_sha256,
                                         extra_meta={"object": obj, "rows": rows})
    scene = Scene.load(scene_path, expected_design_sha256=fmap.design_sha256)
    drive = drive_data(design)
    plant_design, plant_array = design, array
    if plant is not None:  # the as-built device under the runner of ``design``'s map
        plant_design = plant if isinstance(plant, Design) else load_design(plant)
        plant_array = CoilArray.from_design(plant_design)
    device = SimulatedDevice(plant_design, plant_array, seed=seed,
                             resistance_ohm=drive["resistance_ohm"][0],
                             inductance_h=drive["inductance_h"][0])
    loc_kw = _localizer_options(device, map_path, method, calibrate)

    def factory(source, clock, hook):
        cfg = RunnerConfig(**{k: tuple(v) if isinstance(v, list) else v
                              for k, v in drive.items()},
                           control_period_s=period_s, unipolar=unipolar,
                           force_axes="z" if rows == "fz" else "xyz",
                           skip_force_n=skip_force_n)
        localizer = estimator_from_map(map_path, method, RUNNER_SETTINGS, **loc_kw)
        runner = Runner(fmap, SceneForce(scene), localizer, ConstantVelocityTracker(),
                        hook(Allocator()), device.coils, source, cfg, clock=clock,
                        log=lambda line: print(line) if progress else None)
        runner.profile = profile
        runner.start()
        return runner

    res = simulate(device, factory, path, duration_s=duration, period_s=period_s,
                   faults=schedule, scene_force=SceneForce(scene).force, progress=progress)
    summary = summarize(res, force_error_causes(device, fmap, res))
    summary.update({"object": obj, "trajectory": str(trajectory), "design": design.name,
                    "rows": rows,
                    "lambda_n_per_m": lam, "method": method, "unipolar": unipolar,
                    "drive": drive, **_duration_note(path.duration_s, duration),
                    "faults_not_injected": _not_injected(schedule, res.faults)})
    if plant is not None:
        summary["plant"] = plant_design.name
    write_run_csv(out / "run.csv", res.columns)
    write_json_atomic(out / "summary.json", summary)
    plot_run(res, out, surface_height=lambda x, y: virtual.height(np.c_[x, y, np.zeros_like(x)]),
             title=f"{obj}: {trajectory}, lambda = {lam:g} N/m")
    return summary


def _checked_inputs(obj, trajectory, duration_s, faults, rows, period_s, lam_n_per_m=None):
    """The run's inputs, checked: (virtual object, trajectory from a file or None for a scripted
    one, duration s, fault schedule)."""
    if rows not in ("force", "fz"):
        raise BadInputError("--rows", "'force' (3-D) or 'fz' (the thesis' vertical force)", rows)
    if not 1e-4 <= period_s <= 0.05:
        raise BadInputError("--period-ms", "in [0.1, 50] ms", period_s * 1e3)
    if lam_n_per_m is not None and not 0 <= float(lam_n_per_m) < np.inf:
        raise BadInputError("--lambda", ">= 0 and finite, N/m", lam_n_per_m)
    virtual = scenefile.make_object(obj)
    scripted = trajectory in SCRIPTED_DURATION_S
    path = None if scripted else Trajectory.from_csv(trajectory)
    duration = float(duration_s or (path.duration_s if path is not None
                                     else SCRIPTED_DURATION_S[trajectory]))
    if not 0 < duration <= MAX_DURATION_S:
        raise BadInputError("--duration", f"in (0, {MAX_DURATION_S:g}] s", duration)
    return virtual, path, duration, FaultSchedule.parse(faults, duration)


def _duration_note(trajectory_s: float, duration_s: float) -> dict:
    """summary.json: how the simulated time relates to the trajectory's (which keeps its speed:
    a shorter run cuts it, a longer one holds the finger at its last point)."""
    how = ("whole" if abs(duration_s - trajectory_s) <= 1e-9 else
           "cut" if duration_s < trajectory_s else "held at the end")
    return {"duration_s": duration_s, "trajectory_duration_s": trajectory_s,
            "trajectory_played": how}


def _not_injected(schedule: FaultSchedule, injected) -> list:
    """Scheduled faults the run ended before injecting (a PWM NACK, an overrun or an over-limit
    command waits for a running step: designkit.sim.loop.RUNNING_FAULTS)."""
    left = list(injected)
    out = []
    for te, name in schedule.events:
        match = next((k for k, (_, n) in enumerate(left) if n == name), None)
        if match is None:
            out.append({"fault": name, "scheduled_s": float(te),
                        "why": "it waits for a running step; none came before the end"})
        else:
            left.pop(match)
    return out


def _scripted_path(design, array, virtual, trajectory: str) -> Trajectory:
    """``slide`` or ``poke`` over the virtual object at its own speed, kept above the upper
    sensor board."""
    # the magnet cannot go below the upper sensor board: its centre stays half its length
    # and 1 mm (the board and the sensor package) above the highest sensor
    floor = (float(np.max(array.sensor_positions_m()[0, :, 2]))
             + design.magnet.length_m / 2 + 1e-3)
    make = slide_trajectory if trajectory == "slide" else poke_trajectory
    return make(lambda x, y: virtual.height(np.c_[x, y, np.zeros_like(x)]),
                duration_s=SCRIPTED_DURATION_S[trajectory], z_limits_m=(floor, TOP_OF_BOX_M))


def _map(design, array, map_path, out: Path, progress: bool):
    """The map file (built into ``out`` when none is given) and its loaded MapFile, checked to
    be the design's."""
    if map_path is None:
        map_path = out / "map.npz"
        data = fieldmap.build(design, array=array, progress=progress)
        fieldmap.write(map_path, data)
    return map_path, MapFile.load(map_path, expected_design_sha256=design.spec_hash())


def _localizer_options(device: SimulatedDevice, map_path, method: str, calibrate: bool) -> dict:
    """The localizer's keywords: the start-up calibration (coils only; the map carries the
    magnet's cylinder), unless not calibrating."""
    loc_kw: dict = {}
    if calibrate and method != "learned":
        loc_kw.update(calibration=device.calibrate_sensors(SensorModel.from_map(map_path)))
    return loc_kw
