"""Driver of the Infineon TLV493D-A1B6 3D Hall sensor in master-controlled mode.

Reads have no register pointer (raw 6, 7 or 10 byte frames), writes are 4 bytes with an odd
parity bit; the address is latched at a general-call reset from the level on SDA. The pure
helpers :func:`tlv493d_address`, :func:`tlv493d_write_frame` and :func:`tlv493d_decode` carry
the bit layouts of the user manual ([UM], register map in docs/hardware.md) and the datasheet
([DS]) so they can be checked on their own. Each read is checked (:class:`FrameChecks`): the
flags, a frame counter that stopped (an ADC hang), values frozen while the counter runs, and
all-zero values -- a value a sensor reports with an ok frame is not trusted blindly.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from ..errors import BadInputError, I2CError, SensorConfigError
from .bus import I2CBus, raw_read, raw_write, wrap_os_error

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


@dataclass(frozen=True)
class FrameChecks:
    """Debounces of the checks on each read, in reads in a row.

    Attributes
    ----------
    hang_reads : int
        Frame counter unchanged: 'stale' below this, then an ADC hang ('hung' / 'recovered')
        [UM 5.6]. Single repeats are seen in practice, so it is debounced.
    frozen_reads : int
        The frame counter advances but (Bx, By, Bz) repeat the previous read exactly: 'frozen'
        from this many repeats on (0: off). With the datasheet's 0.1 mT rms noise (about one
        LSB) three axes repeat by chance with probability ~0.02 per read, eight in a row
        ~1e-14.
    zero_reads : int
        Bx = By = Bz = 0 exactly: 'zero' from this many reads in a row on (0: off). A sensor in
        a field below one LSB reads 0 on all three axes with probability ~0.06 per read (0.1 mT
        noise), five in a row ~1e-6; in this device the magnet and the coils keep every sensor
        above that.
    """

    hang_reads: int = 3
    frozen_reads: int = 8
    zero_reads: int = 5

    def __post_init__(self):
        for name in ("hang_reads", "frozen_reads", "zero_reads"):
            v = getattr(self, name)
            low = 1 if name == "hang_reads" else 0
            if isinstance(v, bool) or not isinstance(v, int) or v < low:
                raise BadInputError(name, f"an int >= {low} (reads)", v)


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
                       "hung", "frozen", "zero", "nack", "failed", "unconfigured"]


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
    checks : FrameChecks
        Debounces of the hang, frozen-value and zero-value checks.
    reset_wait_s : float
        Wait after the general-call reset, s (default 40e-3: the wake-up time of [INF] and
        [RS]; see docs/hardware.md).
    recover_in_read : bool
        True: a read that finds the ADC hung resets and reconfigures the sensor at once (status
        'recovered'; the read waits ``reset_wait_s``). False: it reports 'hung' and leaves the
        recovery to the caller (:class:`~firmware_io.hw.sensors.SensorArrays` resets it between
        passes, so no read waits).

    Notes
    -----
    The reset is a general call: it resets every TLV493D the bus reaches. Call :meth:`configure`
    with only this sensor's mux channel enabled (:class:`SensorArrays` does).
    """

    def __init__(self, bus: I2CBus, address: int = 0x5E, *,
                 temperature: Literal["off", "on"] = "off", checks: FrameChecks = FrameChecks(),
                 reset_wait_s: float = 40e-3, config_attempts: int = 3,
                 recover_in_read: bool = True, sleep: Callable[[float], None] = time.sleep):
        self.base_address, self.iic_addr_code = _split_address(address)
        if temperature not in ("off", "on"):
            raise BadInputError("temperature", "'off' or 'on'", temperature)
        if not isinstance(checks, FrameChecks):
            raise BadInputError("checks", "a FrameChecks", checks)
        self.bus = bus
        self.address = address
        self.temperature = temperature
        self.read_length = 7 if temperature == "on" else 6
        self.checks = checks
        self.reset_wait_s = float(reset_wait_s)
        self.config_attempts = int(config_attempts)
        self.recover_in_read = bool(recover_in_read)
        self.sleep = sleep
        self.factory: bytes | None = None
        self.status: SensorStatus = "unconfigured"
        self.temperature_c: float | None = None
        self.recoveries = 0
        self.last_frame: TLVFrame | None = None
        self._last_frm: int | None = None
        self._stuck = 0
        self._last_raw: tuple | None = None
        self._same = 0       # reads in a row repeating the previous values (counter running)
        self._zeros = 0      # reads in a row with Bx = By = Bz = 0

    def _name(self) -> str:
        return f"TLV493D at 0x{self.address:02X}"

    def reset(self) -> None:
        """General-call reset (:meth:`start_reset`), then wait ``reset_wait_s``."""
        self.start_reset()
        self.sleep(self.reset_wait_s)

    def start_reset(self) -> None:
        """General-call reset; SDA held at the level that selects this sensor's base address.
        The sensor takes ``reset_wait_s`` to wake up before :meth:`configure_after_reset`.

        The sensor does not acknowledge the data byte, so the NACK error is expected and ignored.
        """
        level_byte = 0xFF if self.base_address == 0x5E else 0x00
        try:
            self.bus.write_byte(0x00, level_byte)
        except OSError:
            pass

    def _read_raw(self, address: int, length: int) -> bytes:
        try:
            return raw_read(self.bus, address, length)
        except OSError as exc:
            raise wrap_os_error(exc, f"TLV493D at 0x{address:02X}: read {length} bytes") from exc

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
            last_problem = self.configure_after_reset()
            if not last_problem:
                return
        self.status = "failed"
        raise SensorConfigError(
            f"{self._name()} did not take its configuration after {self.config_attempts} attempts: "
            f"{last_problem}. Check the sensor's supply (power-cycle it) and that only its mux "
            "channel is enabled.")

    def configure_after_reset(self) -> str:
        """One configuration attempt of a sensor reset ``reset_wait_s`` ago (read the factory
        bytes, write, verify as :meth:`configure` says): '' and status 'ok' when it took, else
        the problem (status unchanged)."""
        try:
            frame = self._read_raw(self.base_address, 10)
            self.factory = frame[7:10]
            cfg = tlv493d_write_frame(self.factory, iic_addr_code=self.iic_addr_code,
                                      temperature=self.temperature)
            try:
                raw_write(self.bus, self.base_address, cfg)
            except OSError as exc:
                raise wrap_os_error(exc, f"TLV493D at 0x{self.base_address:02X}: write configuration") from exc
            first = tlv493d_decode(self._read_raw(self.address, self.read_length))
            second = tlv493d_decode(self._read_raw(self.address, self.read_length))
        except I2CError as exc:
            return str(exc)
        if second.power_down_flag == 1 and second.frame_counter == (first.frame_counter + 1) % 4:
            self._last_frm = second.frame_counter
            # the value checks keep their count: a reset does not mend a frozen data path
            self._stuck = 0
            self.last_frame = second
            self.status = "ok"
            return ""
        return ("no conversion after configuration (frame counter "
                f"{first.frame_counter} -> {second.frame_counter}, PD={second.power_down_flag}):"
                " configuration rejected, e.g. parity")

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
            if self._stuck < self.checks.hang_reads:
                self.status = "stale"
            elif not self.recover_in_read:
                self.status = "hung"  # the caller resets it (its wake-up wait outside a read)
            else:
                # ADC hang-up [UM 5.6]: a frozen frame counter; reset + reconfigure fixes it
                self.configure()
                self.recoveries += 1
                self.status = "recovered"
            return frame
        self._stuck = 0
        self._last_frm = frame.frame_counter
        if frame.temperature_raw is not None:
            self.temperature_c = frame.temperature_c
        self.status = self._value_check(frame) or ("saturated" if frame.saturated else "ok")
        return frame

    def _value_check(self, frame: TLVFrame) -> str:
        """'frozen', 'zero' or '' for a frame whose counter advanced (:class:`FrameChecks`)."""
        raw = (frame.bx_raw, frame.by_raw, frame.bz_raw)
        self._same = self._same + 1 if raw == self._last_raw else 0
        self._zeros = self._zeros + 1 if raw == (0, 0, 0) else 0
        self._last_raw = raw
        c = self.checks
        if c.zero_reads and self._zeros >= c.zero_reads:
            return "zero"
        if c.frozen_reads and self._same >= c.frozen_reads:
            return "frozen"
        return ""

    def read(self) -> tuple[float, float, float]:
        """(Bx, By, Bz), T, of the conversion started by the previous read.

        :attr:`status` tells whether the value is fresh: 'ok'; 'saturated' (an axis at the
        12-bit limit, |B| is at least the value); 'stale' (frame counter did not advance);
        'recovered' (the sensor hung and was reset, the value is stale); 'hung' (the frame
        counter stood still ``checks.hang_reads`` reads in a row and ``recover_in_read`` is
        False: the caller must reset it, the value is stale); 'frozen' (the counter runs but
        the values repeated ``checks.frozen_reads`` times); 'zero' (all three axes 0 in
        ``checks.zero_reads`` reads in a row); 'not_ready' (PD=0 or CH!=0); 'test_mode' (T
        flag set). A NACK raises :class:`I2CError` (status 'nack').
        """
        return self.read_frame().field_t

