"""Simulated I2C bus with register-level models of the PCA9685, TLV493D-A1B6 and TCA9548A.

There is no hardware here, so firmware_io is built against these models. They follow the chips at
the level the drivers see (their datasheets, as in :mod:`firmware_io.devices`):

* :class:`SimPCA9685` -- register file with auto-increment (0x45 wraps to 0x00), PRE_SCALE
  writable only while SLEEP=1 (minimum 3), All-Call at 0x70 while MODE1.ALLCALL=1, ALL_LED
  registers writing every channel, full-on / full-off bits (OFF wins), outputs latched at STOP
  (MODE2.OCH=0), SWRST by general call 0x06, the 500 us oscillator wait before RESTART.
* :class:`SimTLV493D` -- 10-byte read frame without register pointer, 4-byte writes with the
  odd-parity rule enforced when PT=1, address latched at reset from the level seen on SDA,
  IICAddr offsets, frame counter advancing once per read in master-controlled mode, PD / CH / T
  flags, 12-bit saturation.
* :class:`SimTCA9548A` -- one control register; the new channel mask routes only after STOP.

:class:`SimBus` has :class:`smbus2.SMBus`'s methods, routes each message to the one device that
answers its address (an error if two would), records every transaction in :attr:`SimBus.log`
so tests can assert the exact bytes on the wire, and raises ``OSError(121)`` on a NACK like the
Linux i2c-dev driver. Faults are injected on the devices: :meth:`SimDevice.inject_nack`,
``SimTLV493D.stuck_frame``, ``SimTLV493D.reject_config``, a field beyond the range limit.

:class:`SimI2cDevFile` plays the kernel side of ``/dev/i2c-N`` (``os.open``, ``os.close``,
``fcntl.ioctl``) on top of a :class:`SimBus`, so the real ``smbus2.SMBus`` class can be run end to
end without hardware.
"""

from __future__ import annotations

import ctypes
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from .bus import I2C_M_RD, transaction_wire_time_s
from .errors import NACK_ERRNO

# ---------------------------------------------------------------------------------------------
# clock, log records, errors


class SimClock:
    """A clock the simulation and the drivers share, so timing rules are checked without waiting.

    Pass ``clock.sleep`` as the drivers' ``sleep`` and the clock to :class:`SimBus`; the bus also
    advances the clock by each transaction's wire time.
    """

    def __init__(self, start_s: float = 0.0):
        self.t = float(start_s)

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(float(seconds), 0.0)


@dataclass(frozen=True)
class Message:
    """One message of a transaction: ``op`` 'w' (data sent) or 'r' (data returned)."""

    op: Literal["w", "r"]
    addr: int
    data: bytes


@dataclass(frozen=True)
class Transaction:
    """Messages between one START and the STOP; ``error`` is the errno raised (None = ACKed)."""

    messages: tuple[Message, ...]
    error: int | None
    api: str
    start_s: float | None = None  # SimClock time at START (None without a SimClock)

    def wire_time_s(self, scl_hz: float) -> float:
        """Wire time of this transaction at ``scl_hz``, s (:func:`firmware_io.bus.transaction_wire_time_s`)."""
        return transaction_wire_time_s([len(m.data) for m in self.messages], scl_hz)


class SimAddressConflict(RuntimeError):
    """Two enabled devices answer one address: on real hardware their replies would collide."""


class _Nack(Exception):
    pass


# ---------------------------------------------------------------------------------------------
# devices


class SimDevice:
    """Base of the device models: address matching, NACK injection, rule violations."""

    def __init__(self) -> None:
        self.violations: list[str] = []
        self._nack_remaining = 0
        self._nack_skip = 0
        self.nack_always = False
        self.clock: Callable[[], float] = time.monotonic

    def inject_nack(self, count: int = 1, after: int = 0) -> None:
        """NACK the next ``count`` transfers addressed to this device, after ``after`` good ones."""
        self._nack_skip = int(after)
        self._nack_remaining = int(count)

    def _check_nack(self) -> None:
        if self.nack_always:
            raise _Nack
        if self._nack_remaining > 0:
            if self._nack_skip > 0:
                self._nack_skip -= 1
                return
            self._nack_remaining -= 1
            raise _Nack

    def responds_to(self, addr: int) -> bool:
        raise NotImplementedError

    def on_write(self, addr: int, data: bytes) -> None:
        raise NotImplementedError

    def on_read(self, addr: int, length: int) -> bytes:
        raise NotImplementedError

    def on_general_call(self, data: bytes) -> bool:
        """React to a general-call write; return True if the device ACKs the data."""
        return False

    def on_stop(self) -> None:
        pass

    def downstream(self) -> list["SimDevice"]:
        return []


