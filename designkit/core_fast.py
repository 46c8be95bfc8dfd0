# SHIM: old path, removed at integration
from .cores.material import steel1010_h_smooth  # noqa: F401
from .cores.nagaoka import nagaoka_self  # noqa: F401
from .cores.rod import (applied_slice_flux, bessel_slice_flux, interval_mutual,  # noqa: F401
                        slice_edges, solve_rod, solve_rods)
