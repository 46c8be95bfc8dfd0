"""``designkit run --simulate`` end to end: map, scene, simulated device, runner, results.

Builds (or loads) the force-current map of a design, compiles the virtual object into a scene
(or loads a compiled one), closes firmware_io's runner (the code that runs on the controller)
around the simulated device and writes run.csv (one row per control step, SI), summary.json,
run.png and loop_timing.png. Every input is checked before anything is computed.

The force constant lambda (thesis eq. 4.3): given (``lam_n_per_m``), the compiled scene's, or
the design's ``render.stiffness_n_per_m`` capped at what the device renders over the object
(:func:`designkit.render.force_constant` on the map, with the runner's current bounds and drive
mode): a stiffer object than the coils can push asks for currents beyond the limit everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from firmware_io.allocation import Allocator
from firmware_io.localization import SensorModel, estimator_from_map
from firmware_io.mapfile import MapFile
from firmware_io.mapfile.drive import DriveRecord
from firmware_io.runner import Runner, RunnerIO, SceneForce, SensorHeadroom, config_from_map
from firmware_io.scene import Scene

from .. import fieldmap, render
from ..design import Design, load_design
from ..errors import BadInputError
from ..model import electrical
from ..model.array import CoilArray
from ..model.coil import Coil
from ..render import scenefile  # called through the module: tests substitute its functions
from ..render.laws import ConstraintLaw
from ..support.atomic import write_json_atomic
from .device import SimulatedDevice
from .faults import FaultSchedule
from .loop import LoopTiming, simulate
from .plot import plot_run
from .report import force_error_causes, saturation_summary, summarize, write_run_csv
from .trajectory import Trajectory, poke_trajectory, slide_trajectory, tilt_trajectory

MAX_DURATION_S = 600.0
"""Longest simulated run, s."""

SCRIPTED_DURATION_S = {"slide": 4.0, "poke": 3.0, "tilt": 4.0}
"""Length of the scripted trajectories at their own speed, s."""

BOX_MARGIN_M = 0.002
"""A scripted trajectory keeps this far inside the map's box at its top, m."""


def drive_data(design) -> DriveRecord:
    """:func:`designkit.model.electrical.drive_data` for the design's own coils."""
    return electrical.drive_data(design, [Coil.of_design(design, k)
                                         for k in range(design.n_coils)])


@dataclass(frozen=True)
class RunSettings:
    """What a simulated run renders, and how (SI; the ``designkit run --simulate`` options).

    Attributes
    ----------
    obj : str or None -- the virtual object ('plane', 'hemisphere', 'half-cylinder', 'wedge') or
        a mesh (None: the hemisphere, or the objects of ``scene_path``)
    trajectory : str -- 'slide', 'poke', 'tilt' or a CSV file (:mod:`.trajectory`)
    duration_s : float or None -- simulated time, s (None: the trajectory's own)
    faults : str -- 'none', 'default' or 'TYPE@SECONDS,...' (:mod:`.faults`)
    method : str -- the localization method
    period_s : float -- the control period, s
    unipolar : bool -- the thesis' drive (0 <= I)
    lam_n_per_m : float or None -- the force constant, N/m (None: the design's
        ``render.stiffness_n_per_m`` capped at what the device renders over the object,
        :func:`choose_lambda`; not with ``scene_path``, which carries its own)
    rows : {'force', 'fz'} -- the object's 3-D force, or only its vertical component (the
        thesis' eq. 4.6)
    seed : int -- the sensor noise's
    calibrate : bool -- the start-up sensor calibration (:meth:`SimulatedDevice.
        calibrate_sensors`); the estimator then weighs the sensors as calibrated
        (:meth:`firmware_io.localization.EstimatorSettings.relative_error_for`)
    profile : bool -- the runner times each stage of its step (summary
        ``loop_by_kind['stages']``; compute time measured, not modelled)
    skip_force_n : float -- the runner's coil-skip force, N
    keep_sensors : tuple of int -- sensors the scene keeps in their linear range
        (:class:`firmware_io.runner.SensorHeadroom`; default none)
    background_t : (3,) T -- a uniform ambient field (array frame) that appears after the
        start-up calibration (which would take a constant one as the sensors' offsets): the
        estimator must find it
    scene_path : str or None -- a compiled scene (``designkit scene compile``) to run instead
        of ``obj``: its objects and its lambda
    """

    obj: str | None = None
    trajectory: str = "slide"
    duration_s: float | None = None
    faults: str = "none"
    method: str = "model"
    period_s: float = 1e-3
    unipolar: bool = False
    lam_n_per_m: float | None = None
    rows: str = "force"
    seed: int = 0
    calibrate: bool = True
    profile: bool = False
    skip_force_n: float = 0.0
    keep_sensors: tuple = ()
    background_t: tuple = (0.0, 0.0, 0.0)
    scene_path: str | None = None


MAX_BACKGROUND_T = 10e-3
"""Largest ambient field a simulated run takes, T per axis (beyond, sensors saturate)."""


