"""The drive record: the coils' electrical and thermal data, their supply and the driver the
design names, as designkit writes it (``designkit.model.electrical.drive_data``), the map stores it
(``meta['drive']``, :meth:`DriveRecord.to_dict`) and the runner uses it (its configuration).

SI units. The resistance is a model: R_k(T) = R_k(T_ref) (1 + alpha (T - T_ref)) per coil, with
the operating temperature the runner computes with and the hot temperature the thermal budget
and the design rules use. The coils see ``supply_voltage_v``; whether the driver is rated for it is a rule
(:meth:`DriveRecord.violations`: ``designkit check`` reports it, the hardware entry point
refuses it, the simulator runs it and says so) -- its one definition is
:meth:`firmware_io.hw.driver.DriverRating.supply_violation`. Meaning of each field:
docs/mapfile_format.md, "The drive record".
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import BadInputError
from ..hw.driver import MD10C, CoilDrive, DriverRating

_REBUILD = ("Rebuild the map for this version: designkit map --out <file.npz> (with --design "
            "<design.toml> for a design of your own)")


def _number(name: str, value, valid: str, ok) -> float:
    """``value`` as a float when finite and ``ok(value)``, else BadInputError(name, valid)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise BadInputError(name, valid, value) from None
    if isinstance(value, bool) or not math.isfinite(x) or not ok(x):
        raise BadInputError(name, valid, value)
    return x


def _per_coil(name: str, values, unit: str) -> tuple:
    """A non-empty tuple of finite values > 0 (one per coil)."""
    valid = f"one finite value > 0 {unit} per coil"
    if isinstance(values, (str, bytes)) or not hasattr(values, "__len__") or not len(values):
        raise BadInputError(name, valid, values)
    return tuple(_number(name, v, valid, lambda x: x > 0) for v in values)


