"""Standard magnet-wire sizes and their enamelled diameters (SI: m).

Bare copper diameters of AWG 14-30 (ASTM B258) and of the IEC 60317 metric grades
0.20-1.60 mm; the insulated diameter of a bare size is the grade-1 enamel build, assumed
bare x 1.04 + 20 um.
"""

from __future__ import annotations

ENAMEL_BUILD_RATIO = 1.04
"""Grade-1 enamel: insulated diameter per bare diameter before the fixed build (assumed)."""
ENAMEL_BUILD_M = 20e-6
"""Grade-1 enamel: fixed build added to the diameter, m (assumed)."""
THESIS_WIRE_M = 0.7e-3
"""The thesis' wire, taken as the bare diameter, m."""
GRADE1_INSULATION_RATIO = ENAMEL_BUILD_RATIO + ENAMEL_BUILD_M / THESIS_WIRE_M
"""Insulated / bare diameter of the grade-1 family at the thesis' 0.7 mm wire (~1.069)."""

AWG_DIAMETERS_M = {
    14: 1.628e-3, 15: 1.450e-3, 16: 1.291e-3, 17: 1.150e-3, 18: 1.024e-3, 19: 0.912e-3,
    20: 0.812e-3, 21: 0.723e-3, 22: 0.644e-3, 23: 0.573e-3, 24: 0.511e-3, 25: 0.455e-3,
    26: 0.405e-3, 27: 0.361e-3, 28: 0.321e-3, 29: 0.286e-3, 30: 0.255e-3,
}
"""AWG gauge -> bare copper diameter, m (ASTM B258)."""
METRIC_DIAMETERS_M = tuple(x * 1e-3 for x in (0.20, 0.25, 0.30, 0.35, 0.40, 0.45, 0.50, 0.56,
                                              0.60, 0.63, 0.70, 0.71, 0.75, 0.80, 0.85, 0.90,
                                              1.00, 1.06, 1.12, 1.18, 1.25, 1.32, 1.40, 1.50,
                                              1.60))
"""IEC 60317 metric grades, bare copper diameter, m."""


def insulated_diameter_for(bare_m: float) -> float:
    """Grade-1 enamelled diameter of a bare diameter (both m): bare x 1.04 + 20 um (assumed)."""
    return bare_m * ENAMEL_BUILD_RATIO + ENAMEL_BUILD_M

