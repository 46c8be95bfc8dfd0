"""Chip drivers: PCA9685 (PWM), TLV493D-A1B6 (3D Hall sensor), TCA9548A (I2C switch).

Every driver takes a ``bus`` with :class:`smbus2.SMBus`'s methods (see :mod:`firmware_io.bus`)
and does one thing per call with as few transactions as the chip allows. Register facts, byte
layouts and sequences are those of the chips' datasheets (NXP PCA9685, NXP PCA9548A /
TI TCA9548A, Infineon TLV493D-A1B6 user manual); the pure helpers (:func:`pca9685_prescale`,
:func:`pca9685_channel_bytes`, :func:`tlv493d_write_frame`, :func:`tlv493d_decode`) carry them
so they can be checked on their own.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Literal

from .bus import I2CBus, raw_read, raw_write, write_block
from .errors import BadInputError, I2CError, SensorConfigError

# ---------------------------------------------------------------------------------------------
# PCA9685

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


def _wrap(exc: OSError, what: str) -> I2CError:
    reason = exc.strerror or str(exc)
    code = exc.errno
    hint = " (no acknowledge: check wiring, address and power)" if code == 121 else ""
    return I2CError(code, f"{what} failed: {reason}{hint}")


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
        ``sleep(seconds)``; the oscillator needs >= 500 us after leaving SLEEP.
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
            raise _wrap(exc, f"{self._name()}: write 0x{value:02X} to register 0x{register:02X}") from exc

    def initialize(self, pwm_frequency_hz: float = 1526.0) -> float:
        """Put the chip in a known state with every output off; return the PWM frequency, Hz.

        MODE1=0x30 (SLEEP, auto-increment, ALLCALL cleared because All-Call 0x70 is also the
        TCA9548A's default address), PRE_SCALE, MODE2=0x04 (totem pole, outputs change on STOP),
        ALL_LED_OFF_H=0x10, MODE1=0x20 (wake), wait 1 ms, MODE1=0xA0 (RESTART, a no-op unless
        an earlier session slept with PWM running).
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
            raise _wrap(exc, f"{self._name()}: read MODE1") from exc
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
            raise _wrap(exc, f"{self._name()}: write channels {lo}..{hi}") from exc
        for ch, b in encoded.items():
            self._shadow[ch] = b

    def all_off(self) -> None:
        """Every output full OFF in one single-byte write (ALL_LED_OFF_H = 0x10)."""
        self._write_reg(PCA9685_ALL_LED_OFF_H, 0x10)
        self._shadow = [_FULL_OFF] * 16

    def commanded(self, channel: int) -> bytes:
        """The 4 register bytes last commanded for ``channel``."""
        return self._shadow[channel]


# ---------------------------------------------------------------------------------------------
# TCA9548A


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
            raise _wrap(exc, f"TCA9548A at 0x{self.address:02X}: set channel mask 0x{mask:02X}") from exc
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
            raise _wrap(exc, f"TCA9548A at 0x{self.address:02X}: read channel mask") from exc


# ---------------------------------------------------------------------------------------------
# TLV493D-A1B6

TLV493D_LSB_T = 0.098e-3          # T per LSB of the 12-bit field values [DS]
TLV493D_LINEAR_RANGE_T = 0.130    # +-130 mT linear range [DS]
TLV493D_T25_RAW = 340             # temperature count at 25 degC [UM 3.2] (device specific)
TLV493D_TEMP_K_PER_LSB = 1.1
TLV493D_BASE_ADDRESSES = (0x5E, 0x1F)

TLVMode = Literal["master_controlled", "fast", "low_power", "ultra_low_power", "power_down"]
_MODE_BITS = {"power_down": (0, 0, 0), "fast": (1, 0, 0), "low_power": (0, 1, 1),
              "ultra_low_power": (0, 1, 0), "master_controlled": (1, 1, 0)}  # FAST, LOW, LP


def tlv493d_address(base: int, iic_addr_code: int) -> int:
    """Address after MOD1.IICAddr = ``iic_addr_code`` (0..3) from base 0x5E or 0x1F [UM Table 6]."""
    return base ^ (((iic_addr_code << 3) | (iic_addr_code << 2)) & 0x14)


def _split_address(address: int) -> tuple[int, int]:
    for base in TLV493D_BASE_ADDRESSES:
        for code in range(4):
            if tlv493d_address(base, code) == address:
                return base, code
    valid = ", ".join(f"0x{tlv493d_address(b, c):02X}" for b in TLV493D_BASE_ADDRESSES for c in range(4))
    raise BadInputError("address", f"one of the TLV493D addresses {valid}", address)


def tlv493d_write_frame(factory: bytes, *, iic_addr_code: int = 0,
                        mode: TLVMode = "master_controlled",
                        interrupt: Literal["off", "on"] = "off",
                        temperature: Literal["off", "on"] = "off",
                        parity_test: Literal["on", "off"] = "on") -> bytes:
    """The 4 bytes written to a TLV493D: ``[0x00, MOD1, byte8, MOD2]`` with odd parity.

    Parameters
    ----------
    factory : bytes, length >= 3
        Read bytes 7, 8, 9 (bits 4:3 of byte 7, byte 8 and bits 4:0 of byte 9 are copied).
    iic_addr_code : int
        MOD1.IICAddr (0..3).

    Notes
    -----
    MOD1 = P b7 | IICAddr b6:5 | factory b4:3 | INT b2 | FAST b1 | LOW b0;
    MOD2 = T b7 (1 = temperature off) | LP b6 | PT b5 | factory b4:0. P makes the number of
    ones in the 32 bits odd.
    """
    fast, low, lp = _MODE_BITS[mode]
    mod1 = ((iic_addr_code & 0x3) << 5 | (factory[0] & 0x18) | (interrupt == "on") << 2
            | fast << 1 | low)
    mod2 = ((temperature == "off") << 7 | lp << 6 | (parity_test == "on") << 5
            | (factory[2] & 0x1F))
    body = bytes([0x00, mod1, factory[1], mod2])
    ones = sum(bin(b).count("1") for b in body)
    if ones % 2 == 0:
        mod1 |= 0x80
    return bytes([0x00, mod1, factory[1], mod2])


def _s12(v: int) -> int:
    return v - 4096 if v & 0x800 else v


@dataclass(frozen=True)
class TLVFrame:
    """A decoded TLV493D read frame (raw 12-bit counts and flags)."""

    bx_raw: int
    by_raw: int
    bz_raw: int
    temperature_raw: int | None  # None when byte 6 was not read
    frame_counter: int
    channel: int
    power_down_flag: int
    test_flag: int
    fuse_flag: int

    @property
    def field_t(self) -> tuple[float, float, float]:
        """(Bx, By, Bz), T: counts times 0.098 mT."""
        return (self.bx_raw * TLV493D_LSB_T, self.by_raw * TLV493D_LSB_T, self.bz_raw * TLV493D_LSB_T)

    @property
    def temperature_c(self) -> float | None:
        """Die temperature, degC: (raw - 340) * 1.1 + 25 (offset 340 is device specific)."""
        if self.temperature_raw is None:
            return None
        return (self.temperature_raw - TLV493D_T25_RAW) * TLV493D_TEMP_K_PER_LSB + 25.0

    @property
    def saturated(self) -> bool:
        """True if any axis sits at the 12-bit limit (-2048 or +2047): a lower bound only."""
        return any(v in (-2048, 2047) for v in (self.bx_raw, self.by_raw, self.bz_raw))


def tlv493d_decode(frame: bytes) -> TLVFrame:
    """Decode the first 6, 7 or 10 bytes read from a TLV493D [UM register map].

    Bx = b0<<4 | b4>>4, By = b1<<4 | b4&15, Bz = b2<<4 | b5&15, T = (b3&0xF0)<<4 | b6, all 12-bit
    two's complement; FRM = b3 bits 3:2, CH = b3 bits 1:0, T-flag b5.6, FF b5.5, PD b5.4.
    """
    if len(frame) < 6:
        raise BadInputError("frame", "at least 6 bytes read from a TLV493D", bytes(frame))
    b = frame
    temp = _s12(((b[3] & 0xF0) << 4) | b[6]) if len(b) >= 7 else None
    return TLVFrame(
        bx_raw=_s12((b[0] << 4) | (b[4] >> 4)),
        by_raw=_s12((b[1] << 4) | (b[4] & 0x0F)),
        bz_raw=_s12((b[2] << 4) | (b[5] & 0x0F)),
        temperature_raw=temp,
        frame_counter=(b[3] >> 2) & 0x3,
        channel=b[3] & 0x3,
        power_down_flag=(b[5] >> 4) & 1,
        test_flag=(b[5] >> 6) & 1,
        fuse_flag=(b[5] >> 5) & 1,
    )


SensorStatus = Literal["ok", "saturated", "stale", "not_ready", "test_mode", "recovered",
                       "nack", "failed", "unconfigured"]


class TLV493D:
    """Infineon TLV493D-A1B6 3D Hall sensor in master-controlled mode.

    Parameters
    ----------
    bus : smbus2.SMBus-like
    address : int
        Address after configuration: 0x5E (default), 0x5A, 0x4E, 0x4A, or 0x1F, 0x1B, 0x0F, 0x0B
        (reset level low). The reset drives SDA to the matching level.
    temperature : {'off', 'on'}
        'off' (recommended) reads 6 bytes per frame; 'on' reads 7 and fills ``temperature_c``.
    hang_threshold : int
        Consecutive reads with an unchanged frame counter before the sensor is reset and
        reconfigured (the check is debounced because single repeats are seen in practice).
    reset_wait_s : float
        Wait after the general-call reset, s (40 ms as [INF] and [RS]).

    Notes
    -----
    The reset is a general call: it resets every TLV493D the bus reaches. Call :meth:`configure`
    with only this sensor's mux channel enabled (:class:`SensorArrays` does).
    """

    def __init__(self, bus: I2CBus, address: int = 0x5E, *,
                 temperature: Literal["off", "on"] = "off", hang_threshold: int = 3,
                 reset_wait_s: float = 40e-3, config_attempts: int = 3,
                 sleep: Callable[[float], None] = time.sleep):
        self.base_address, self.iic_addr_code = _split_address(address)
        if temperature not in ("off", "on"):
            raise BadInputError("temperature", "'off' or 'on'", temperature)
        if isinstance(hang_threshold, bool) or not isinstance(hang_threshold, int) or hang_threshold < 1:
            raise BadInputError("hang_threshold", "an int >= 1", hang_threshold)
        self.bus = bus
        self.address = address
        self.temperature = temperature
        self.read_length = 7 if temperature == "on" else 6
        self.hang_threshold = hang_threshold
        self.reset_wait_s = float(reset_wait_s)
        self.config_attempts = int(config_attempts)
        self.sleep = sleep
        self.factory: bytes | None = None
        self.status: SensorStatus = "unconfigured"
        self.temperature_c: float | None = None
        self.recoveries = 0
        self.last_frame: TLVFrame | None = None
        self._last_frm: int | None = None
        self._stuck = 0

    def _name(self) -> str:
        return f"TLV493D at 0x{self.address:02X}"

    def reset(self) -> None:
        """General-call reset; SDA held at the level that selects this sensor's base address.

        The sensor does not acknowledge the data byte, so the NACK error is expected and ignored.
        """
        level_byte = 0xFF if self.base_address == 0x5E else 0x00
        try:
            self.bus.write_byte(0x00, level_byte)
        except OSError:
            pass
        self.sleep(self.reset_wait_s)

    def _read_raw(self, address: int, length: int) -> bytes:
        try:
            return raw_read(self.bus, address, length)
        except OSError as exc:
            raise _wrap(exc, f"TLV493D at 0x{address:02X}: read {length} bytes") from exc

    def configure(self) -> None:
        """Reset, read the factory bytes, write the master-controlled configuration, verify.

        Verification: in master-controlled mode each read starts one conversion, so of two
        reads the second must show PD=1 and a frame counter one higher. A configuration the
        sensor rejected (wrong parity) leaves it powered down and fails this test; the whole
        sequence is retried ``config_attempts`` times before :class:`SensorConfigError`.
        """
        last_problem = ""
        for _ in range(self.config_attempts):
            self.reset()
            try:
                frame = self._read_raw(self.base_address, 10)
                self.factory = frame[7:10]
                cfg = tlv493d_write_frame(self.factory, iic_addr_code=self.iic_addr_code,
                                          temperature=self.temperature)
                try:
                    raw_write(self.bus, self.base_address, cfg)
                except OSError as exc:
                    raise _wrap(exc, f"TLV493D at 0x{self.base_address:02X}: write configuration") from exc
                first = tlv493d_decode(self._read_raw(self.address, self.read_length))
                second = tlv493d_decode(self._read_raw(self.address, self.read_length))
            except I2CError as exc:
                last_problem = str(exc)
                continue
            if second.power_down_flag == 1 and second.frame_counter == (first.frame_counter + 1) % 4:
                self._last_frm = second.frame_counter
                self._stuck = 0
                self.last_frame = second
                self.status = "ok"
                return
            last_problem = ("no conversion after configuration (frame counter "
                            f"{first.frame_counter} -> {second.frame_counter}, PD={second.power_down_flag}):"
                            " configuration rejected, e.g. parity")
        self.status = "failed"
        raise SensorConfigError(
            f"{self._name()} did not take its configuration after {self.config_attempts} attempts: "
            f"{last_problem}. Check the sensor's supply (power-cycle it) and that only its mux "
            "channel is enabled.")

    def read_frame(self) -> TLVFrame:
        """Read and check one frame; updates :attr:`status` (see :meth:`read`)."""
        try:
            frame = tlv493d_decode(self._read_raw(self.address, self.read_length))
        except I2CError:
            self.status = "nack"
            raise
        self.last_frame = frame
        if frame.test_flag:
            self.status = "test_mode"
            return frame
        if frame.channel != 0 or frame.power_down_flag != 1:
            self.status = "not_ready"
            return frame
        if self._last_frm is not None and frame.frame_counter == self._last_frm:
            self._stuck += 1
            if self._stuck >= self.hang_threshold:
                # ADC hang-up [UM 5.6]: a frozen frame counter; reset + reconfigure fixes it
                self.configure()
                self.recoveries += 1
                self.status = "recovered"
            else:
                self.status = "stale"
            return frame
        self._stuck = 0
        self._last_frm = frame.frame_counter
        if frame.temperature_raw is not None:
            self.temperature_c = frame.temperature_c
        self.status = "saturated" if frame.saturated else "ok"
        return frame

    def read(self) -> tuple[float, float, float]:
        """(Bx, By, Bz), T, of the conversion started by the previous read.

        :attr:`status` tells whether the value is fresh: 'ok'; 'saturated' (an axis at the
        12-bit limit, |B| is at least the value); 'stale' (frame counter did not advance);
        'recovered' (the sensor hung and was reset, the value is stale); 'not_ready' (PD=0 or
        CH!=0); 'test_mode' (T flag set). A NACK raises :class:`I2CError` (status 'nack').
        """
        return self.read_frame().field_t


__all__ = [
    "PCA9685", "TCA9548A", "TLV493D", "TLVFrame", "pca9685_prescale", "pca9685_channel_bytes",
    "tlv493d_write_frame", "tlv493d_decode", "tlv493d_address", "TLV493D_LSB_T",
]