@dataclass(frozen=True)
class DriveRecord:
    """One design's drive: what every coil gets from its driver and supply (SI).

    Attributes
    ----------
    resistance_ref_ohm : tuple of float, one per coil
        Winding resistance at ``reference_temperature_c``, ohm.
    inductance_h : tuple of float, one per coil
        Inductance (secant, at the operating current, with the core), H.
    supply_voltage_v : float
        The drivers' motor supply, V: what a coil sees at full duty.
    current_limit_a : float
        Per-coil bound |I_k| <= u, A (at most the driver's continuous rating).
    total_current_a : float
        Budget sum |I_k| <= I_t, A.
    driver : DriverRating
        The driver the design names (:data:`firmware_io.hw.driver.MD10C` by default).
    pwm_frequency_hz : float
        PWM frequency of the drivers' inputs, Hz.
    reference_temperature_c, temperature_coefficient_per_k : float
        The resistance model's T_ref (deg C) and alpha (1/K).
    operating_temperature_c : float
        Winding temperature the runner's R (:attr:`resistance_ohm`) is taken at, deg C.
    hot_temperature_c : float
        The winding's temperature limit, deg C: the I^2 t budget heats the winding from the
        operating temperature to it (and the design rules take R there).
    thermal_continuous_current_a, thermal_time_constant_s : float
        The I^2 t guard (:class:`firmware_io.runner.thermal.ThermalGuard`), A and s.
    """

    resistance_ref_ohm: tuple
    inductance_h: tuple
    supply_voltage_v: float
    current_limit_a: float
    total_current_a: float
    driver: DriverRating = MD10C
    pwm_frequency_hz: float = 1526.0
    reference_temperature_c: float = 20.0
    temperature_coefficient_per_k: float = 0.00393
    operating_temperature_c: float = 20.0
    hot_temperature_c: float = 100.0
    thermal_continuous_current_a: float = 3.0
    thermal_time_constant_s: float = 300.0
    drives: tuple = field(init=False, repr=False, compare=False)
    """One :class:`~firmware_io.hw.driver.CoilDrive` per coil (derived): R at the operating
    temperature, L, the supply and the driver."""

    def __post_init__(self) -> None:
        self.check()
        r = self.resistance_ohm
        object.__setattr__(self, "drives", tuple(
            CoilDrive.supply_limited(self.supply_voltage_v, rk, lk, self.driver)
            for rk, lk in zip(r, self.inductance_h)))

    # ------------------------------------------------------------------ validity
    def check(self) -> None:
        """Refuse a record that is not well formed (BadInputError naming the field, its value
        and the valid range); a driver rating the supply exceeds is :meth:`violations`'."""
        r = _per_coil("resistance_ref_ohm", self.resistance_ref_ohm, "ohm")
        ind = _per_coil("inductance_h", self.inductance_h, "H")
        if len(ind) != len(r):
            raise BadInputError("inductance_h", f"{len(r)} values (one per coil)",
                                len(self.inductance_h))
        if not isinstance(self.driver, DriverRating):
            raise BadInputError("driver", "a DriverRating", type(self.driver).__name__)
        positive = (lambda x: x > 0)
        _number("supply_voltage_v", self.supply_voltage_v, "a finite voltage > 0 V", positive)
        cont = self.driver.continuous_current_a
        _number("current_limit_a", self.current_limit_a,
                f"in (0, {cont:g}] A ({self.driver.name} continuous rating)",
                lambda x: 0 < x <= cont)
        _number("total_current_a", self.total_current_a, "a finite current >= 0 A",
                lambda x: x >= 0)
        for name, unit in (("pwm_frequency_hz", "Hz"), ("thermal_continuous_current_a", "A"),
                           ("thermal_time_constant_s", "s")):
            _number(name, getattr(self, name), f"a finite value > 0 {unit}", positive)
        for name in ("reference_temperature_c", "operating_temperature_c", "hot_temperature_c",
                     "temperature_coefficient_per_k"):
            _number(name, getattr(self, name), "a finite number", lambda x: True)
        for name in ("operating_temperature_c", "hot_temperature_c"):
            if not self.resistance_factor(getattr(self, name)) > 0:
                raise BadInputError(name, "a temperature where the resistance model stays > 0",
                                    getattr(self, name))
        object.__setattr__(self, "resistance_ref_ohm", r)
        object.__setattr__(self, "inductance_h", ind)

    def violations(self) -> list[str]:
        """The driver's ratings this drive breaks, as sentences naming the design keys (empty:
        none): a supply outside the driver's voltage range, a PWM faster than its input."""
        out = []
        bad = self.driver.supply_violation(self.supply_voltage_v)
        if bad:
            out.append(bad)
        if self.pwm_frequency_hz > self.driver.max_pwm_frequency_hz:
            out.append(f"drive.pwm_frequency_hz = {self.pwm_frequency_hz:g} Hz is above the PWM "
                       f"input limit of the driver {self.driver.name!r} "
                       f"(drive.driver_max_pwm_frequency_hz = "
                       f"{self.driver.max_pwm_frequency_hz:g} Hz)")
        return out

    def check_ratings(self) -> None:
        """BadInputError for the first of :meth:`violations` (before a real coil is driven)."""
        bad = self.violations()
        if bad:
            raise BadInputError("drive", "a supply and PWM frequency within the driver's "
                                "ratings", bad[0], "Fix the design and rebuild the map.")

    # ------------------------------------------------------------------ derived numbers
    @property
    def n_coils(self) -> int:
        return len(self.resistance_ref_ohm)

    def resistance_factor(self, temperature_c: float) -> float:
        """R(T) / R(T_ref) = 1 + alpha (T - T_ref)."""
        return 1.0 + self.temperature_coefficient_per_k * (
            temperature_c - self.reference_temperature_c)

    def resistance_at(self, temperature_c: float) -> np.ndarray:
        """(n_coils,) ohm: every coil's resistance at ``temperature_c`` (deg C)."""
        return np.asarray(self.resistance_ref_ohm) * self.resistance_factor(temperature_c)

    @property
    def resistance_ohm(self) -> tuple:
        """Per coil R at the operating temperature, ohm (what the runner computes with)."""
        return tuple(float(x) for x in self.resistance_at(self.operating_temperature_c))

    @property
    def time_constant_s(self) -> tuple:
        """Per coil L / R at the operating temperature, s."""
        return tuple(lk / rk for lk, rk in zip(self.inductance_h, self.resistance_ohm))

    # ------------------------------------------------------------------ storage
    def to_dict(self) -> dict:
        """The record as JSON-ready SI numbers (the map's ``meta['drive']``)."""
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.init}
        out["driver"] = dataclasses.asdict(self.driver)
        out["resistance_ref_ohm"] = list(self.resistance_ref_ohm)
        out["inductance_h"] = list(self.inductance_h)
        return out

    @classmethod
    def from_dict(cls, data, n_coils: int | None = None) -> "DriveRecord":
        """The record from :meth:`to_dict`'s dict (a map's ``meta['drive']``): every field
        present and no other, checked (BadInputError naming the field; ``n_coils``: the number
        of coils it must describe)."""
        names = [f.name for f in dataclasses.fields(cls) if f.init]
        d_names = [f.name for f in dataclasses.fields(DriverRating)]
        if not isinstance(data, dict):
            raise BadInputError("drive", "a drive record (a JSON object)",
                                type(data).__name__, _REBUILD)
        missing = [k for k in names if k not in data]
        extra = sorted(set(data) - set(names))
        drv = data.get("driver")
        if isinstance(drv, dict):
            missing += [f"driver.{k}" for k in d_names if k not in drv]
            extra += sorted(f"driver.{k}" for k in set(drv) - set(d_names))
        elif "driver" in data:
            missing.append("driver (an object)")
        if missing or extra:
            raise BadInputError("drive", f"the drive record's fields {names}",
                                f"missing {missing}, unknown {extra}", _REBUILD)
        rec = cls(**{**data, "driver": DriverRating(**drv)})
        if n_coils is not None and rec.n_coils != n_coils:
            raise BadInputError("drive.resistance_ref_ohm", f"{n_coils} values (one per coil)",
                                rec.n_coils, _REBUILD)
        return rec
