"""Register-level simulated PCA9685 (16-channel 12-bit PWM), as the driver sees the chip.

Register file with auto-increment (0x45 wraps to 0x00), PRE_SCALE writable only while SLEEP=1
(minimum 3), All-Call at 0x70 while MODE1.ALLCALL=1, ALL_LED registers writing every channel,
full-on / full-off bits (OFF wins), outputs latched at STOP (MODE2.OCH=0), SWRST by general call
0x06, and the datasheet's oscillator start-up wait before RESTART checked against the bus clock
(NXP PCA9685 datasheet; docs/hardware.md).
"""

from __future__ import annotations

from typing import Literal

from .device import SimDevice

MODE1, MODE2, SUBADR1, SUBADR2, SUBADR3, ALLCALLADR = 0x00, 0x01, 0x02, 0x03, 0x04, 0x05
LED0_ON_L, ALL_LED_ON_L, ALL_LED_OFF_H, PRE_SCALE, TESTMODE = 0x06, 0xFA, 0xFD, 0xFE, 0xFF
_RESTART, _AI, _SLEEP, _SUB1, _SUB2, _SUB3, _ALLCALL = 0x80, 0x20, 0x10, 0x08, 0x04, 0x02, 0x01


class SimPCA9685(SimDevice):
    """Register-level PCA9685 (16-channel 12-bit PWM).

    Parameters
    ----------
    address : int
        7-bit address set by A5..A0 (0x40..0x7F).
    oscillator_hz : float
        Internal oscillator, Hz (25 MHz nominal; real parts are untrimmed).
    """

    def __init__(self, address: int = 0x40, oscillator_hz: float = 25e6):
        super().__init__()
        self.address = address
        self.oscillator_hz = oscillator_hz
        self.output_enable_high = False  # the OE pin: high = hardware kill
        self.power_on_reset()

    def power_on_reset(self) -> None:
        self.regs = bytearray(256)
        self.regs[MODE1] = 0x11  # SLEEP | ALLCALL
        self.regs[MODE2] = 0x04
        self.regs[SUBADR1], self.regs[SUBADR2], self.regs[SUBADR3] = 0xE2, 0xE4, 0xE8
        self.regs[ALLCALLADR] = 0xE0
        for n in range(16):
            self.regs[LED0_ON_L + 4 * n + 3] = 0x10  # full OFF at power-up
        self.regs[PRE_SCALE] = 0x1E
        self.pointer = 0
        self._woke_at: float | None = None
        self._latched = bytes(self.regs[LED0_ON_L:LED0_ON_L + 64])

    # -- bus side --------------------------------------------------------------------------
    def responds_to(self, addr: int) -> bool:
        m = self.regs[MODE1]
        return (addr == self.address
                or (bool(m & _ALLCALL) and addr == self.regs[ALLCALLADR] >> 1)
                or (bool(m & _SUB1) and addr == self.regs[SUBADR1] >> 1)
                or (bool(m & _SUB2) and addr == self.regs[SUBADR2] >> 1)
                or (bool(m & _SUB3) and addr == self.regs[SUBADR3] >> 1))

    def _advance(self) -> None:
        if self.regs[MODE1] & _AI:
            self.pointer = 0x00 if self.pointer == 0x45 else (self.pointer + 1) & 0xFF

    def on_write(self, addr: int, data: bytes) -> None:
        if not data:
            return
        self.pointer = data[0]
        for value in data[1:]:
            self._write_register(self.pointer, value)
            self._advance()

    def on_read(self, addr: int, length: int) -> bytes:
        out = bytearray()
        for _ in range(length):
            reg = self.pointer
            out.append(0 if ALL_LED_ON_L <= reg <= ALL_LED_OFF_H else self.regs[reg])
            self._advance()
        return bytes(out)

    def on_general_call(self, data: bytes) -> bool:
        if bytes(data) == b"\x06":  # SWRST
            self.power_on_reset()
            return True
        return False

    def on_stop(self) -> None:
        if not self.regs[MODE2] & 0x08:  # OCH=0: outputs change on STOP
            self._latch()

    def _latch(self) -> None:
        self._latched = bytes(self.regs[LED0_ON_L:LED0_ON_L + 64])
        for n in range(16):
            on_l, on_h, off_l, off_h = self._latched[4 * n:4 * n + 4]
            if not (on_h & 0x10 or off_h & 0x10):
                if (on_l | (on_h & 0x0F) << 8) == (off_l | (off_h & 0x0F) << 8):
                    self.violations.append(f"channel {n}: ON count equals OFF count")

    def _write_register(self, reg: int, value: int) -> None:
        if reg == MODE1:
            old = self.regs[MODE1]
            new = value & 0x7F
            if value & _RESTART and old & _RESTART:
                # writing 1 to a set RESTART clears it and restarts the PWM channels
                if self._woke_at is not None and self.clock() - self._woke_at < 500e-6:
                    self.violations.append("RESTART written < 500 us after leaving SLEEP")
            elif old & _RESTART:
                new |= _RESTART
            if new & _SLEEP and not old & _SLEEP and self._any_active():
                new |= _RESTART
            if old & _SLEEP and not new & _SLEEP:
                self._woke_at = self.clock()
            self.regs[MODE1] = new
        elif ALL_LED_ON_L <= reg <= ALL_LED_OFF_H:
            for n in range(16):
                self.regs[LED0_ON_L + 4 * n + (reg - ALL_LED_ON_L)] = value
        elif reg == PRE_SCALE:
            if self.regs[MODE1] & _SLEEP:
                self.regs[PRE_SCALE] = max(value, 3)
            else:
                self.violations.append("PRE_SCALE written while awake (ignored by the chip)")
        elif reg == TESTMODE:
            self.violations.append("register 0xFF (test mode) written")
        elif 0x46 <= reg <= 0xF9:
            pass  # reserved
        else:
            self.regs[reg] = value

    def _any_active(self) -> bool:
        return any(self.duty(n) > 0 for n in range(16))

    # -- observation -----------------------------------------------------------------------
    @property
    def prescale(self) -> int:
        return self.regs[PRE_SCALE]

    @property
    def frequency_hz(self) -> float:
        """PWM frequency, Hz: oscillator / (4096 (prescale + 1))."""
        return self.oscillator_hz / (4096.0 * (self.prescale + 1))

    def channel_bytes(self, channel: int) -> bytes:
        """``[ON_L, ON_H, OFF_L, OFF_H]`` of ``channel`` as held in the register file."""
        base = LED0_ON_L + 4 * channel
        return bytes(self.regs[base:base + 4])

    def duty(self, channel: int) -> float:
        """Fraction of the PWM period the output is high (after STOP latching, SLEEP and OE)."""
        m = self.regs[MODE1]
        if m & _SLEEP or m & _RESTART or self.output_enable_high:
            return 0.0
        on_l, on_h, off_l, off_h = self._latched[4 * channel:4 * channel + 4]
        if off_h & 0x10:
            d = 0.0
        elif on_h & 0x10:
            d = 1.0
        else:
            on = on_l | (on_h & 0x0F) << 8
            off = off_l | (off_h & 0x0F) << 8
            d = ((off - on) % 4096) / 4096.0
        return 1.0 - d if self.regs[MODE2] & 0x10 else d

    def level(self, channel: int) -> Literal["low", "high", "pwm"]:
        d = self.duty(channel)
        return "low" if d == 0.0 else ("high" if d == 1.0 else "pwm")
