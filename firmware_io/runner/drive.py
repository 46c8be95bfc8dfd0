"""The current path of one control step: allocator amperes -> the voltage the driver should
apply -> its duty and direction, and the R-L model of the currents that results.

One unit change per hop: the allocator's currents (A) become, through the exact R-L step
response, the average voltage (V, within the supply) that brings each coil to its command at
the end of the period; :meth:`firmware_io.hw.coils.CoilDriver.command_voltage` turns that voltage
into the PCA9685 duty (``|V| / Vs``); the model advances by the voltage the quantised duty
really applies. R, L and Vs are read from the coils' :class:`firmware_io.hw.driver.CoilDrive`
records (the drive record's ``drives``), the one place they are stored.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..hw.driver import CoilDrive


def feedforward_voltage(target_a, current_a, resistance_ohm, inductance_h, period_s,
                        supply_v):
    """Voltage that takes an R-L coil from ``current_a`` to ``target_a`` in one period.

    With a constant voltage V over the period T the current of an R-L coil is
    ``I(T) = V/R + (I0 - V/R) exp(-T R / L)`` exactly, so
    ``V = R (I* - I0 e) / (1 - e)`` with ``e = exp(-T R / L)``. The result is clipped to
    ``[-supply_v, supply_v]`` (the driver's sign-magnitude output); then the target is reached
    later, never overshot, because I(t) is monotone under a constant V.

    Parameters
    ----------
    target_a, current_a : ndarray, shape (n,), A
    resistance_ohm, inductance_h : ndarray, shape (n,), ohm and H (> 0)
    period_s : float, s
    supply_v : float or ndarray, shape (n,), V

    Returns
    -------
    ndarray, shape (n,), V
    """
    e = np.exp(-period_s * resistance_ohm / inductance_h)
    v = resistance_ohm * (target_a - current_a * e) / (1.0 - e)
    return np.clip(v, -supply_v, supply_v)


def rl_step(current_a, voltage_v, resistance_ohm, inductance_h, period_s):
    """Exact R-L response to a constant voltage over one period: I(T), A, shape (n,)."""
    e = np.exp(-period_s * resistance_ohm / inductance_h)
    i_inf = voltage_v / resistance_ohm
    return i_inf + (current_a - i_inf) * e


class CurrentPath:
    """Commanded currents -> applied voltages, and the model of the coil currents (A).

    Parameters
    ----------
    drives : sequence of CoilDrive, one per coil, each with its ``inductance_h``
    period_s : float, s -- the control period
    feedforward : bool
        Voltage feed-forward through the L/R model; off: the steady-state voltage ``I R``.
    """

    def __init__(self, drives: Sequence[CoilDrive], period_s: float, feedforward: bool = True):
        self.resistance_ohm = np.array([d.resistance_ohm for d in drives], float)
        self.inductance_h = np.array([d.inductance_h for d in drives], float)
        self.supply_v = np.array([d.supply_voltage_v for d in drives], float)
        self.period_s = float(period_s)
        self.feedforward = bool(feedforward)
        self.current_a = np.zeros(len(self.resistance_ohm))   # the feed-forward's state

    def voltage(self, command_a: np.ndarray) -> np.ndarray:
        """(n,) V the drives should apply this period for the currents ``command_a`` (n,) A."""
        if self.feedforward:
            return feedforward_voltage(command_a, self.current_a, self.resistance_ohm,
                                       self.inductance_h, self.period_s, self.supply_v)
        return np.clip(command_a * self.resistance_ohm, -self.supply_v, self.supply_v)

    def advance(self, applied_v: np.ndarray) -> np.ndarray:
        """Step the model one period under the voltages really applied, (n,) V; returns I, A."""
        self.current_a = rl_step(self.current_a, applied_v, self.resistance_ohm,
                                 self.inductance_h, self.period_s)
        return self.current_a
