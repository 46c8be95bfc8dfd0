"""Register-level simulated TLV493D-A1B6 3D Hall sensor, as the driver sees the chip.

10-byte read frame without register pointer, 4-byte writes with the odd-parity rule enforced
when PT=1, address latched at reset from the level seen on SDA, IICAddr offsets, frame counter
advancing once per read in master-controlled mode, PD / CH / T flags, 12-bit saturation
(Infineon TLV493D-A1B6 user manual [UM] and datasheet [DS]; docs/hardware.md). Faults:
``stuck_frame``, ``value_fault`` ('frozen' / 'zero' values with a live frame counter),
``reject_config``, ``busy_reads``, :meth:`SimDevice.inject_nack`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Literal

from ..tlv493d import TLV493D_LSB_T, tlv493d_address
from .device import SimDevice


class SimTLV493D(SimDevice):
    """Register-level TLV493D-A1B6 3D Hall sensor.

    Parameters
    ----------
    field_t : (3,) floats, T
        Flux density the sensor sees; converted to 12-bit counts of 0.098 mT, saturating at
        -2048 / +2047 (the range limit).
    temperature_raw : int
        12-bit temperature count (340 at 25 degC nominal [UM 3.2]).
    power_up_address : {0x5E, 0x1F}
        Address latched at power-up (SDA high at power-up -> 0x5E).
    factory_bytes : (3,) ints
        Read-only bytes 7..9; their bits 4:3, byte 8 and bits 4:0 must be copied into writes.

    Faults: ``stuck_frame`` (ADC hang: no new conversion, frame counter frozen; a general reset
    clears it unless ``stuck_after_reset``), ``value_fault`` ('frozen': each conversion advances
    the frame counter but repeats the values converted before the fault; 'zero': the values
    read 0 on every axis; a damaged sensor: a reset does not clear it), ``reject_config`` (the
    next ``reject_config`` writes
    are ignored as if their parity were wrong), ``busy_reads`` (the next reads see CH != 0, PD = 0),
    :meth:`inject_nack`.
    """

    def __init__(self, field_t: Sequence[float] = (0.0, 0.0, 0.0), temperature_raw: int = 340,
                 power_up_address: int = 0x5E, factory_bytes: Sequence[int] = (0x8D, 0x85, 0x3A)):
        super().__init__()
        self.field_t = tuple(float(v) for v in field_t)
        self.field_source: Callable[[], Sequence[float]] | None = None
        """Optional callable returning the field (3,) T at each conversion (e.g. a
        designkit.sim.readings simulator); overrides ``field_t``."""
        self.temperature_raw = int(temperature_raw)
        self.factory_bytes = bytes(factory_bytes)
        self.stuck_frame = False
        self.stuck_after_reset = False
        self.value_fault: Literal["frozen", "zero"] | None = None
        self._frozen_raw: list | None = None
        self._last_converted = [0, 0, 0]    # survives a reset: the values the fault freezes
        self.reject_config = 0
        self.busy_reads = 0
        self.parity_rejections = 0
        self.conversions = 0
        self.resets = 0
        self._reset_state(power_up_address)

    def _reset_state(self, base: int) -> None:
        self.base_address = base
        fb = self.factory_bytes
        self.write_regs = bytes([0x00, fb[0] & 0x18, fb[1], fb[2] & 0x1F])  # power-down mode
        self.raw = [0, 0, 0]
        self.temp_raw_latched = 0
        self.frm = 0
        self.pd = 0
        self._read_happened = False
        self._pending_write: bytes | None = None

    # -- configuration decoded -------------------------------------------------------------
    @property
    def mod1(self) -> int:
        return self.write_regs[1]

    @property
    def mod2(self) -> int:
        return self.write_regs[3]

    @property
    def address(self) -> int:
        return tlv493d_address(self.base_address, (self.mod1 >> 5) & 0x3)

    @property
    def mode(self) -> Literal["power_down", "fast", "low_power", "ultra_low_power", "master_controlled"]:
        fast, low = (self.mod1 >> 1) & 1, self.mod1 & 1
        if fast and low:
            return "master_controlled"
        if fast:
            return "fast"
        if low:
            return "low_power" if self.mod2 & 0x40 else "ultra_low_power"
        return "power_down"

    # -- bus side --------------------------------------------------------------------------
    def responds_to(self, addr: int) -> bool:
        return addr == self.address

    def on_write(self, addr: int, data: bytes) -> None:
        self._pending_write = bytes(data)

    def on_read(self, addr: int, length: int) -> bytes:
        self._read_happened = True
        frame = bytearray(self.frame())
        if self.busy_reads > 0:
            self.busy_reads -= 1
            frame[3] = (frame[3] & 0xFC) | 0x01  # CH = 1: conversion of Y still running
            frame[5] &= ~0x10 & 0xFF             # PD = 0
        # no register pointer: reads start at byte 0; beyond byte 9 SDA stays high
        return bytes(frame[:length]) + b"\xff" * max(length - 10, 0)

    def on_general_call(self, data: bytes) -> bool:
        self.resets += 1
        # the master holds SDA at the data level: all-zero byte -> low -> 0x1F, else high -> 0x5E
        self._reset_state(0x1F if data[:1] == b"\x00" else 0x5E)
        if not self.stuck_after_reset:
            self.stuck_frame = False
        return False  # the sensor is in reset and does not acknowledge the data byte

    def on_stop(self) -> None:
        if self._pending_write is not None:
            self._apply_write(self._pending_write)
            self._pending_write = None
        if self._read_happened:
            self._read_happened = False
            if self.mode != "power_down" and not self.stuck_frame:
                self._convert()

    def _apply_write(self, data: bytes) -> None:
        if len(data) != 4:
            self.violations.append(f"write of {len(data)} bytes (the sensor expects 4)")
            return
        parity_test = bool(data[3] & 0x20)
        odd = bin(int.from_bytes(data, "big")).count("1") % 2 == 1
        if (parity_test and not odd) or self.reject_config > 0:
            self.reject_config = max(self.reject_config - 1, 0)
            self.parity_rejections += 1
            return
        fb = self.factory_bytes
        if (data[1] & 0x18) != (fb[0] & 0x18) or data[2] != fb[1] or (data[3] & 0x1F) != (fb[2] & 0x1F):
            self.violations.append("factory bits not copied into the write registers")
        self.write_regs = bytes(data)

    def _convert(self) -> None:
        self.conversions += 1
        b_t = self.field_t if self.field_source is None else tuple(self.field_source())
        self.raw = [int(min(max(round(b / TLV493D_LSB_T), -2048), 2047)) for b in b_t]
        if self.value_fault == "zero":
            self.raw = [0, 0, 0]
        elif self.value_fault == "frozen":
            if self._frozen_raw is None:
                self._frozen_raw = list(self._last_converted)
            self.raw = list(self._frozen_raw)
        self._last_converted = list(self.raw)
        if not self.mod2 & 0x80:  # T=0: temperature measured too
            self.temp_raw_latched = self.temperature_raw
        self.frm = (self.frm + 1) & 0x3
        self.pd = 1

    def frame(self) -> bytes:
        """The 10 readable bytes as the sensor would send them now."""
        bx, by, bz = (v & 0xFFF for v in self.raw)
        t = self.temp_raw_latched & 0xFFF
        ff = 1 if self.mod2 & 0x20 else 0
        return bytes([
            bx >> 4, by >> 4, bz >> 4,
            ((t >> 8) & 0x0F) << 4 | self.frm << 2 | 0,
            (bx & 0x0F) << 4 | (by & 0x0F),
            ff << 5 | self.pd << 4 | (bz & 0x0F),
            t & 0xFF,
        ]) + self.factory_bytes