def run_simulation(settings: RunSettings = RunSettings(), *, design=None, map_path=None,
                   out=Path("run-out"), progress: bool = True, array=None,
                   plant=None) -> dict:
    """Build (or load) the map, compile the scene (or load ``settings.scene_path``), close the
    runner around the simulated device, and write run.csv, summary.json, run.png and
    loop_timing.png into ``out``. Returns the summary. Every input is checked before anything
    is computed.

    ``settings``: :class:`RunSettings`. ``array``: the design's CoilArray when the caller has
    one (its coupled solve is reused). ``plant``: the device that was built (a design with
    ``[asbuilt]``, or its path): the simulated device is it, while the runner uses the map of
    ``design``.
    """
    st = settings
    design = design if isinstance(design, Design) else load_design(design)
    if st.scene_path is not None:
        for name, value in (("--object", st.obj), ("--lambda", st.lam_n_per_m)):
            if value is not None:
                raise BadInputError(name, "left out with --scene (the compiled scene has its "
                                    "objects and lambda)", value)
    obj = "hemisphere" if st.obj is None and st.scene_path is None else st.obj
    virtual, path, duration, schedule = _checked_inputs(st, obj, design)
    # the scene is read and matched to the design before the map is built
    scene = (None if st.scene_path is None else
             Scene.load(st.scene_path, expected_design_sha256=design.spec_hash()))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    array = array if array is not None else CoilArray.from_design(design)
    map_path, fmap = map_of_design(design, array, map_path, out, progress)
    # the runner's configuration from the map's drive record, as on the controller
    cfg = config_from_map(fmap, control_period_s=st.period_s, unipolar=st.unipolar,
                          force_axes="z" if st.rows == "fz" else "xyz",
                          skip_force_n=st.skip_force_n)
    drive = cfg.drive     # its rating violations are simulated and listed, not refused
    if scene is not None:
        virtual = SceneSurface(scene)
        choice = {"lambda_n_per_m": scene.lam_n_per_m, "lambda_source": f"scene {st.scene_path}"}
        obj = ", ".join(str(o.kind) for o in scene.objects)
    else:
        choice = choose_lambda(design, virtual, fmap, drive, st, progress=progress)
        meta = {"object": obj, "rows": st.rows}
        if st.keep_sensors:
            meta["keep_sensors"] = [int(k) for k in st.keep_sensors]
        scene_file = scenefile.compile_scene(virtual, out / "scene.npz",
                                             lam_n_per_m=choice["lambda_n_per_m"],
                                             law=ConstraintLaw(choice["lambda_n_per_m"]),
                                             map_design_sha256=fmap.design_sha256,
                                             extra_meta=meta)
        scene = Scene.load(scene_file, expected_design_sha256=fmap.design_sha256)
    lam = choice["lambda_n_per_m"]
    if path is None:
        path = _scripted_path(design, array, virtual, st.trajectory, fmap.bounds)
    plant_design, plant_array = design, array
    if plant is not None:  # the as-built device under the runner of ``design``'s map
        plant_design = plant if isinstance(plant, Design) else load_design(plant)
        plant_array = CoilArray.from_design(plant_design)
    device = SimulatedDevice(plant_design, plant_array, seed=st.seed, drive=drive)
    loc_kw = _localizer_options(device, map_path, st.method, st.calibrate)
    device.ambient_t = np.asarray(st.background_t, float)     # after the calibration

    def factory(source, clock, hook):
        estimator = estimator_from_map(map_path, st.method, **loc_kw)
        io = RunnerIO(device.coils, source, lambda line: print(line) if progress else None,
                      clock)
        runner = Runner(fmap, SceneForce(scene), estimator, io, cfg,
                        allocate=hook(Allocator()),
                        headroom=SensorHeadroom.from_meta(scene.meta))
        runner.profile = st.profile
        runner.start()
        return runner

    timing = LoopTiming(st.period_s, "measured" if st.profile else "modelled")
    res = simulate(device, factory, path, duration_s=duration, timing=timing,
                   faults=schedule, scene_force=SceneForce(scene).force, progress=progress)
    summary = summarize(res, force_error_causes(device, fmap, res))
    sat = saturation_summary(device, fmap, res, drive.current_limit_a)
    if sat:
        summary["saturation"] = sat
    summary.update({"object": obj, "trajectory": str(st.trajectory), "design": design.name,
                    "rows": st.rows, **choice, "method": st.method,
                    "unipolar": st.unipolar, "keep_sensors": list(st.keep_sensors),
                    "background_t": [float(x) for x in st.background_t],
                    "drive": drive.to_dict(), "drive_violations": drive.violations(),
                    **_duration_note(path.duration_s, duration),
                    "faults_not_injected": _not_injected(schedule, res.faults)})
    if plant is not None:
        summary["plant"] = plant_design.name
    write_run_csv(out / "run.csv", res.columns)
    write_json_atomic(out / "summary.json", summary)
    plot_run(res, out, surface_height=lambda x, y: virtual.height(np.c_[x, y, np.zeros_like(x)]),
             title=f"{obj}: {st.trajectory}, lambda = {lam:.3g} N/m")
    return summary


