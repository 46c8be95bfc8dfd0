"""Simulated I2C adapter with :class:`smbus2.SMBus`'s methods, its transaction log and clock.

:class:`SimBus` routes each message to the one device that answers its address (an error if two
would), records every transaction in :attr:`SimBus.log` so tests can assert the exact bytes on
the wire, and raises ``OSError(121)`` on a NACK like the Linux i2c-dev driver. A shared
:class:`SimClock` lets timing rules be checked without waiting: the bus advances it by each
transaction's wire time (:func:`firmware_io.hw.bus.transaction_wire_time_s`).
"""

from __future__ import annotations

import ctypes
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from ...errors import NACK_ERRNO
from ..bus import I2C_M_RD, transaction_wire_time_s
from .device import SimDevice, Nack


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
        """Wire time of this transaction at ``scl_hz``, s (:func:`firmware_io.hw.bus.transaction_wire_time_s`)."""
        return transaction_wire_time_s([len(m.data) for m in self.messages], scl_hz)


class SimAddressConflict(RuntimeError):
    """Two enabled devices answer one address: on real hardware their replies would collide."""



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
        self.model_time_s = 0.0  # host wall time spent inside the device models (bench_io)
        self.model_cpu_s = 0.0  # the calling thread's CPU time spent inside them
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
        for ch in device.channels:
            for d in ch:
                self._give_clock(d)

    def all_devices(self) -> list[SimDevice]:
        """Every device on the bus, reachable now or not."""
        out: list[SimDevice] = []

        def walk(d: SimDevice) -> None:
            out.append(d)
            for ch in d.channels:
                for sub in ch:
                    walk(sub)
        for d in self.devices:
            walk(d)
        return out

    def reachable(self) -> list[SimDevice]:
        """Devices connected to the upstream segment through the current mux settings."""
        out: list[SimDevice] = []
        stack = list(reversed(self.devices))
        while stack:   # depth first, in order (no recursive closure: that is a reference
            d = stack.pop()    # cycle, garbage for the cyclic collector on every transfer)
            out.append(d)
            stack.extend(reversed(list(d.downstream())))
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
    def cpu_outside_s(self) -> float:
        """This thread's CPU time (s) less the part spent inside the device models: a step
        clock for code that drives the bus (wall time inside the models grows with the host's
        load, CPU time does not)."""
        return time.thread_time() - self.model_cpu_s

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
        t0, c0 = time.perf_counter(), time.thread_time()
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
                        raise Nack
                    continue
                devs = [d for d in reach if d.responds_to(addr)]
                if len(devs) > 1:
                    conflict = (f"address 0x{addr:02X} answered by "
                                + ", ".join(type(d).__name__ for d in devs))
                    logged.append(Message(op, addr, bytes(payload) if op == "w" else b""))
                    break
                if not devs:
                    logged.append(Message(op, addr, bytes(payload) if op == "w" else b""))
                    raise Nack
                dev = devs[0]
                try:
                    dev._check_nack()
                except Nack:
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
        except Nack:
            error = NACK_ERRNO
        finally:
            for d in touched:  # the master sends STOP after a NACK too
                d.on_stop()
            tr = Transaction(tuple(logged), error if conflict is None else 5, api, start_s)
            self.log.append(tr)
            if self.clock is not None:
                self.clock.t += tr.wire_time_s(self.scl_hz)
            self.model_time_s += time.perf_counter() - t0
            self.model_cpu_s += time.thread_time() - c0
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
        self.transfer_msgs(i2c_msgs, "i2c_rdwr")

    def transfer_msgs(self, msgs: Sequence[Any], api: str) -> None:
        """Run kernel-layout ``i2c_msg`` structures as one transaction; read data is copied into
        each read message's buffer."""
        plan = [("r", m.addr, m.len) if m.flags & I2C_M_RD
                else ("w", m.addr, ctypes.string_at(m.buf, m.len)) for m in msgs]
        reads = iter(self.transfer(plan, api))
        for m in msgs:
            if m.flags & I2C_M_RD:
                ctypes.memmove(m.buf, next(reads), m.len)
