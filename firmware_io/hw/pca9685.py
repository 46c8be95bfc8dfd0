"""Driver of the NXP PCA9685 16-channel 12-bit PWM chip (the coil drivers' PWM and DIR lines).

Takes a ``bus`` with :class:`smbus2.SMBus`'s methods (:class:`firmware_io.hw.bus.I2CBus`) and
does one thing per call with as few transactions as the chip allows. Register numbers, byte
layouts and the SLEEP / PRE_SCALE / RESTART sequence are the datasheet's (NXP PCA9685, section
numbers in brackets); the register map and timing are summarized in docs/hardware.md. The pure
helpers :func:`pca9685_prescale` and :func:`pca9685_channel_bytes` carry the arithmetic so it
can be checked on its own.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from typing import Literal

from ..errors import BadInputError
from .bus import I2CBus, wrap_os_error, write_block

PCA9685_MODE1 = 0x00
PCA9685_MODE2 = 0x01
PCA9685_LED0_ON_L = 0x06
PCA9685_ALL_LED_OFF_H = 0xFD
PCA9685_PRE_SCALE = 0xFE
PCA9685_OSCILLATOR_HZ = 25e6
_MODE1_RESTART, _MODE1_AI, _MODE1_SLEEP = 0x80, 0x20, 0x10
_FULL_ON = b"\x00\x10\x00\x00"   # ON_H bit 4
_FULL_OFF = b"\x00\x00\x00\x10"  # OFF_H bit 4 (wins over full ON)

ChannelValue = int | Literal["on", "off"]


def pca9685_prescale(hz: float, reference_clock_hz: float = PCA9685_OSCILLATOR_HZ) -> int:
    """PRE_SCALE for a PWM frequency: ``round(clock / (4096 hz)) - 1``, valid 3..255 [NXP 7.3.5].

    Parameters
    ----------
    hz : float
        Wanted PWM frequency, Hz (about 24..1526 Hz with the 25 MHz oscillator).
    reference_clock_hz : float
        Oscillator frequency, Hz.
    """
    try:
        f = float(hz)
    except (TypeError, ValueError):
        f = math.nan
    lo = reference_clock_hz / (4096.0 * 256.5)
    hi = reference_clock_hz / (4096.0 * 3.5)
    if not (math.isfinite(f) and lo <= f <= hi):
        raise BadInputError("hz", f"in [{lo:.4g}, {hi:.5g}] Hz (PRE_SCALE 3..255)", hz)
    return int(round(reference_clock_hz / (4096.0 * f))) - 1


def pca9685_channel_bytes(value: ChannelValue) -> bytes:
    """``[ON_L, ON_H, OFF_L, OFF_H]`` for a duty count 0..4095, ``'on'`` or ``'off'``.

    A duty d in 1..4095 turns on at count 0 and off at count d (high d/4096 of the period); 0 and
    ``'off'`` use the full-OFF bit and ``'on'`` the full-ON bit, so ON never equals OFF.
    """
    if isinstance(value, str):
        if value == "on":
            return _FULL_ON
        if value == "off":
            return _FULL_OFF
    elif isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= 4095:
        if value == 0:
            return _FULL_OFF
        return bytes([0x00, 0x00, value & 0xFF, value >> 8])
    raise BadInputError("channel value", "an int duty in 0..4095, 'on' or 'off'", value)


class PCA9685:
    """NXP PCA9685 16-channel 12-bit PWM driver.

    Parameters
    ----------
    bus : smbus2.SMBus-like
    address : int
        7-bit address, 0x40..0x7F.
    reference_clock_hz : float
        Oscillator, Hz (25 MHz nominal; measure and set it for an accurate frequency).
    sleep : callable
        ``sleep(seconds)``; the oscillator needs its datasheet start-up time after leaving SLEEP
        (docs/hardware.md).
    """

    def __init__(self, bus: I2CBus, address: int = 0x40, *,
                 reference_clock_hz: float = PCA9685_OSCILLATOR_HZ,
                 sleep: Callable[[float], None] = time.sleep):
        if isinstance(address, bool) or not isinstance(address, int) or not 0x40 <= address <= 0x7F:
            raise BadInputError("address", "a 7-bit PCA9685 address in 0x40..0x7F", address)
        self.bus = bus
        self.address = address
        self.reference_clock_hz = float(reference_clock_hz)
        self.sleep = sleep
        self.prescale: int | None = None
        self.frequency_hz: float | None = None
        # last commanded bytes per channel: channels inside a block write that the caller did not
        # name are rewritten with these, so a partial command never changes them
        self._shadow: list[bytes] = [_FULL_OFF] * 16

    def _name(self) -> str:
        return f"PCA9685 at 0x{self.address:02X}"

    def _write_reg(self, register: int, value: int) -> None:
        try:
            self.bus.write_byte_data(self.address, register, value)
        except OSError as exc:
            raise wrap_os_error(exc, f"{self._name()}: write 0x{value:02X} to register 0x{register:02X}") from exc

    def initialize(self, pwm_frequency_hz: float = 1526.0) -> float:
        """Put the chip in a known state with every output off; return the PWM frequency, Hz.

        MODE1=0x30 (SLEEP, auto-increment, ALLCALL cleared because All-Call 0x70 is also the
        TCA9548A's default address), PRE_SCALE, MODE2=0x04 (totem pole, outputs change on STOP),
        ALL_LED_OFF_H=0x10, MODE1=0x20 (wake), wait past the datasheet's oscillator start-up,
        MODE1=0xA0 (RESTART, a no-op unless an earlier run slept with PWM running).
        """
        p = pca9685_prescale(pwm_frequency_hz, self.reference_clock_hz)
        self._write_reg(PCA9685_MODE1, _MODE1_SLEEP | _MODE1_AI)
        self._write_reg(PCA9685_PRE_SCALE, p)
        self._write_reg(PCA9685_MODE2, 0x04)
        self._write_reg(PCA9685_ALL_LED_OFF_H, 0x10)
        self._write_reg(PCA9685_MODE1, _MODE1_AI)
        self.sleep(1e-3)
        self._write_reg(PCA9685_MODE1, _MODE1_RESTART | _MODE1_AI)
        self._shadow = [_FULL_OFF] * 16
        return self._set_prescale_state(p)

    def _set_prescale_state(self, p: int) -> float:
        self.prescale = p
        self.frequency_hz = self.reference_clock_hz / (4096.0 * (p + 1))
        return self.frequency_hz

    def set_pwm_frequency(self, hz: float) -> float:
        """Set the PWM frequency through the SLEEP / PRE_SCALE / wake / RESTART sequence.

        Returns the frequency actually produced, Hz: ``clock / (4096 (prescale + 1))``.
        """
        p = pca9685_prescale(hz, self.reference_clock_hz)
        try:
            mode1 = self.bus.read_byte_data(self.address, PCA9685_MODE1)
        except OSError as exc:
            raise wrap_os_error(exc, f"{self._name()}: read MODE1") from exc
        old = mode1 & ~_MODE1_RESTART & 0xFF
        awake = (old & ~_MODE1_SLEEP & 0xFF) | _MODE1_AI
        self._write_reg(PCA9685_MODE1, old | _MODE1_SLEEP)  # PRE_SCALE is writable only in SLEEP
        self._write_reg(PCA9685_PRE_SCALE, p)
        self._write_reg(PCA9685_MODE1, awake)
        self.sleep(500e-6)  # oscillator start-up before RESTART [NXP 7.3.1.1]
        self._write_reg(PCA9685_MODE1, awake | _MODE1_RESTART)
        return self._set_prescale_state(p)

    def set_channels(self, values: Mapping[int, ChannelValue]) -> None:
        """Set several channels in ONE bus transaction (they all change at its STOP).

        Parameters
        ----------
        values : mapping channel (0..15) -> duty count 0..4095, ``'on'`` or ``'off'``
            Channels between the lowest and the highest one named but not named themselves keep
            their last commanded value.
        """
        if not isinstance(values, Mapping) or not values:
            raise BadInputError("values", "a non-empty mapping {channel 0..15: 0..4095 | 'on' | 'off'}", values)
        encoded: dict[int, bytes] = {}
        for ch, v in values.items():
            if isinstance(ch, bool) or not isinstance(ch, int) or not 0 <= ch <= 15:
                raise BadInputError("channel", "an int in 0..15", ch)
            encoded[ch] = pca9685_channel_bytes(v)
        lo, hi = min(encoded), max(encoded)
        data = b"".join(encoded.get(ch, self._shadow[ch]) for ch in range(lo, hi + 1))
        try:
            write_block(self.bus, self.address, PCA9685_LED0_ON_L + 4 * lo, data)
        except OSError as exc:
            raise wrap_os_error(exc, f"{self._name()}: write channels {lo}..{hi}") from exc
        for ch, b in encoded.items():
            self._shadow[ch] = b

    def all_off(self) -> None:
        """Every output full OFF in one single-byte write (ALL_LED_OFF_H = 0x10)."""
        self._write_reg(PCA9685_ALL_LED_OFF_H, 0x10)
        self._shadow = [_FULL_OFF] * 16

    def commanded(self, channel: int) -> bytes:
        """The 4 register bytes last commanded for ``channel``."""
        return self._shadow[channel]

