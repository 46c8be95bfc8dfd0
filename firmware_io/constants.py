"""Physical constants, defined once for firmware_io and designkit (designkit.constants re-exports
them: designkit may import firmware_io, never the reverse)."""

import math

MU0 = 4e-7 * math.pi
"""Vacuum permeability, T m / A. The classical exact value 4 pi 1e-7; it differs from CODATA
2022 (1.25663706127e-6) by 1.3e-10 relative."""
