# SHIM: old path, removed at integration
from .cores.material import KNEE_T, STEEL1010_B, STEEL1010_H  # noqa: F401
from .cores.panel import Core, _solve_linear, _solve_nonlinear  # noqa: F401
from .cores.saturation import SaturationWarning  # noqa: F401
