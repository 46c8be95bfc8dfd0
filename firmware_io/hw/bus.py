"""The bus interface firmware_io talks to, the real-bus opener and wire-time arithmetic.

A *bus* is anything with :class:`smbus2.SMBus`'s methods: a real ``smbus2.SMBus`` (see
:func:`open_bus`), :class:`firmware_io.hw.sim.SimBus`, or a test fake. Drivers use only the methods
listed in :class:`I2CBus`.

Raw transfers (TLV493D reads have no register pointer; PCA9685 writes of more than 32 data bytes
exceed SMBus block limits) go through ``i2c_rdwr`` with ``smbus2.i2c_msg`` objects. smbus2 is
imported lazily, on first use: when it is not installed (a pure simulation host), a ctypes
structure with the kernel's ``struct i2c_msg`` layout and the same ``read``/``write`` factories
takes its place, which the simulated bus accepts too.
"""

from __future__ import annotations

import ctypes
from collections.abc import Sequence
from typing import Any, Protocol

from ..errors import BadInputError, I2CError

#: i2c_msg flag for a read message (uapi/linux/i2c.h I2C_M_RD).
I2C_M_RD = 0x0001

MESSAGE_BUFFER_TYPES = tuple(ctypes.c_char * n for n in range(1, 66))
"""The ctypes array types of every message buffer up to 65 bytes (a PCA9685 register byte and
all 16 channels' 64), held for the life of the process. ``i2c_msg.read``/``write`` build
their buffer with ``ctypes.create_string_buffer``, and ctypes caches an array type only while
something else holds it: without this, every raw transfer made a new type (slow to make, and
a reference cycle, so garbage only the cyclic collector frees -- work that lands in a control
step)."""


class I2CBus(Protocol):
    """The subset of :class:`smbus2.SMBus` that firmware_io uses."""

    def write_byte(self, i2c_addr: int, value: int, force: bool | None = None) -> None: ...

    def read_byte(self, i2c_addr: int, force: bool | None = None) -> int: ...

    def write_byte_data(self, i2c_addr: int, register: int, value: int,
                        force: bool | None = None) -> None: ...

    def read_byte_data(self, i2c_addr: int, register: int, force: bool | None = None) -> int: ...

    def write_i2c_block_data(self, i2c_addr: int, register: int, data: Sequence[int],
                             force: bool | None = None) -> None: ...

    def i2c_rdwr(self, *i2c_msgs: Any) -> None: ...


class _FallbackI2cMsg(ctypes.Structure):
    """Same layout and factories as ``smbus2.i2c_msg``; used only when smbus2 is missing."""

    _fields_ = [("addr", ctypes.c_uint16), ("flags", ctypes.c_uint16),
                ("len", ctypes.c_uint16), ("buf", ctypes.POINTER(ctypes.c_char))]

    def __len__(self) -> int:
        return self.len

    def __bytes__(self) -> bytes:
        return ctypes.string_at(self.buf, self.len)

    def __iter__(self):
        return iter(bytes(self))

    @staticmethod
    def read(address: int, length: int) -> "_FallbackI2cMsg":
        arr = ctypes.create_string_buffer(length)
        # assigning the array to the pointer field keeps it alive in the structure's _objects
        return _FallbackI2cMsg(addr=address, flags=I2C_M_RD, len=length, buf=arr)

    @staticmethod
    def write(address: int, buf: Sequence[int] | bytes) -> "_FallbackI2cMsg":
        data = bytes(buf)
        arr = ctypes.create_string_buffer(data, len(data))
        return _FallbackI2cMsg(addr=address, flags=0, len=len(data), buf=arr)


_MSG_CLASS: Any = None


def i2c_msg_class() -> Any:
    """``smbus2.i2c_msg`` if smbus2 is installed, else the layout-compatible fallback."""
    global _MSG_CLASS
    if _MSG_CLASS is None:
        try:
            from smbus2 import i2c_msg  # lazy: the simulation host may not have smbus2
        except ImportError:
            i2c_msg = _FallbackI2cMsg
        _MSG_CLASS = i2c_msg
    return _MSG_CLASS


def raw_write(bus: I2CBus, address: int, data: Sequence[int] | bytes) -> None:
    """One START, address+W, ``data``, STOP (no SMBus framing, any length)."""
    bus.i2c_rdwr(i2c_msg_class().write(address, bytes(data)))


def raw_read(bus: I2CBus, address: int, length: int) -> bytes:
    """One START, address+R, ``length`` bytes, STOP (no register pointer written first)."""
    msg = i2c_msg_class().read(address, length)
    bus.i2c_rdwr(msg)
    return bytes(msg)


def write_block(bus: I2CBus, address: int, register: int, data: Sequence[int] | bytes) -> None:
    """Write ``[register] + data`` in one transaction, via SMBus block write up to 32 data bytes
    (what every adapter supports) and ``i2c_rdwr`` above that."""
    payload = bytes(data)
    if len(payload) <= 32:
        bus.write_i2c_block_data(address, register, list(payload))
    else:
        raw_write(bus, address, bytes([register]) + payload)


def wrap_os_error(exc: OSError, what: str) -> I2CError:
    """The :class:`I2CError` a driver raises for a failed transfer: ``what`` failed, the bus's
    reason and errno, and a wiring hint on a NACK (errno 121)."""
    reason = exc.strerror or str(exc)
    code = exc.errno
    hint = " (no acknowledge: check wiring, address and power)" if code == 121 else ""
    return I2CError(code, f"{what} failed: {reason}{hint}")


def open_bus(bus: int | str) -> Any:
    """Open a real Linux I2C adapter: ``open_bus(1)`` or ``open_bus("/dev/i2c-1")``.

    Returns
    -------
    smbus2.SMBus
        Close it with ``.close()`` or use it as a context manager.
    """
    if isinstance(bus, bool) or not isinstance(bus, (int, str)):
        raise BadInputError("bus", "an adapter number (int >= 0) or a path like '/dev/i2c-1'", bus)
    if isinstance(bus, int) and bus < 0:
        raise BadInputError("bus", "an adapter number (int >= 0) or a path like '/dev/i2c-1'", bus)
    try:
        import smbus2
    except ImportError:
        raise ImportError("firmware_io.hw.bus.open_bus needs smbus2: pip install smbus2") from None
    return smbus2.SMBus(bus)


def transaction_bits(message_lengths: Sequence[int]) -> int:
    """SCL clock periods of one STOP-terminated transaction.

    Every byte (the address byte included) takes 9 clocks (8 data + ACK); START and STOP take
    about one each, and each repeated START about one more (NXP UM10204, I2C-bus spec, 3.1).

    Parameters
    ----------
    message_lengths : sequence of int
        Data bytes of each message of the transaction (address byte not counted).
    """
    n = len(message_lengths)
    return sum(9 * (length + 1) for length in message_lengths) + 2 + max(n - 1, 0)


def transaction_wire_time_s(message_lengths: Sequence[int], scl_hz: float) -> float:
    """Wire time of one transaction, s: ``transaction_bits / scl_hz``."""
    return transaction_bits(message_lengths) / float(scl_hz)
