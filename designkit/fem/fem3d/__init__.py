"""3-D GetDP reference for coupled cores: several iron cores, one energized winding, a magnet.

The independent check of the coupled-array model: what the axisymmetric model
(:mod:`designkit.fem.runner`) cannot do -- cores side by side, the 3x3 array with one coil
energized, the finger magnet magnetizing a core -- solved by a 3-D finite-element model
(magnetostatics in the vector potential, Whitney + second-order face functions, tree gauge,
a spherical shell mapped to infinity, half or quarter symmetry where the bodies allow it).

Modules: :mod:`.bodies` (the bodies, region tags, mirror folding), :mod:`.mesh` (gmsh),
:mod:`.problem` (the .pro text), :mod:`.solver` (:func:`solve`), :mod:`.device` (any
array's cores in their poses and one energized winding), :mod:`.iron` (B and grad B
from the iron's magnetization, the conical rule), :mod:`.lines` (line fits), :mod:`.force`
(the force on the magnet), :mod:`.cases` (the thesis cases). Units SI: m, T, T/m, N.

The formulation, the output methods, the force integral and the measured accuracy and mesh
convergence (with the commands that measure them) are in docs/fem.md.
"""

from __future__ import annotations

from .bodies import AIR, BOUNDARY, CORE0, MAGNET, SHELL, WIND0, Cyl, model_symmetry
from .cases import (WORKSPACE_BOX, array_case, image_force_z, magnet_block_force,
                    magnet_pull_case, single_core_case, thesis_geometry, two_cores_case,
                    workspace_points)
from .device import device_bodies, device_case
from .iron import conical_rule, core_dipoles, dipoles_field, iron_field
from .lines import FIT_DEGREE, FIT_HALF_WINDOW, FIT_SAMPLES
from .mesh import MeshSettings, build_mesh
from .problem import problem_text
from .solver import Fem3DResult, Fem3DSettings, solve

__all__ = ["AIR", "BOUNDARY", "CORE0", "MAGNET", "SHELL", "WIND0", "Cyl", "Fem3DResult",
           "Fem3DSettings", "MeshSettings",
           "device_bodies", "device_case", "model_symmetry",
           "FIT_DEGREE", "FIT_HALF_WINDOW", "FIT_SAMPLES", "WORKSPACE_BOX", "array_case",
           "build_mesh", "conical_rule", "core_dipoles", "dipoles_field", "image_force_z",
           "iron_field", "magnet_block_force", "magnet_pull_case", "problem_text",
           "single_core_case", "solve", "thesis_geometry", "two_cores_case",
           "workspace_points"]
