"""designkit: coil-and-field design toolkit for electromagnetic mid-air haptic interfaces.

SI units throughout (m, A, T, N). Light to import: heavy optional libraries (build123d, pyvista,
gmsh, smbus2) are imported only by the modules that need them.
"""

from .constants import MU0
from .cores import Core
from .design import Design, default_design, load_design
from .errors import BadInputError, DesignkitError, DesignRuleError, MissingDependencyError
from .geometry.pose import Pose
from .model.array import CoilArray
from .model.coil import Coil

__version__ = "0.1.0"

__all__ = [
    "Coil", "CoilArray", "Core", "Design", "Pose", "default_design", "load_design", "MU0",
    "BadInputError", "DesignkitError", "DesignRuleError", "MissingDependencyError", "__version__",
]
