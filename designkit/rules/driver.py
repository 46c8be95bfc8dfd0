"""The driver's rules: the supply and the PWM within the ratings of the driver the design names."""

from __future__ import annotations

from ..design import Design
from ..model import electrical as el
from .rule import Rule


def driver_rules(d: Design) -> list[Rule]:
    """The supply and the PWM within the ratings of the driver the design names (the same
    limits :meth:`firmware_io.hw.driver.DriverRating.supply_violation` applies to the map's
    drive record, which the hardware runner refuses to drive past)."""
    drv = el.driver_rating(d.drive)
    vs = d.drive.supply_voltage_v
    name = f"the driver {drv.name!r}"
    return [
        Rule("design_supply_voltage_v", vs, drv.max_voltage_v, "V", "upper",
             ("drive.supply_voltage_v", "drive.driver_max_voltage_v"),
             f"supply vs the rating of {name}",
             f"reduce drive.supply_voltage_v to <= {drv.max_voltage_v:g} V or name a driver "
             "rated for it (drive.driver, drive.driver_max_voltage_v)", 0.0, "device"),
        Rule("design_supply_min_voltage_v", vs, drv.min_voltage_v, "V", "lower",
             ("drive.supply_voltage_v", "drive.driver_min_voltage_v"),
             f"supply vs the lowest supply {name} is rated for",
             f"raise drive.supply_voltage_v to >= {drv.min_voltage_v:g} V or name a driver "
             "rated for it", 0.0, "device"),
        Rule("pwm_frequency_hz", d.drive.pwm_frequency_hz, drv.max_pwm_frequency_hz, "Hz",
             "upper", ("drive.pwm_frequency_hz", "drive.driver_max_pwm_frequency_hz"),
             f"PWM frequency vs the PWM input limit of {name}",
             f"reduce drive.pwm_frequency_hz to <= {drv.max_pwm_frequency_hz:g} Hz", 0.0,
             "device"),
    ]
