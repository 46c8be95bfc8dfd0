"""The coils' I^2 t guard: a first-order thermal budget per coil, A^2 s.

``E_k <- E_k exp(-T / tau) + I_k^2 T`` each control period T; a coil carrying its continuous
current I_c forever settles at ``I_c^2 tau`` (the budget). The runner's ``thermal`` fault is
entered when any E_k exceeds the budget and cleared once every E_k is below a fraction of it
(resume policy: docs/runner.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import BadInputError


@dataclass
class ThermalGuard:
    """I^2 t budget per coil with first-order cooling.

    ``E_k <- E_k exp(-T / tau) + I_k^2 T``; a coil carrying ``continuous_current_a`` forever
    settles at ``E = I_c^2 tau (1 - ...)`` -> the budget is ``I_c^2 * tau``. A fault when any
    ``E_k`` exceeds the budget; cleared when every ``E_k`` is below ``resume_fraction`` of it.

    Attributes
    ----------
    n_coils : int
    continuous_current_a : float, A
        Current the coil can carry indefinitely without reaching its temperature limit.
    time_constant_s : float, s
        Thermal time constant of the winding.
    resume_fraction : float
        Fraction of the budget every coil must be below before the fault clears.
    energy_a2s : ndarray, shape (n_coils,), A^2 s
    """

    n_coils: int
    continuous_current_a: float
    time_constant_s: float
    resume_fraction: float = 0.8
    energy_a2s: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self):
        if not (self.continuous_current_a > 0 and math.isfinite(self.continuous_current_a)):
            raise BadInputError("continuous_current_a", "a finite current > 0 A",
                                self.continuous_current_a)
        if not (self.time_constant_s > 0 and math.isfinite(self.time_constant_s)):
            raise BadInputError("time_constant_s", "a finite time > 0 s", self.time_constant_s)
        if self.energy_a2s is None:
            self.energy_a2s = np.zeros(self.n_coils)

    @property
    def budget_a2s(self) -> float:
        """The budget ``I_c^2 tau``, A^2 s."""
        return self.continuous_current_a ** 2 * self.time_constant_s

    def update(self, current_a: np.ndarray, period_s: float) -> None:
        """Cool for ``period_s`` (s), then add the heat of ``current_a`` ((n,) A) over it."""
        self.energy_a2s *= math.exp(-period_s / self.time_constant_s)
        self.energy_a2s += np.square(current_a) * period_s

    def exceeded(self) -> bool:
        """True when some coil is over the budget."""
        return bool(np.any(self.energy_a2s > self.budget_a2s))

    def cooled(self) -> bool:
        """True when every coil is below ``resume_fraction`` of the budget."""
        return bool(np.all(self.energy_a2s < self.resume_fraction * self.budget_a2s))
