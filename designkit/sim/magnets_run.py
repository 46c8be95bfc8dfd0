"""``designkit run --simulate --trajectory pinch``: two fingers squeeze a block, end to end.

The map of the design (built, or given), the block compiled into a scene with the god-object
law (:class:`designkit.render.laws.PenetrationLaw`: each finger its own contact, the side it
presses), the simulated device with every magnet (:class:`designkit.sim.magnets.
MagnetsDevice`: the coupled model as the truth), firmware_io's
:class:`~firmware_io.runner.MagnetsRunner` closed around it, run twice: with the magnets' pull
on each other compensated (the runner's default) and without (the comparison). Writes run.csv,
summary.json (``magnets``: one entry per magnet) and run_<name>.png per magnet, and the
uncompensated run's into ``no-pair-compensation/``.

The N-magnet estimator is the one extension point (``estimator``): a callable
``estimator(map_path, design, calibration) -> estimator`` with the interface of
``firmware_io.localization.MagnetsEstimator`` (docs/runner.md, "Several magnets"); by default
that estimator itself (:func:`magnets_estimator`).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from firmware_io.allocation import Allocator
from firmware_io.localization import MagnetsEstimator, SensorModel
from firmware_io.runner import MagnetsRunner, MagnetsSettings, RunnerIO, SceneForce, \
    config_from_map
from firmware_io.scene import Scene

from ..design import Design, load_design
from ..errors import BadInputError
from ..model.array import CoilArray
from ..render import scenefile
from ..render.laws import PenetrationLaw
from ..support.atomic import write_json_atomic
from .loop import LoopTiming
from .magnets import MagnetsDevice
from .magnets_loop import magnets_summary, plot_magnets, simulate_magnets, write_magnets_csv
from .pinch import Pinch, pinch_trajectory
from .run import RunSettings, map_of_design

PINCH_STIFFNESS_N_PER_M = 60.0
"""The block's stiffness, N/m: 3 mm into it, 0.18 N per finger (the god-object law; its
passivity bound at a 1 ms period is 2000 N/m, its position-noise bound is left out -- the
tracked estimate's noise, not one frame's, is what the finger feels)."""



def magnets_estimator(map_path, design, calibration) -> MagnetsEstimator:
    """The design's magnets' estimator from the map's sensor section, with the start-up
    calibration (the pinch's default)."""
    return MagnetsEstimator.from_map(map_path, design.magnets, calibration=calibration,
                                     names=[m.name for m in design.magnets],
                                     expected_design_sha256=design.spec_hash())


def run_pinch(settings: RunSettings, *, design=None, map_path=None, out=Path("run-out"),
              progress: bool = True, estimator: Callable = magnets_estimator,
              pinch: Pinch = Pinch()) -> dict:
    """The pinch (module docstring); returns the summary. Every input is checked before
    anything is computed: a design without exactly two magnets, a path leaving the map's box
    or magnets that overlap along it, faults, another object or Fz rows are refused in one
    line."""
    st = settings
    design = design if isinstance(design, Design) else load_design(design)
    _check(st, design)
    pinch_trajectory(pinch, design.magnets, _box(design))   # refused before anything is built
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    array = CoilArray.from_design(design)
    map_path, fmap = map_of_design(design, array, map_path, out, progress)
    path = pinch_trajectory(pinch, design.magnets, fmap.bounds)
    cfg = config_from_map(fmap, control_period_s=st.period_s, unipolar=st.unipolar,
                          force_axes="xyz")
    law = PenetrationLaw(stiffness_n_per_m=PINCH_STIFFNESS_N_PER_M, loop_period_s=st.period_s,
                         position_noise_m=0.0)
    scene = Scene.load(scenefile.compile_scene(
        pinch.block(), out / "scene.npz", lam_n_per_m=PINCH_STIFFNESS_N_PER_M, law=law,
        map_design_sha256=fmap.design_sha256, extra_meta={"object": "block"}),
        expected_design_sha256=fmap.design_sha256)
    device = MagnetsDevice(design, array, seed=st.seed, drive=cfg.drive)
    calibration = (device.calibrate_sensors(SensorModel.from_map(map_path)) if st.calibrate
                   else None)
    duration = pinch.duration_s if st.duration_s is None else st.duration_s
    runs = {}
    for compensate in (True, False):
        # the fingers' places at the start (the pinch's first point): which magnet is which
        magnets = MagnetsSettings.of_specs(design.magnets, compensate_pair=compensate,
                                           start_positions_m=path.positions_m[:, 0])

        def factory(source, clock, magnets=magnets):
            io = RunnerIO(device.coils, source, lambda line: print(line) if progress else None,
                          clock)
            runner = MagnetsRunner(fmap, SceneForce(scene), estimator(map_path, design,
                                                                      calibration),
                                   io, cfg, magnets, allocate=Allocator())
            runner.start()
            return runner

        device.current_a[:] = 0.0
        runs[compensate] = simulate_magnets(device, factory, path, duration_s=duration,
                                            timing=LoopTiming(st.period_s),
                                            scene_force=SceneForce(scene).force,
                                            progress=progress)
    summary = magnets_summary(runs[True])
    without = magnets_summary(runs[False])
    for entry, other in zip(summary["magnets"], without["magnets"]):
        entry["force_error_rms_without_pair_compensation_n"] = other["force_error_rms_n"]
    summary.update({"object": "block", "trajectory": "pinch", "design": design.name,
                    "stiffness_n_per_m": PINCH_STIFFNESS_N_PER_M, "duration_s": duration,
                    "pinch": {k: getattr(pinch, k) for k in pinch.__dataclass_fields__},
                    "drive": cfg.drive.to_dict(), "seed": st.seed})
    (out / "no-pair-compensation").mkdir(exist_ok=True)
    for folder, res in ((out, runs[True]), (out / "no-pair-compensation", runs[False])):
        write_magnets_csv(folder / "run.csv", res)
        plot_magnets(res, folder, file_names(res.names), title="pinch on a block")
    write_json_atomic(out / "no-pair-compensation" / "summary.json", without)
    write_json_atomic(out / "summary.json", summary)
    return summary


def file_names(names) -> list:
    """run_<name>.png for each magnet name (characters other than letters, digits, '-' and
    '_' replaced by '_')."""
    return [f"run_{re.sub(r'[^A-Za-z0-9_-]', '_', n)}.png" for n in names]


def _check(st: RunSettings, design) -> None:
    """The pinch's refusals that need no map (one line each)."""
    if len(design.magnets) != 2:
        raise BadInputError("--trajectory pinch", "a design with two [[magnets]] (one per "
                            "fingertip)", f"{len(design.magnets)} magnet(s) in {design.name}")
    for key, value, default in (("--faults", st.faults, "none"), ("--rows", st.rows, "force"),
                                ("--object", st.obj, None), ("--scene", st.scene_path, None),
                                ("--keep-sensors", st.keep_sensors, ())):
        if value != default:
            raise BadInputError(key, f"left at its default ({default!r}) with --trajectory "
                                "pinch (its object is the block, its rows the 3-D force)",
                                value)


def _box(design) -> tuple:
    """The design's workspace box ((3,), (3,)) m, as the map will cover it."""
    w = design.workspace_region()
    xy = np.asarray(w.outline_m, float)
    return (np.r_[xy.min(axis=0), w.z_min_m], np.r_[xy.max(axis=0), w.z_max_m])
