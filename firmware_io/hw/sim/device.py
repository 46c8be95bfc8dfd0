"""Base of the simulated I2C devices: address matching, NACK injection, rule violations.

A device model reacts to the bus's messages (:meth:`SimDevice.on_write`, :meth:`on_read`,
:meth:`on_general_call`, :meth:`on_stop`) and records any rule of its datasheet the driver broke
in :attr:`SimDevice.violations`; :class:`firmware_io.hw.sim.bus.SimBus` routes the messages.
"""

from __future__ import annotations

import time
from collections.abc import Callable


class Nack(Exception):
    """A simulated device did not acknowledge (the bus turns it into errno 121, as Linux does)."""


class SimDevice:
    """Base of the device models: address matching, NACK injection, rule violations.

    ``channels``: the devices behind this one, one list per downstream channel (a switch's; an
    end device has none)."""

    def __init__(self) -> None:
        self.channels: list[list[SimDevice]] = []
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
            raise Nack
        if self._nack_remaining > 0:
            if self._nack_skip > 0:
                self._nack_skip -= 1
                return
            self._nack_remaining -= 1
            raise Nack

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