# PCA9685 register numbers and MODE1 bits [NXP]
MODE1, MODE2, SUBADR1, SUBADR2, SUBADR3, ALLCALLADR = 0x00, 0x01, 0x02, 0x03, 0x04, 0x05
LED0_ON_L, ALL_LED_ON_L, ALL_LED_OFF_H, PRE_SCALE, TESTMODE = 0x06, 0xFA, 0xFD, 0xFE, 0xFF
_RESTART, _AI, _SLEEP, _SUB1, _SUB2, _SUB3, _ALLCALL = 0x80, 0x20, 0x10, 0x08, 0x04, 0x02, 0x01


class SimPCA9685(SimDevice):
    """Register-level PCA9685 (16-channel 12-bit PWM).

    Parameters
    ----------
    address : int
        7-bit address set by A5..A0 (0x40..0x7F).
    oscillator_hz : float
        Internal oscillator, Hz (25 MHz nominal; real parts are untrimmed).
    """

    def __init__(self, address: int = 0x40, oscillator_hz: float = 25e6):
        super().__init__()
        self.address = address
        self.oscillator_hz = oscillator_hz
        self.output_enable_high = False  # the OE pin: high = hardware kill
        self.power_on_reset()

    def power_on_reset(self) -> None:
        self.regs = bytearray(256)
        self.regs[MODE1] = 0x11  # SLEEP | ALLCALL
        self.regs[MODE2] = 0x04
        self.regs[SUBADR1], self.regs[SUBADR2], self.regs[SUBADR3] = 0xE2, 0xE4, 0xE8
        self.regs[ALLCALLADR] = 0xE0
        for n in range(16):
            self.regs[LED0_ON_L + 4 * n + 3] = 0x10  # full OFF at power-up
        self.regs[PRE_SCALE] = 0x1E
        self.pointer = 0
        self._woke_at: float | None = None
        self._latched = bytes(self.regs[LED0_ON_L:LED0_ON_L + 64])

    # -- bus side --------------------------------------------------------------------------
    def responds_to(self, addr: int) -> bool:
        m = self.regs[MODE1]
        return (addr == self.address
                or (bool(m & _ALLCALL) and addr == self.regs[ALLCALLADR] >> 1)
                or (bool(m & _SUB1) and addr == self.regs[SUBADR1] >> 1)
                or (bool(m & _SUB2) and addr == self.regs[SUBADR2] >> 1)
                or (bool(m & _SUB3) and addr == self.regs[SUBADR3] >> 1))

    def _advance(self) -> None:
        if self.regs[MODE1] & _AI:
            self.pointer = 0x00 if self.pointer == 0x45 else (self.pointer + 1) & 0xFF

    def on_write(self, addr: int, data: bytes) -> None:
        if not data:
            return
        self.pointer = data[0]
        for value in data[1:]:
            self._write_register(self.pointer, value)
            self._advance()

    def on_read(self, addr: int, length: int) -> bytes:
        out = bytearray()
        for _ in range(length):
            reg = self.pointer
            out.append(0 if ALL_LED_ON_L <= reg <= ALL_LED_OFF_H else self.regs[reg])
            self._advance()
        return bytes(out)

    def on_general_call(self, data: bytes) -> bool:
        if bytes(data) == b"\x06":  # SWRST
            self.power_on_reset()
            return True
        return False

    def on_stop(self) -> None:
        if not self.regs[MODE2] & 0x08:  # OCH=0: outputs change on STOP
            self._latch()

    def _latch(self) -> None:
        self._latched = bytes(self.regs[LED0_ON_L:LED0_ON_L + 64])
        for n in range(16):
            on_l, on_h, off_l, off_h = self._latched[4 * n:4 * n + 4]
            if not (on_h & 0x10 or off_h & 0x10):
                if (on_l | (on_h & 0x0F) << 8) == (off_l | (off_h & 0x0F) << 8):
                    self.violations.append(f"channel {n}: ON count equals OFF count")

    def _write_register(self, reg: int, value: int) -> None:
        if reg == MODE1:
            old = self.regs[MODE1]
            new = value & 0x7F
            if value & _RESTART and old & _RESTART:
                # writing 1 to a set RESTART clears it and restarts the PWM channels
                if self._woke_at is not None and self.clock() - self._woke_at < 500e-6:
                    self.violations.append("RESTART written < 500 us after leaving SLEEP")
            elif old & _RESTART:
                new |= _RESTART
            if new & _SLEEP and not old & _SLEEP and self._any_active():
                new |= _RESTART
            if old & _SLEEP and not new & _SLEEP:
                self._woke_at = self.clock()
            self.regs[MODE1] = new
        elif ALL_LED_ON_L <= reg <= ALL_LED_OFF_H:
            for n in range(16):
                self.regs[LED0_ON_L + 4 * n + (reg - ALL_LED_ON_L)] = value
        elif reg == PRE_SCALE:
            if self.regs[MODE1] & _SLEEP:
                self.regs[PRE_SCALE] = max(value, 3)
            else:
                self.violations.append("PRE_SCALE written while awake (ignored by the chip)")
        elif reg == TESTMODE:
            self.violations.append("register 0xFF (test mode) written")
        elif 0x46 <= reg <= 0xF9:
            pass  # reserved
        else:
            self.regs[reg] = value

    def _any_active(self) -> bool:
        return any(self.duty(n) > 0 for n in range(16))

    # -- observation -----------------------------------------------------------------------
    @property
    def prescale(self) -> int:
        return self.regs[PRE_SCALE]

    @property
    def frequency_hz(self) -> float:
        """PWM frequency, Hz: oscillator / (4096 (prescale + 1))."""
        return self.oscillator_hz / (4096.0 * (self.prescale + 1))

    def channel_bytes(self, channel: int) -> bytes:
        """``[ON_L, ON_H, OFF_L, OFF_H]`` of ``channel`` as held in the register file."""
        base = LED0_ON_L + 4 * channel
        return bytes(self.regs[base:base + 4])

    def duty(self, channel: int) -> float:
        """Fraction of the PWM period the output is high (after STOP latching, SLEEP and OE)."""
        m = self.regs[MODE1]
        if m & _SLEEP or m & _RESTART or self.output_enable_high:
            return 0.0
        on_l, on_h, off_l, off_h = self._latched[4 * channel:4 * channel + 4]
        if off_h & 0x10:
            d = 0.0
        elif on_h & 0x10:
            d = 1.0
        else:
            on = on_l | (on_h & 0x0F) << 8
            off = off_l | (off_h & 0x0F) << 8
            d = ((off - on) % 4096) / 4096.0
        return 1.0 - d if self.regs[MODE2] & 0x10 else d

    def level(self, channel: int) -> Literal["low", "high", "pwm"]:
        d = self.duty(channel)
        return "low" if d == 0.0 else ("high" if d == 1.0 else "pwm")


