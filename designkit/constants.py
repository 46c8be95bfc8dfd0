"""Physical constants of designkit, at the bottom of the import graph (the field kernels and the
design spec both read them; neither imports the other)."""

import math

MU0 = 4e-7 * math.pi
"""Vacuum permeability used throughout designkit, T m / A. The classical exact value
4 pi 1e-7; it differs from CODATA 2022 (1.25663706127e-6) by 1.3e-10 relative."""
