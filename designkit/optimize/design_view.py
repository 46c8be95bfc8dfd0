"""The numbers both optimizer problems read from their design (SI), defined once.

A problem holds a :class:`designkit.design.Design` and its search space; these properties
name the design's fields in the problem's terms (the design point, the operating current, the
limits of thesis eq. 2.14).
"""

from __future__ import annotations

from ..design import Design


class DesignView:
    """Properties of ``self.design`` shared by the coil and the device problem."""

    design: Design

    @property
    def height_m(self) -> float:
        """Design point: magnet centre above the coil tops, m (``optimize.height_m``)."""
        return self.design.optimize.height_m

    @property
    def moment_a_m2(self) -> float:
        """The magnet's dipole moment |m|, A m^2."""
        return self.design.magnet.moment_a_m2

    @property
    def current_a(self) -> float:
        """Operating current, A (``drive.max_current_a``)."""
        return self.design.drive.max_current_a

    @property
    def max_resistance_ohm(self) -> float:
        return self.design.optimize.max_resistance_ohm

    @property
    def max_settling_time_s(self) -> float:
        """Bound on 5 L/R, s."""
        return self.design.optimize.max_settling_time_s

    @property
    def packing(self) -> str:
        """Winding packing, 'layered' or 'orthocyclic'."""
        return self.design.wire.packing
