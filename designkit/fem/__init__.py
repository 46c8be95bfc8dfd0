"""FEM cross-check of a coil and its core: gmsh mesh, meshio export, GetDP solve, extraction.

The axisymmetric magnetostatic problem (vector potential a_phi, second-order hierarchical
elements, GetDP's ``VolAxiSqu`` Jacobian, a spherical-shell transformation to infinity) is built
from the same :class:`designkit.Coil` that designkit's own models use, so the two can be compared
point by point. GetDP is an external program (Debian package ``getdp``); gmsh and meshio are
Python packages. Nothing here is imported by the rest of designkit.

Entry point: :func:`solve` -> :class:`FemResult`. The 3-D model of several cores in any pose
is :mod:`.fem3d`; :mod:`.array_check` compares a design's whole coupled array with it.
"""

from __future__ import annotations

from .runner import FemResult, find_getdp, solve

__all__ = ["FemResult", "find_getdp", "solve"]
