"""Cytron MD10C in sign-magnitude mode: a signed coil voltage or current request -> (PWM duty,
direction).

The MD10C turns its PWM input into the bridge duty and its DIR input into the polarity, so the
coil sees an average voltage of about +-D Vs and settles at I = D Vs / R (inference from
the Cytron MD10C manual's sign-magnitude mode; the coil's L/R must be long against the PWM
period for the ripple Vs D (1 - D) / (L f) to be small). A request is clamped to the smallest
of the coil's limit, the driver's continuous rating and what the supply can push through R.
:class:`CoilDrive` is the one record of a coil's R, L and supply voltage: the runner's
configuration refers to it (firmware_io.runner.config).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..errors import BadInputError

MD10C_SUPPLY_MIN_V = 5.0
MD10C_SUPPLY_MAX_V = 30.0
MD10C_CONTINUOUS_A = 13.0
MD10C_PEAK_A = 30.0           # for 10 s; not used as a steady limit
MD10C_MAX_PWM_HZ = 20e3

#: PCA9685 counts per PWM period; a duty of 4096 counts is the full-ON bit.
PWM_COUNTS = 4096


def _finite(name: str, value: object, valid: str) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise BadInputError(name, valid, value) from None
    if not math.isfinite(v):
        raise BadInputError(name, valid, value)
    return v


@dataclass(frozen=True)
class CoilDrive:
    """Electrical data of one coil on one MD10C.

    Attributes
    ----------
    supply_voltage_v : float
        MD10C motor supply, V (5..30 V rating).
    resistance_ohm : float
        Coil resistance at operating temperature, ohm (> 0).
    current_limit_a : float
        Largest coil current allowed, A (> 0, at most the MD10C's 13 A continuous rating).
    inductance_h : float, optional
        Coil inductance (secant, at the operating current), H (> 0): the L/R lag the runner's
        voltage feed-forward compensates; None when only steady currents are commanded.
    """

    supply_voltage_v: float
    resistance_ohm: float
    current_limit_a: float
    inductance_h: float | None = None

    def __post_init__(self) -> None:
        vs = _finite("supply_voltage_v", self.supply_voltage_v, "in [5, 30] V (MD10C rating)")
        if not MD10C_SUPPLY_MIN_V <= vs <= MD10C_SUPPLY_MAX_V:
            raise BadInputError("supply_voltage_v", "in [5, 30] V (MD10C rating)", self.supply_voltage_v)
        r = _finite("resistance_ohm", self.resistance_ohm, "a finite number > 0 ohm")
        if r <= 0:
            raise BadInputError("resistance_ohm", "a finite number > 0 ohm", self.resistance_ohm)
        lim = _finite("current_limit_a", self.current_limit_a, "in (0, 13] A (MD10C continuous rating)")
        if not 0 < lim <= MD10C_CONTINUOUS_A:
            raise BadInputError("current_limit_a", "in (0, 13] A (MD10C continuous rating)",
                                self.current_limit_a)
        if self.inductance_h is not None:
            ind = _finite("inductance_h", self.inductance_h, "a finite number > 0 H")
            if ind <= 0:
                raise BadInputError("inductance_h", "a finite number > 0 H", self.inductance_h)

    @classmethod
    def supply_limited(cls, supply_voltage_v: float, resistance_ohm: float,
                       inductance_h: float | None = None) -> "CoilDrive":
        """A drive whose current limit is what the supply can push through R (at most the
        MD10C's 13 A): every voltage within the supply can be applied."""
        return cls(supply_voltage_v, resistance_ohm,
                   min(supply_voltage_v / resistance_ohm, MD10C_CONTINUOUS_A), inductance_h)

    @property
    def max_current_a(self) -> float:
        """Largest reachable steady current, A: min(limit, 13 A, Vs / R)."""
        return min(self.current_limit_a, MD10C_CONTINUOUS_A, self.supply_voltage_v / self.resistance_ohm)

    @property
    def max_voltage_v(self) -> float:
        """Largest average voltage a command may apply, V: min(limit R, 13 A R, Vs)."""
        r = self.resistance_ohm
        return min(self.current_limit_a * r, MD10C_CONTINUOUS_A * r, self.supply_voltage_v)


@dataclass(frozen=True)
class DriveCommand:
    """What to put on one MD10C's inputs.

    Attributes
    ----------
    duty_counts : int
        PWM high time in PCA9685 counts, 0..4096 (4096 = always on).
    direction : {'forward', 'reverse'}
        'forward' for a current >= 0 (CytronMotorDriver PWM_DIR: DIR low), 'reverse' for < 0.
    current_a : float
        The current this command produces in steady state, A (signed, after clamping).
    clamped : bool
        True if the request exceeded :attr:`CoilDrive.max_current_a` (resp.
        :attr:`CoilDrive.max_voltage_v`).
    voltage_v : float
        The average voltage the duty applies, V (signed): ``D Vs``.
    """

    duty_counts: int
    direction: Literal["forward", "reverse"]
    current_a: float
    clamped: bool
    voltage_v: float

    @property
    def pwm_value(self) -> int | Literal["on", "off"]:
        """The value for :meth:`PCA9685.set_channels`: 'off', 1..4095 or 'on'."""
        if self.duty_counts <= 0:
            return "off"
        if self.duty_counts >= PWM_COUNTS:
            return "on"
        return self.duty_counts


def current_to_command(current_a: float, drive: CoilDrive) -> DriveCommand:
    """Signed coil current request, A -> MD10C duty and direction.

    ``duty = |I| R / Vs`` quantised to 1/4096 of the period, after clamping ``|I|`` to
    ``drive.max_current_a``. The returned ``current_a`` is the steady current of the quantised
    duty, with the request's sign.
    """
    i = _finite("current_a", current_a, "a finite number, A")
    i_max = drive.max_current_a
    duty = min(abs(i), i_max) * drive.resistance_ohm / drive.supply_voltage_v
    return _duty_command(duty, i < 0, abs(i) > i_max, drive)


def voltage_to_command(voltage_v: float, drive: CoilDrive) -> DriveCommand:
    """Signed average coil voltage request, V -> MD10C duty and direction.

    ``duty = |V| / Vs`` quantised to 1/4096 of the period, after clamping ``|V|`` to
    ``drive.max_voltage_v``; the voltage the runner's feed-forward asks for goes to the output
    stage without a detour through a current.
    """
    v = _finite("voltage_v", voltage_v, "a finite number, V")
    v_max = drive.max_voltage_v
    duty = min(abs(v), v_max) / drive.supply_voltage_v
    return _duty_command(duty, v < 0, abs(v) > v_max, drive)


def _duty_command(duty: float, negative: bool, clamped: bool, drive: CoilDrive) -> DriveCommand:
    """Quantise a duty in [0, 1] to PCA9685 counts; the sign picks the direction."""
    counts = int(round(duty * PWM_COUNTS))
    counts = min(max(counts, 0), PWM_COUNTS)
    applied_v = counts / PWM_COUNTS * drive.supply_voltage_v
    produced = applied_v / drive.resistance_ohm
    direction: Literal["forward", "reverse"] = "reverse" if negative and counts > 0 else "forward"
    sign = -1.0 if direction == "reverse" else 1.0
    return DriveCommand(counts, direction, sign * produced, clamped, sign * applied_v)
