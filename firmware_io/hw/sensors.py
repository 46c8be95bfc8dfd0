"""SensorArrays: the TLV493D sensors -> one (n_sensors, 3) field array in tesla with per-sensor
health.

Default topology: one sensor per mux channel, so sensors that share an address never see each
other and each reset reaches one sensor only: e.g. 18 sensors on three TCA9548A at 0x71, 0x72,
0x73 (0x70 is left to the PCA9685 All-Call), sensor i on mux 0x71 + i // 8, channel i % 8,
in the map's sensor order. Only one mux has a channel enabled at any time.

A runner calls :meth:`SensorArrays.read` once per loop; a sensor that fails keeps its last good
value, is marked unhealthy, and is reset and reconfigured after ``checks.hang_reads`` bad reads
in a row (a NACK, frozen or zero values; a hung ADC after the sensor's own ``hang_reads``
frozen frame counters), at most once every ``retry_interval`` reads once it has failed. The
reset's wake-up wait (``TLV493D.reset_wait_s``, tens of ms) is not spent inside a read: the pass
sends the reset and goes on, a later pass configures the sensor once the wait is over (up to
``TLV493D.config_attempts`` resets), so the other sensors' frames keep their rate.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..errors import BadInputError, FirmwareIOError, I2CError
from .bus import I2CBus
from .tca9548a import TCA9548A
from .tlv493d import TLV493D, FrameChecks


@dataclass(frozen=True)
class SensorSlot:
    """Where one sensor sits: mux address, mux channel (0..7), sensor address."""

    mux_address: int
    mux_channel: int
    sensor_address: int = 0x5E


MAX_SENSORS = (0x77 - 0x71 + 1) * 8
"""Sensors the default layout addresses: one TLV493D per channel of the TCA9548A muxes at
0x71..0x77 (0x70 left free), 8 channels each."""


def default_sensor_layout(n_sensors: int = 18, first_mux: int = 0x71) -> tuple[SensorSlot, ...]:
    """One sensor per channel: sensor i on mux ``first_mux + i // 8``, channel ``i % 8``."""
    most = (0x77 - first_mux + 1) * 8
    if not 0 < n_sensors <= most:
        raise BadInputError("n_sensors", f"1..{most} (TCA9548A muxes 0x{first_mux:02x}..0x77, "
                            "8 channels each)", n_sensors)
    return tuple(SensorSlot(first_mux + i // 8, i % 8) for i in range(n_sensors))


@dataclass(frozen=True)
class ArraysReading:
    """One pass over every sensor.

    Attributes
    ----------
    field_t : ndarray, shape (n_sensors, 3), T
        (Bx, By, Bz) of each sensor in the layout's order; an unhealthy sensor shows its last
        good value (zeros before it ever read well), a saturated one its clipped value.
    status : tuple of str, length n_sensors
        Per-sensor status (see :meth:`firmware_io.hw.tlv493d.TLV493D.read`).
    healthy : ndarray, shape (n_sensors,), bool
        ``status == 'ok'``.
    """

    field_t: np.ndarray
    status: tuple[str, ...]
    healthy: np.ndarray


class SensorArrays:
    """Reads every sensor through TCA9548A muxes.

    Parameters
    ----------
    bus : smbus2.SMBus-like
    layout : sequence of SensorSlot, one per sensor
        Default :func:`default_sensor_layout` (18 sensors).
    temperature : {'off', 'on'}
    checks : firmware_io.hw.tlv493d.FrameChecks
        Each sensor's read checks; ``hang_reads`` is also the number of bad reads in a row
        (NACK, frozen, zero) before a sensor is reset and reconfigured.
    retry_interval : int
        Reads between configuration attempts of a sensor that failed.
    sleep : callable
        Waits s seconds (the reset's wake-up wait of :meth:`configure`).
    clock : callable
        Now, s (when a sensor reset during :meth:`read` may be configured); the clock ``sleep``
        advances.
    """

    def __init__(self, bus: I2CBus, layout: Sequence[SensorSlot] | None = None, *,
                 temperature: Literal["off", "on"] = "off", checks: FrameChecks = FrameChecks(),
                 retry_interval: int = 100, sleep: Callable[[float], None] = time.sleep,
                 clock: Callable[[], float] = time.monotonic):
        self.layout = tuple(layout) if layout is not None else default_sensor_layout()
        n = len(self.layout)
        if n == 0:
            raise BadInputError("layout", "at least one SensorSlot", n)
        seen = set()
        for s in self.layout:
            # sensors sharing a channel see one SDA level at reset and cannot be told apart
            key = (s.mux_address, s.mux_channel)
            if key in seen:
                raise BadInputError("layout", "one sensor per (mux, channel)", key)
            seen.add(key)
        self.bus = bus
        self.muxes = {a: TCA9548A(bus, a) for a in sorted({s.mux_address for s in self.layout})}
        self.sensors = [TLV493D(bus, s.sensor_address, temperature=temperature, checks=checks,
                                recover_in_read=False, sleep=sleep) for s in self.layout]
        self.hang_reads = checks.hang_reads
        self.retry_interval = int(retry_interval)
        self._last_good = np.zeros((n, 3))
        self._bad_in_row = [0] * n
        self._retry_countdown = [0] * n
        self.clock = clock
        self._resetting: list[tuple[float, int, str] | None] = [None] * n
        """Per sensor in recovery: (time of its reset s, resets so far, status once configured:
        'recovered' after bad reads, 'ok' after a failure, then read in the same pass)."""
        self.status: list[str] = ["unconfigured"] * n

    def _route(self, i: int) -> None:
        slot = self.layout[i]
        for addr, mux in self.muxes.items():
            if addr != slot.mux_address and mux.mask != 0:
                mux.disable()
        self.muxes[slot.mux_address].select(slot.mux_channel)

    def configure(self) -> tuple[str, ...]:
        """Disconnect every mux channel, then reset and configure each sensor alone.

        Returns the per-sensor status ('ok' or 'failed'); failures do not stop the others.
        """
        for mux in self.muxes.values():
            mux.invalidate()
            try:
                mux.disable()
            except I2CError:
                pass  # _route below reports the mux again if it stays silent
        for i in range(len(self.sensors)):
            self._configure_one(i)
        return tuple(self.status)

    def _configure_one(self, i: int) -> None:
        self._resetting[i] = None
        try:
            self._route(i)
            self.sensors[i].configure()
            self.status[i] = "ok"
            self._bad_in_row[i] = 0
        except FirmwareIOError:
            self._failed(i)

    def _failed(self, i: int) -> None:
        self.status[i] = "failed"
        self._retry_countdown[i] = self.retry_interval

    def _start_reset(self, i: int, tries: int, then: str) -> None:
        """Send sensor i's reset; a later :meth:`_recover` configures it after the wake-up."""
        try:
            self._route(i)
        except FirmwareIOError:
            pass  # the mux did not answer: the configuration after the wait fails and says so
        else:
            self.sensors[i].start_reset()
        self._resetting[i] = (self.clock(), tries + 1, then)

    def _recover(self, i: int, status: str) -> str:
        """Sensor i's status in this pass while it recovers: ``status`` until its reset's
        wake-up is over, then one configuration attempt; a failed attempt resets it again, up
        to the sensor's ``config_attempts``, then 'failed' (retried after ``retry_interval``)."""
        sensor = self.sensors[i]
        reset_s, tries, then = self._resetting[i]
        if self.clock() - reset_s < sensor.reset_wait_s:
            return status
        try:
            self._route(i)
            took = not sensor.configure_after_reset()
        except FirmwareIOError:
            took = False
        if took:
            self._resetting[i] = None
            self._bad_in_row[i] = 0
            if then == "recovered":
                sensor.recoveries += 1
            return then
        if tries < sensor.config_attempts:
            self._start_reset(i, tries, then)
            return status
        self._resetting[i] = None
        sensor.status = "failed"
        self._failed(i)
        return "failed"

    def read(self) -> ArraysReading:
        """Read every sensor once (one mux select, when it changes, and one frame read each)."""
        n = len(self.sensors)
        for i in range(n):
            if self._resetting[i] is not None:
                self.status[i] = self._recover(i, self.status[i])
                if self.status[i] != "ok":
                    continue
            elif self.status[i] in ("failed", "unconfigured"):
                self._retry_countdown[i] -= 1
                if self._retry_countdown[i] <= 0:
                    self._start_reset(i, 0, "ok")
                continue
            sensor = self.sensors[i]
            try:
                self._route(i)
                b = sensor.read()
                status = sensor.status
            except I2CError:
                status = "nack"
                b = None
            except FirmwareIOError:  # the sensor's own recovery failed
                status = "failed"
                b = None
            if status in ("ok", "saturated") and b is not None:
                self._last_good[i] = b
                self._bad_in_row[i] = 0
            elif status == "failed":
                self._retry_countdown[i] = self.retry_interval
            elif status == "hung":  # the sensor debounced its frozen frame counter
                self._start_reset(i, 0, "recovered")
            elif status not in ("stale", "recovered"):  # the sensor itself debounces stale frames
                self._bad_in_row[i] += 1
                if self._bad_in_row[i] >= self.hang_reads:
                    self._start_reset(i, 0, "recovered")
                    self._bad_in_row[i] = 0
            self.status[i] = status
        status = tuple(self.status)
        return ArraysReading(self._last_good.copy(), status,
                             np.array([s == "ok" for s in status]))
