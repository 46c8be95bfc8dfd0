"""Simulated TCA9548A 1-to-8 I2C switch: one control register; a new channel mask routes only
after the STOP of its write (TI TCA9548A datasheet)."""

from __future__ import annotations

from .device import SimDevice


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
