"""A sign-magnitude motor driver (PWM = magnitude, DIR = direction), named by its ratings: a
signed coil voltage or current request -> (PWM duty, direction).

The driver turns its PWM input into the bridge duty and its DIR input into the polarity, so the
coil sees an average voltage of about +-D Vs and settles at I = D Vs / R (inference from the
Cytron MD10C manual's sign-magnitude mode; the coil's L/R must be long against the PWM period
for the ripple Vs D (1 - D) / (L f) to be small). :class:`DriverRating` is the driver the design
names (its voltage range, continuous current and PWM input limit; :data:`MD10C` the default
preset) and the one place its limits are applied: which supply it may take, what current it
and the supply can push through a coil. :class:`CoilDrive` is the one record of a coil's R, L,
supply and driver: the runner's configuration refers to it (firmware_io.runner.config).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ..errors import BadInputError

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
class DriverRating:
    """A coil driver by its ratings (the design's ``drive.driver*`` keys).

    Attributes
    ----------
    name : str
        What the design calls it (messages name it).
    min_voltage_v, max_voltage_v : float
        The motor-supply range it is rated for, V.
    continuous_current_a : float
        Its continuous output current, A: the largest steady coil current it is asked for.
    max_pwm_frequency_hz : float
        The highest PWM input frequency it follows, Hz.
    """

    name: str = "Cytron MD10C"
    min_voltage_v: float = 5.0
    max_voltage_v: float = 30.0
    continuous_current_a: float = 13.0
    max_pwm_frequency_hz: float = 20e3

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.strip():
            raise BadInputError("driver", "a non-empty name", self.name)
        lo = _finite("driver_min_voltage_v", self.min_voltage_v, "a finite voltage >= 0 V")
        hi = _finite("driver_max_voltage_v", self.max_voltage_v,
                     f"a finite voltage > driver_min_voltage_v ({lo:g} V)")
        if lo < 0:
            raise BadInputError("driver_min_voltage_v", "a finite voltage >= 0 V",
                                self.min_voltage_v)
        if hi <= lo:
            raise BadInputError("driver_max_voltage_v", f"> driver_min_voltage_v ({lo:g} V)",
                                self.max_voltage_v)
        for key, value, unit in (("driver_continuous_current_a", self.continuous_current_a, "A"),
                                 ("driver_max_pwm_frequency_hz", self.max_pwm_frequency_hz, "Hz")):
            if not _finite(key, value, f"a finite value > 0 {unit}") > 0:
                raise BadInputError(key, f"a finite value > 0 {unit}", value)

    def supply_violation(self, supply_voltage_v: float) -> str:
        """'' when the driver is rated for ``supply_voltage_v`` (V), else the sentence naming the
        design keys (the rule ``designkit check`` reports and the hardware runner refuses)."""
        vs = float(supply_voltage_v)
        if self.min_voltage_v <= vs <= self.max_voltage_v:
            return ""
        side = "above" if vs > self.max_voltage_v else "below"
        return (f"drive.supply_voltage_v = {vs:g} V is {side} the rating of the driver "
                f"{self.name!r} (drive.driver_min_voltage_v .. drive.driver_max_voltage_v = "
                f"{self.min_voltage_v:g} .. {self.max_voltage_v:g} V)")

    def usable_supply_v(self, supply_voltage_v: float) -> float:
        """The largest supply this driver may be given out of ``supply_voltage_v`` (V): the
        supply itself when within the rating, else the rating (what a coil is designed for)."""
        return min(float(supply_voltage_v), self.max_voltage_v)

    def max_current_a(self, supply_voltage_v: float, resistance_ohm: float) -> float:
        """Largest steady coil current, A: what the supply pushes through R, at most the
        continuous rating."""
        return min(supply_voltage_v / resistance_ohm, self.continuous_current_a)


MD10C = DriverRating()
"""The Cytron MD10C (5-30 V, 13 A continuous, PWM input up to 20 kHz): the default driver."""


@dataclass(frozen=True)
class CoilDrive:
    """Electrical data of one coil on its driver.

    Attributes
    ----------
    supply_voltage_v : float
        The driver's motor supply, V (> 0): the voltage the coil sees at full duty. Whether
        the driver is rated for it is :meth:`DriverRating.supply_violation`'s question.
    resistance_ohm : float
        Coil resistance at operating temperature, ohm (> 0).
    current_limit_a : float
        Largest coil current allowed, A (> 0, at most the driver's continuous rating).
    inductance_h : float, optional
        Coil inductance (secant, at the operating current), H (> 0): the L/R lag the runner's
        voltage feed-forward compensates; None when only steady currents are commanded.
    driver : DriverRating
        The driver (default :data:`MD10C`).
    """

    supply_voltage_v: float
    resistance_ohm: float
    current_limit_a: float
    inductance_h: float | None = None
    driver: DriverRating = MD10C

    def __post_init__(self) -> None:
        vs = _finite("supply_voltage_v", self.supply_voltage_v, "a finite voltage > 0 V")
        if vs <= 0:
            raise BadInputError("supply_voltage_v", "a finite voltage > 0 V", self.supply_voltage_v)
        r = _finite("resistance_ohm", self.resistance_ohm, "a finite number > 0 ohm")
        if r <= 0:
            raise BadInputError("resistance_ohm", "a finite number > 0 ohm", self.resistance_ohm)
        cont = self.driver.continuous_current_a
        valid = f"in (0, {cont:g}] A ({self.driver.name} continuous rating)"
        lim = _finite("current_limit_a", self.current_limit_a, valid)
        if not 0 < lim <= cont:
            raise BadInputError("current_limit_a", valid, self.current_limit_a)
        if self.inductance_h is not None:
            ind = _finite("inductance_h", self.inductance_h, "a finite number > 0 H")
            if ind <= 0:
                raise BadInputError("inductance_h", "a finite number > 0 H", self.inductance_h)

    @classmethod
    def supply_limited(cls, supply_voltage_v: float, resistance_ohm: float,
                       inductance_h: float | None = None,
                       driver: DriverRating = MD10C) -> "CoilDrive":
        """A drive whose current limit is what the supply can push through R (at most the
        driver's continuous rating): every voltage within the supply can be applied."""
        return cls(supply_voltage_v, resistance_ohm,
                   driver.max_current_a(supply_voltage_v, resistance_ohm), inductance_h, driver)

    @property
    def max_current_a(self) -> float:
        """Largest reachable steady current, A: min(limit, the driver's continuous rating,
        Vs / R)."""
        return min(self.current_limit_a,
                   self.driver.max_current_a(self.supply_voltage_v, self.resistance_ohm))

    @property
    def max_voltage_v(self) -> float:
        """Largest average voltage a command may apply, V: the largest current's I R, at
        most Vs."""
        return min(self.max_current_a * self.resistance_ohm, self.supply_voltage_v)


@dataclass(frozen=True)
class DriveCommand:
    """What to put on one driver's inputs.

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
    """Signed coil current request, A -> the driver's duty and direction.

    ``duty = |I| R / Vs`` quantised to 1/4096 of the period, after clamping ``|I|`` to
    ``drive.max_current_a``. The returned ``current_a`` is the steady current of the quantised
    duty, with the request's sign.
    """
    i = _finite("current_a", current_a, "a finite number, A")
    i_max = drive.max_current_a
    duty = min(abs(i), i_max) * drive.resistance_ohm / drive.supply_voltage_v
    return _duty_command(duty, i < 0, abs(i) > i_max, drive)


def voltage_to_command(voltage_v: float, drive: CoilDrive) -> DriveCommand:
    """Signed average coil voltage request, V -> the driver's duty and direction.

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
