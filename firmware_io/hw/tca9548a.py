"""Driver of the TI TCA9548A 1-to-8 I2C switch (the muxes in front of the Hall sensors).

The channel mask is cached and written only when it changes; after any bus error the cache is
dropped. A new mask routes only after the STOP of its write (TI TCA9548A datasheet).
"""

from __future__ import annotations

from ..errors import BadInputError
from .bus import I2CBus, wrap_os_error


class TCA9548A:
    """TI TCA9548A 1-to-8 I2C switch with a cached channel mask.

    The mask is written only when it changes; after any bus error the cache is dropped, so the
    next select writes again. A new mask routes only after the STOP of its write [TI].
    """

    def __init__(self, bus: I2CBus, address: int = 0x71):
        if isinstance(address, bool) or not isinstance(address, int) or not 0x70 <= address <= 0x77:
            raise BadInputError("address", "a TCA9548A address in 0x70..0x77", address)
        self.bus = bus
        self.address = address
        self._mask: int | None = None  # unknown until written

    @property
    def mask(self) -> int | None:
        """Cached channel mask (None = unknown)."""
        return self._mask

    def select_mask(self, mask: int) -> None:
        """Enable exactly the channels whose bits are set in ``mask`` (0..255)."""
        if isinstance(mask, bool) or not isinstance(mask, int) or not 0 <= mask <= 0xFF:
            raise BadInputError("mask", "an int in 0..255", mask)
        if mask == self._mask:
            return
        try:
            self.bus.write_byte(self.address, mask)
        except OSError as exc:
            self._mask = None
            raise wrap_os_error(exc, f"TCA9548A at 0x{self.address:02X}: set channel mask 0x{mask:02X}") from exc
        self._mask = mask

    def select(self, channel: int) -> None:
        """Enable only ``channel`` (0..7)."""
        if isinstance(channel, bool) or not isinstance(channel, int) or not 0 <= channel <= 7:
            raise BadInputError("channel", "an int in 0..7", channel)
        self.select_mask(1 << channel)

    def disable(self) -> None:
        """Disconnect every channel."""
        self.select_mask(0)

    def invalidate(self) -> None:
        """Forget the cached mask (e.g. after the mux was reset or power-cycled)."""
        self._mask = None

    def read_mask(self) -> int:
        """Read the control register back."""
        try:
            return self.bus.read_byte(self.address)
        except OSError as exc:
            self._mask = None
            raise wrap_os_error(exc, f"TCA9548A at 0x{self.address:02X}: read channel mask") from exc
