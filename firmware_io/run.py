"""Hardware entry point on the controller: ``python -m firmware_io.run --bus 1 --map F --scene F``.

Thin: parse, load the map and the scene (refusing a pair from different designs), open the bus
(or two: ``--sensor-bus``), build the drivers with the default wiring (firmware_io.hw.coils,
firmware_io.hw.sensors), put every coil in the safe state and run
:class:`firmware_io.runner.Runner` until Ctrl-C or ``--duration``. Sensors are read in a background thread at the rate the bus allows; the control loop predicts
between frames. Everything a user can get wrong is checked before any coil is energized.
Needs numpy and smbus2 only.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time

import numpy as np

from .allocation import Allocator
from .hw.bus import open_bus
from .hw.coils import CoilDriver
from .hw.pca9685 import PCA9685
from .errors import FirmwareIOError
from .localization import estimator_from_map
from .mapfile import MapFile
from .runner import (CALIBRATION_CURRENT_A, Runner, RunnerIO, SceneForce, SensorFrame,
                     SensorHeadroom, calibrate_sensors, calibration_currents, config_from_map,
                     record_calibration)
from .scene import Scene
from .hw.sensors import SensorArrays, default_sensor_layout

EXIT_BAD_INPUT = 2


SWITCH_INTERVAL_S = 1e-4
"""Python's GIL hand-over interval while the sensor thread runs, s: the control thread waits at
most about this long for the interpreter when it wakes up for a step while the sensor thread is
fitting (docs/runner.md, "Threads")."""


class ThreadedSensorSource:
    """Read the sensor arrays and run the fit continuously in a thread; hand the newest
    :class:`firmware_io.runner.Fix` to the loop once.

    The runner attaches its :class:`firmware_io.runner.SensorPipeline` (:meth:`attach`); until
    then (or without one) the thread hands over raw frames.
    """

    def __init__(self, arrays, clock=time.monotonic):
        self.arrays, self.clock = arrays, clock
        self._lock = threading.Lock()
        self._frame = None
        self._stop = threading.Event()
        self.error: BaseException | None = None
        self.pipeline = None
        self.thread = threading.Thread(target=self._loop, name="sensors", daemon=True)

    def attach(self, pipeline) -> None:
        self.pipeline = pipeline

    def start(self) -> None:
        sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL_S))
        self.thread.start()

    def stop(self) -> None:
        self._stop.set()
        self.thread.join(timeout=1.0)

    def _loop(self) -> None:
        previous = None
        while not self._stop.is_set():
            t0 = self.clock()
            # master-controlled TLV493D: a read returns the conversion the previous read
            # triggered, so a frame holds the field at the previous pass's start (the first
            # pass's is from the configuration: dropped)
            field_t, previous = previous, t0
            try:
                r = self.arrays.read()
            except Exception as exc:  # noqa: BLE001 - the loop must see it, not the thread die
                self.error = exc
                status = ("failed",) * len(self.arrays.sensors)
                frame = SensorFrame(np.full((len(status), 3), np.nan), status, t0)
            else:
                if field_t is None:
                    continue
                frame = SensorFrame(r.field_t, r.status, field_t)
            if self.pipeline is not None:
                try:
                    frame = self.pipeline.process(frame)
                except Exception as exc:  # noqa: BLE001 - a fit that raises: no estimate
                    self.error = exc
                    continue
            with self._lock:
                self._frame = frame

    def __call__(self, t_s: float):
        with self._lock:
            frame, self._frame = self._frame, None
        return frame


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m firmware_io.run",
                                description="Run the haptic rendering loop on the device.")
    p.add_argument("--bus", required=True, help="I2C bus number (/dev/i2c-N) of the PWM boards "
                   "(and of the sensors unless --sensor-bus is given)")
    p.add_argument("--sensor-bus", default=None, help="a second I2C bus for the sensor arrays")
    p.add_argument("--map", required=True, help="force-current map file (designkit map)")
    p.add_argument("--scene", required=True, help="compiled scene file (designkit scene compile)")
    p.add_argument("--method", default="model", help="localization method (default: model)")
    p.add_argument("--period-ms", type=float, default=1.0, help="control period, ms (default 1)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many s")
    p.add_argument("--unipolar", action="store_true", help="drive 0 <= I (the thesis' drive)")
    p.add_argument("--calibrate", action="store_true",
                   help="calibrate the sensors at start-up with the coils alone (~10 s; keep the "
                        "finger magnet away from the board until the loop starts)")
    return p


def _bus_number(text: str, what: str, dev_dir: str = "/dev") -> int:
    """The adapter number, checked to exist (``/dev/i2c-N``) before anything else is done."""
    try:
        n = int(text)
    except ValueError:
        raise FirmwareIOError(f"{what} must be an I2C bus number (N of /dev/i2c-N); instead "
                              f"received {text!r}") from None
    if n < 0:
        raise FirmwareIOError(f"{what} must be >= 0; instead received {n}")
    node = os.path.join(dev_dir, f"i2c-{n}")
    if not os.path.exists(node):
        have = sorted(f for f in os.listdir(dev_dir) if f.startswith("i2c-")) \
            if os.path.isdir(dev_dir) else []
        raise FirmwareIOError(f"{what} {n}: {node} does not exist (adapters here: "
                              f"{', '.join(have) or 'none'}; enable I2C, e.g. raspi-config)")
    return n


def check_sensor_arrays(status, min_fraction: float = 0.75) -> None:
    """Refuse to start when fewer than ``min_fraction`` of the sensors are configured (a board
    or a mux is missing: the pose needs sensors around the workspace)."""
    ok = sum(s == "ok" for s in status)
    if ok < min_fraction * len(status):
        bad = [i for i, s in enumerate(status) if s != "ok"]
        raise FirmwareIOError(f"{ok} of {len(status)} sensors answer (need >= "
                              f"{min_fraction:.0%}); not configured: sensors {bad}: check the "
                              "boards' cables, the TCA9548A addresses and power")


def load_inputs(map_path: str, scene_path: str, method: str):
    """Map, scene and pose estimator, checked against each other (no device is touched)."""
    fmap = MapFile.load(map_path)
    scene = Scene.load(scene_path, expected_design_sha256=fmap.design_sha256)
    estimator = estimator_from_map(map_path, method)
    return fmap, scene, estimator


def open_device(bus_number: int, sensor_bus_number: int | None, drives, n_sensors: int):
    """Open the bus(es) and build the PWM boards (one :class:`firmware_io.hw.driver.CoilDrive`
    per coil: the drive record's ``drives``) and the ``n_sensors`` sensors (default wiring, the
    map's sensor order)."""
    bus = open_bus(bus_number)
    sbus = bus if sensor_bus_number is None else open_bus(sensor_bus_number)
    boards = [PCA9685(bus, 0x40 + b) for b in range((len(drives) + 7) // 8)]
    return CoilDriver(boards, drives), SensorArrays(sbus, default_sensor_layout(n_sensors))


def calibrated_estimator(map_path: str, method: str, estimator, coils, arrays, cfg,
                         sleep=time.sleep):
    """The start-up sensor calibration (firmware_io.runner.record_calibration: coils alone,
    each pattern held for 7 L/R), then a pose estimator that uses it."""
    tau = max(cfg.drive.time_constant_s)
    amp = min(CALIBRATION_CURRENT_A, cfg.drive.current_limit_a)
    print(f"calibrating the sensors ({amp:.1f} A patterns, keep the magnet away)...",
          file=sys.stderr)
    readings, applied = record_calibration(coils, arrays, calibration_currents(cfg.n_coils, amp),
                                           settle_s=7 * tau, sleep=sleep)
    cal = calibrate_sensors(estimator.model, readings, applied)
    return estimator_from_map(map_path, method, calibration=cal)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        bus_n = _bus_number(args.bus, "--bus")
        sbus_n = None if args.sensor_bus is None else _bus_number(args.sensor_bus, "--sensor-bus")
        fmap, scene, estimator = load_inputs(args.map, args.scene, args.method)
        rows = scene.meta.get("rows", "force")
        cfg = config_from_map(fmap, control_period_s=args.period_ms * 1e-3,
                              unipolar=args.unipolar, force_axes="z" if rows == "fz" else "xyz")
        cfg.drive.check_ratings()    # a supply or PWM the driver is not rated for: refused
        coils, arrays = open_device(bus_n, sbus_n, cfg.drive.drives, fmap.n_sensors)
        check_sensor_arrays(arrays.configure())
        if args.calibrate:
            estimator = calibrated_estimator(args.map, args.method, estimator, coils, arrays, cfg)
    except (FirmwareIOError, OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    source = ThreadedSensorSource(arrays)
    runner = Runner(fmap, SceneForce(scene), estimator, RunnerIO(coils, source),
                    cfg, allocate=Allocator(), headroom=SensorHeadroom.from_meta(scene.meta))
    runner.start()
    source.start()
    t0 = time.monotonic()
    period = cfg.control_period_s
    try:
        next_t = t0
        while args.duration is None or time.monotonic() - t0 < args.duration:
            runner.step(time.monotonic())
            next_t += period
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                next_t = time.monotonic()
    except KeyboardInterrupt:
        pass
    finally:
        runner.stop()
        source.stop()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