class SceneSurface:
    """The top surface h(x, y) of a compiled scene's objects (the highest where they overlap),
    for the scripted trajectories and the run figure."""

    def __init__(self, scene: Scene):
        self.objects = list(scene.objects)

    def height(self, points) -> np.ndarray:
        """h(x, y) of the points (n, 3), m, shape (n,)."""
        return np.max([o.height(points) for o in self.objects], axis=0)


def choose_lambda(design: Design, virtual, fmap, drive: DriveRecord, st: RunSettings, *,
                  progress: bool) -> dict:
    """The run's force constant and where it comes from (summary keys): ``st.lam_n_per_m`` when
    given; else ``render.stiffness_n_per_m`` capped at the largest lambda the device renders
    over the object's surface points where it renders any (thesis eq. 4.3 on the map, the
    runner's per-coil and total current bounds; ``lambda_unrenderable_points``: surface points
    where no lambda > 0 is renderable, the cores' pull there exceeding what the coils can
    cancel: no object force is rendered there whatever lambda)."""
    if st.lam_n_per_m is not None:
        return {"lambda_n_per_m": float(st.lam_n_per_m), "lambda_source": "--lambda"}
    fc = render.force_constant(virtual, fmap, current_limit_a=drive.current_limit_a,
                               total_current_a=drive.total_current_a, unipolar=st.unipolar,
                               rows=st.rows, progress=progress)
    renderable = fc.lam_where_renderable()
    asked = design.render.stiffness_n_per_m
    lam = min(asked, renderable)
    return {"lambda_n_per_m": lam,
            "lambda_source": ("render.stiffness_n_per_m" if lam == asked else
                              "the device's force constant (eq. 4.3), below "
                              "render.stiffness_n_per_m"),
            "lambda_design_n_per_m": asked, "lambda_renderable_n_per_m": renderable,
            "lambda_limiting_point_m": fc.limiting_point_where_renderable().tolist(),
            "lambda_unrenderable_points": fc.unrenderable_points,
            "lambda_surface_points": int(len(fc.points_m))}


def _checked_inputs(st: RunSettings, obj: str | None, design: Design):
    """The run's inputs, checked: (virtual object (None with a scene file), trajectory from a
    file -- inside the design's workspace -- or None for a scripted one, duration s, fault
    schedule)."""
    if st.rows not in ("force", "fz"):
        raise BadInputError("--rows", "'force' (3-D) or 'fz' (the thesis' vertical force)",
                            st.rows)
    if not 1e-4 <= st.period_s <= 0.05:
        raise BadInputError("--period-ms", "in [0.1, 50] ms", st.period_s * 1e3)
    if st.lam_n_per_m is not None and not 0 <= float(st.lam_n_per_m) < np.inf:
        raise BadInputError("--lambda", ">= 0 and finite, N/m", st.lam_n_per_m)
    bg = np.asarray(st.background_t, dtype=float)
    if bg.shape != (3,) or not np.all(np.abs(bg) <= MAX_BACKGROUND_T):
        raise BadInputError("--background-mt", f"three values within +-{MAX_BACKGROUND_T * 1e3:g} "
                            "mT (x, y, z, the array frame)", np.round(bg * 1e3, 3).tolist())
    if any(not (isinstance(k, (int, np.integer)) and k >= 0) for k in st.keep_sensors):
        raise BadInputError("--keep-sensors", "sensor indices >= 0 (the map's order)",
                            list(st.keep_sensors))
    virtual = None if obj is None else scenefile.make_object(obj)
    scripted = st.trajectory in SCRIPTED_DURATION_S
    path = None if scripted else Trajectory.from_csv(st.trajectory, design.workspace_region())
    duration = float(st.duration_s or (path.duration_s if path is not None
                                        else SCRIPTED_DURATION_S[st.trajectory]))
    if not 0 < duration <= MAX_DURATION_S:
        raise BadInputError("--duration", f"in (0, {MAX_DURATION_S:g}] s", duration)
    return virtual, path, duration, FaultSchedule.parse(st.faults, duration)


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


def _scripted_path(design, array, virtual, trajectory: str, bounds) -> Trajectory:
    """``slide``, ``poke`` or ``tilt`` over the virtual object at its own speed, inside the map's
    box (``bounds``: lower, upper corners, m) and above the sensor boards below it."""
    # the magnet cannot go below a sensor board under the box: its centre stays half its
    # length and 1 mm (the board and the sensor package) above the highest such sensor
    lo, hi = (np.asarray(b, float) for b in bounds)
    sensors, _ = array.sensor_poses()
    below = sensors[:, 2][sensors[:, 2] <= lo[2]]
    floor = max(lo[2], (float(below.max()) if below.size else -np.inf)
                + design.magnet.length_m / 2 + 1e-3)
    make = {"slide": slide_trajectory, "poke": poke_trajectory,
            "tilt": tilt_trajectory}[trajectory]
    return make(lambda x, y: virtual.height(np.c_[x, y, np.zeros_like(x)]),
                duration_s=SCRIPTED_DURATION_S[trajectory],
                z_limits_m=(floor, hi[2] - BOX_MARGIN_M))


def map_of_design(design, array, map_path, out: Path, progress: bool):
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