class SimTCA9548A(SimDevice):
    """TCA9548A 1-to-8 I2C switch: one control register, routing changes after STOP."""

    def __init__(self, address: int = 0x71):
        super().__init__()
        self.address = address
        self.channels: list[list[SimDevice]] = [[] for _ in range(8)]
        self.mask = 0
        self._pending: int | None = None

    def attach(self, channel: int, device: SimDevice) -> SimDevice:
        self.channels[channel].append(device)
        return device

    def reset(self) -> None:
        """The /RESET pin or a power cycle: every channel off."""
        self.mask = 0
        self._pending = None

    def responds_to(self, addr: int) -> bool:
        return addr == self.address

    def on_write(self, addr: int, data: bytes) -> None:
        if data:
            self._pending = data[-1]

    def on_read(self, addr: int, length: int) -> bytes:
        return bytes([self.mask]) * length

    def on_stop(self) -> None:
        if self._pending is not None:
            self.mask = self._pending
            self._pending = None

    def downstream(self) -> list[SimDevice]:
        return [d for ch in range(8) if self.mask >> ch & 1 for d in self.channels[ch]]


TLV_LSB_T = 0.098e-3  # tesla per LSB of the 12-bit field values [DS]


def _tlv_address(base: int, code: int) -> int:
    # MOD1.IICAddr offsets [UM Table 6]; formula from [PYT]
    return base ^ (((code << 3) | (code << 2)) & 0x14)


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
    clears it unless ``stuck_after_reset``), ``reject_config`` (the next ``reject_config`` writes
    are ignored as if their parity were wrong), ``busy_reads`` (the next reads see CH != 0, PD = 0),
    :meth:`inject_nack`.
    """

    def __init__(self, field_t: Sequence[float] = (0.0, 0.0, 0.0), temperature_raw: int = 340,
                 power_up_address: int = 0x5E, factory_bytes: Sequence[int] = (0x8D, 0x85, 0x3A)):
        super().__init__()
        self.field_t = tuple(float(v) for v in field_t)
        self.field_source: Callable[[], Sequence[float]] | None = None
        """Optional callable returning the field (3,) T at each conversion (e.g. a
        designkit.localize simulator); overrides ``field_t``."""
        self.temperature_raw = int(temperature_raw)
        self.factory_bytes = bytes(factory_bytes)
        self.stuck_frame = False
        self.stuck_after_reset = False
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
        return _tlv_address(self.base_address, (self.mod1 >> 5) & 0x3)

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
        self.raw = [int(min(max(round(b / TLV_LSB_T), -2048), 2047)) for b in b_t]
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


# ---------------------------------------------------------------------------------------------
# the bus


class SimBus:
    """Simulated I2C adapter with :class:`smbus2.SMBus`'s methods.

    Parameters
    ----------
    devices : iterable of SimDevice
        Devices on the upstream segment (muxes carry their own downstream devices).
    scl_hz : float
        Clock used to advance ``clock`` by each transaction's wire time.
    clock : SimClock, optional
        Shared simulated clock; default: the host's ``time.monotonic`` (no advance).
    """

    def __init__(self, devices: Iterable[SimDevice] = (), *, scl_hz: float = 400e3,
                 clock: SimClock | None = None):
        self.devices: list[SimDevice] = []
        self.scl_hz = float(scl_hz)
        self.clock = clock
        self.log: list[Transaction] = []
        self.model_time_s = 0.0  # host time spent inside the device models (bench_io)
        self.closed = False
        for d in devices:
            self.attach(d)

    def attach(self, device: SimDevice) -> SimDevice:
        self.devices.append(device)
        self._give_clock(device)
        return device

    def _give_clock(self, device: SimDevice) -> None:
        if self.clock is not None:
            device.clock = self.clock.now
        for ch in getattr(device, "channels", []):
            for d in ch:
                self._give_clock(d)

    def all_devices(self) -> list[SimDevice]:
        """Every device on the bus, reachable now or not."""
        out: list[SimDevice] = []

        def walk(d: SimDevice) -> None:
            out.append(d)
            for ch in getattr(d, "channels", []):
                for sub in ch:
                    walk(sub)
        for d in self.devices:
            walk(d)
        return out

    def reachable(self) -> list[SimDevice]:
        """Devices connected to the upstream segment through the current mux settings."""
        out: list[SimDevice] = []

        def walk(d: SimDevice) -> None:
            out.append(d)
            for sub in d.downstream():
                walk(sub)
        for d in self.devices:
            walk(d)
        return out

    def violations(self) -> list[str]:
        """Rule violations recorded by every device (empty for a correct driver)."""
        return [f"{type(d).__name__}: {v}" for d in self.all_devices() for v in d.violations]

    def clear_log(self) -> None:
        self.log.clear()

    def writes_to(self, addr: int) -> list[bytes]:
        """Data of every write message sent to ``addr`` (ACKed or not), oldest first."""
        return [m.data for t in self.log for m in t.messages if m.op == "w" and m.addr == addr]

    # -- core ------------------------------------------------------------------------------
    def transfer(self, msgs: Sequence[tuple[str, int, bytes | int]], api: str = "i2c_rdwr") -> list[bytes]:
        """Run one STOP-terminated transaction.

        Parameters
        ----------
        msgs : sequence of (op, addr, payload)
            ``('w', addr, bytes)`` or ``('r', addr, n_bytes)``.

        Returns
        -------
        list of bytes
            The data of each read message, in order.
        """
        if self.closed:
            raise OSError(9, "Bad file descriptor (bus closed)")
        t0 = time.perf_counter()
        start_s = self.clock.now() if self.clock is not None else None
        reach = self.reachable()  # routing changes only at STOP
        touched: list[SimDevice] = []
        logged: list[Message] = []
        reads: list[bytes] = []
        error: int | None = None
        conflict: str | None = None
        try:
            for op, addr, payload in msgs:
                if op == "w" and addr == 0x00:
                    data = bytes(payload)
                    logged.append(Message("w", addr, data))
                    acked = False
                    for d in reach:
                        acked |= d.on_general_call(data)
                        touched.append(d)
                    if not acked:
                        raise _Nack
                    continue
                devs = [d for d in reach if d.responds_to(addr)]
                if len(devs) > 1:
                    conflict = (f"address 0x{addr:02X} answered by "
                                + ", ".join(type(d).__name__ for d in devs))
                    logged.append(Message(op, addr, bytes(payload) if op == "w" else b""))
                    break
                if not devs:
                    logged.append(Message(op, addr, bytes(payload) if op == "w" else b""))
                    raise _Nack
                dev = devs[0]
                try:
                    dev._check_nack()
                except _Nack:
                    logged.append(Message(op, addr, bytes(payload) if op == "w" else b""))
                    raise
                if dev not in touched:
                    touched.append(dev)
                if op == "w":
                    data = bytes(payload)
                    dev.on_write(addr, data)
                    logged.append(Message("w", addr, data))
                else:
                    data = dev.on_read(addr, int(payload))
                    logged.append(Message("r", addr, data))
                    reads.append(data)
        except _Nack:
            error = NACK_ERRNO
        finally:
            for d in touched:  # the master sends STOP after a NACK too
                d.on_stop()
            tr = Transaction(tuple(logged), error if conflict is None else 5, api, start_s)
            self.log.append(tr)
            if self.clock is not None:
                self.clock.t += tr.wire_time_s(self.scl_hz)
            self.model_time_s += time.perf_counter() - t0
        if conflict is not None:
            raise SimAddressConflict(conflict)
        if error is not None:
            raise OSError(error, "Remote I/O error")
        return reads

    # -- smbus2.SMBus methods --------------------------------------------------------------
    def close(self) -> None:
        self.closed = True

    def __enter__(self) -> "SimBus":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def write_quick(self, i2c_addr: int, force: bool | None = None) -> None:
        self.transfer([("w", i2c_addr, b"")], "write_quick")

    def read_byte(self, i2c_addr: int, force: bool | None = None) -> int:
        return self.transfer([("r", i2c_addr, 1)], "read_byte")[0][0]

    def write_byte(self, i2c_addr: int, value: int, force: bool | None = None) -> None:
        self.transfer([("w", i2c_addr, bytes([value]))], "write_byte")

    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        return self.transfer([("w", i2c_addr, bytes([register])), ("r", i2c_addr, 1)],
                             "read_byte_data")[0][0]

    def write_byte_data(self, i2c_addr: int, register: int, value: int,
                        force: bool | None = None) -> None:
        self.transfer([("w", i2c_addr, bytes([register, value]))], "write_byte_data")

    def read_word_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int:
        data = self.transfer([("w", i2c_addr, bytes([register])), ("r", i2c_addr, 2)],
                             "read_word_data")[0]
        return data[0] | data[1] << 8

    def write_word_data(self, i2c_addr: int, register: int, value: int,
                        force: bool | None = None) -> None:
        self.transfer([("w", i2c_addr, bytes([register, value & 0xFF, value >> 8 & 0xFF]))],
                      "write_word_data")

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int,
                            force: bool | None = None) -> list[int]:
        if length > 32:
            raise ValueError("Desired block length over 32 bytes")
        return list(self.transfer([("w", i2c_addr, bytes([register])), ("r", i2c_addr, length)],
                                  "read_i2c_block_data")[0])

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int],
                             force: bool | None = None) -> None:
        if len(data) > 32:
            raise ValueError("Data length cannot exceed 32 bytes")
        self.transfer([("w", i2c_addr, bytes([register]) + bytes(data))], "write_i2c_block_data")

    def i2c_rdwr(self, *i2c_msgs: Any) -> None:
        """Combined transfer of ``smbus2.i2c_msg`` objects (read when ``flags & 1``)."""
        plan = [("r", m.addr, m.len) if m.flags & I2C_M_RD
                else ("w", m.addr, ctypes.string_at(m.buf, m.len)) for m in i2c_msgs]
        reads = iter(self.transfer(plan, "i2c_rdwr"))
        for m in i2c_msgs:
            if m.flags & I2C_M_RD:
                data = next(reads)
                ctypes.memmove(m.buf, data, m.len)


# ---------------------------------------------------------------------------------------------
# the kernel side of /dev/i2c-N, for exercising the real smbus2.SMBus


class SimI2cDevFile:
    """Fake ``os.open`` / ``os.close`` / ``fcntl.ioctl`` of a Linux i2c-dev node over a SimBus.

    Patch ``smbus2.smbus2.os`` with :meth:`os_namespace` and ``smbus2.smbus2.ioctl`` with
    :meth:`ioctl`; every ``I2C_SMBUS`` and ``I2C_RDWR`` request is turned into the messages the
    kernel would put on the wire and run on the SimBus.
    """

    I2C_SLAVE, I2C_FUNCS, I2C_SLAVE_FORCE, I2C_RDWR, I2C_PEC, I2C_SMBUS = (
        0x0703, 0x0705, 0x0706, 0x0707, 0x0708, 0x0720)
    #: what i2c-bcm2835 reports: plain I2C plus SMBus emulation
    FUNCS = 0x0EFF0009

    def __init__(self, bus: SimBus, fd: int = 1000):
        self.bus = bus
        self.fd = fd
        self.opened: list[str] = []
        self.closed_fds: list[int] = []
        self.slave: int | None = None
        self.requests: list[int] = []

    def os_namespace(self) -> Any:
        import types
        import os as real_os
        return types.SimpleNamespace(open=self.open, close=self.close, O_RDWR=real_os.O_RDWR)

    def open(self, path: str, flags: int) -> int:
        self.opened.append(path)
        return self.fd

    def close(self, fd: int) -> None:
        self.closed_fds.append(fd)

    def ioctl(self, fd: int, request: int, arg: Any = 0, *rest: Any) -> int:
        if fd != self.fd:
            raise OSError(9, "Bad file descriptor")
        self.requests.append(request)
        if request == self.I2C_FUNCS:
            arg.value = self.FUNCS
        elif request in (self.I2C_SLAVE, self.I2C_SLAVE_FORCE):
            self.slave = int(arg)
        elif request == self.I2C_PEC:
            pass
        elif request == self.I2C_SMBUS:
            self._smbus(arg)
        elif request == self.I2C_RDWR:
            msgs = [arg.msgs[i] for i in range(arg.nmsgs)]
            plan = [("r", m.addr, m.len) if m.flags & I2C_M_RD
                    else ("w", m.addr, ctypes.string_at(m.buf, m.len)) for m in msgs]
            reads = iter(self.bus.transfer(plan, "ioctl I2C_RDWR"))
            for m in msgs:
                if m.flags & I2C_M_RD:
                    ctypes.memmove(m.buf, next(reads), m.len)
        else:
            raise OSError(25, f"Inappropriate ioctl 0x{request:04X}")
        return 0

    def _smbus(self, arg: Any) -> None:
        # sizes and read/write markers from uapi/linux/i2c.h
        if self.slave is None:
            raise OSError(22, "Invalid argument (no I2C_SLAVE set)")
        addr, rw, cmd, size = self.slave, arg.read_write, arg.command, arg.size
        data = arg.data.contents
        api = f"ioctl I2C_SMBUS size={size} rw={rw}"
        if size == 0:  # QUICK
            self.bus.transfer([("r", addr, 0) if rw else ("w", addr, b"")], api)
        elif size == 1:  # BYTE
            if rw:
                data.byte = self.bus.transfer([("r", addr, 1)], api)[0][0]
            else:
                self.bus.transfer([("w", addr, bytes([cmd]))], api)
        elif size == 2:  # BYTE_DATA
            if rw:
                data.byte = self.bus.transfer([("w", addr, bytes([cmd])), ("r", addr, 1)], api)[0][0]
            else:
                self.bus.transfer([("w", addr, bytes([cmd, data.byte]))], api)
        elif size == 3:  # WORD_DATA
            if rw:
                r = self.bus.transfer([("w", addr, bytes([cmd])), ("r", addr, 2)], api)[0]
                data.word = r[0] | r[1] << 8
            else:
                w = data.word
                self.bus.transfer([("w", addr, bytes([cmd, w & 0xFF, w >> 8]))], api)
        elif size == 8:  # I2C_BLOCK_DATA: block[0] = length
            n = data.block[0]
            if rw:
                r = self.bus.transfer([("w", addr, bytes([cmd])), ("r", addr, n)], api)[0]
                for i, b in enumerate(r):
                    data.block[i + 1] = b
            else:
                payload = bytes(data.block[1:n + 1])
                self.bus.transfer([("w", addr, bytes([cmd]) + payload)], api)
        else:
            raise OSError(95, f"SMBus transfer size {size} not supported by this adapter")
