"""Exceptions of firmware_io.

firmware_io must run on a Raspberry-Pi-class host with only numpy and smbus2, so it does not
import designkit; its exceptions follow the same pattern (a built-in base plus the library base,
fields kept, picklable) so ``except OSError`` / ``except ValueError`` keep working.
"""

from __future__ import annotations

import errno as _errno

#: errno the Linux i2c-dev driver reports when the addressed device does not acknowledge (NACK).
NACK_ERRNO = _errno.EREMOTEIO  # 121 on Linux


class FirmwareIOError(Exception):
    """Base class of every error firmware_io raises on purpose."""


class InputRangeError(ValueError):
    """An input is outside its valid range: the one message pattern of firmware_io and designkit
    (``designkit.errors.BadInputError`` derives from it too).

    ``Input hz must be in [23.8, 1526] Hz; instead received 5000.``
    """

    def __init__(self, name: str, valid: str, received: object, hint: str = ""):
        self.name = name
        self.valid = valid
        self.received = received
        self.hint = hint
        message = f"Input {name} must be {valid}; instead received {received!r}."
        if hint:
            message += f" {hint}"
        super().__init__(message)

    def __reduce__(self):
        return (type(self), (self.name, self.valid, self.received, self.hint))


class BadInputError(InputRangeError, FirmwareIOError):
    """An input of firmware_io is outside its valid range (see :class:`InputRangeError`)."""


class I2CError(OSError, FirmwareIOError):
    """A bus transfer failed; ``errno`` is the one the bus reported (121 = NACK).

    The message names the device, its address and what was being done, so a log line is enough
    to find the wire or the chip at fault.
    """

    def __init__(self, errno: int | None, message: str):
        super().__init__(errno, message)

    def __str__(self) -> str:
        code = "" if self.errno is None else f" [errno {self.errno}]"
        return f"{self.strerror}{code}"

    def __reduce__(self):
        return (type(self), (self.errno, self.strerror))


class CoilWriteError(I2CError):
    """A coil command could not be written; the driver then switched every coil off.

    ``safe_state`` tells whether switching off was confirmed on every PCA9685
    (``"all_off_confirmed"``) or not (``"unconfirmed"``: drive the PCA9685 OE pin high).
    """

    def __init__(self, errno: int | None, message: str, safe_state: str = "all_off_confirmed"):
        super().__init__(errno, message)
        self.safe_state = safe_state

    def __reduce__(self):
        return (type(self), (self.errno, self.strerror, self.safe_state))


class SensorConfigError(RuntimeError, FirmwareIOError):
    """A TLV493D did not take its configuration (parity rejected, no conversions after config)."""
