"""The kernel side of ``/dev/i2c-N`` over a :class:`SimBus`, to run the real ``smbus2.SMBus``.

:class:`SimI2cDevFile` fakes ``os.open``, ``os.close`` and ``fcntl.ioctl`` of a Linux i2c-dev
node: every ``I2C_SMBUS`` and ``I2C_RDWR`` request is turned into the messages the kernel would
put on the wire (sizes and flags of uapi/linux/i2c.h) and run on the simulated bus, so the
real smbus2 class is exercised end to end without hardware.
"""

from __future__ import annotations

import os
import types
from typing import Any

from .bus import SimBus


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
        return types.SimpleNamespace(open=self.open, close=self.close, O_RDWR=os.O_RDWR)

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
            self.bus.transfer_msgs([arg.msgs[i] for i in range(arg.nmsgs)], "ioctl I2C_RDWR")
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
