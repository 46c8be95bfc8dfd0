# SHIM: old path, removed at integration
from .cores.coupled import ArraySystem, one_blas_thread  # noqa: F401
from .cores.core_model import M_MAX  # noqa: F401
from .cores.saturation import saturation_table  # noqa: F401
