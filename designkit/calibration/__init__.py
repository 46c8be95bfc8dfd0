"""As-built calibration: fit the as-built parameters of a design to field measurements.

- :mod:`.measurements`: the measurement CSV, its checks, simulated onboard and probe plans;
- :mod:`.model`: each coil's field per ampere as a function of its parameters, with Jacobian;
- :mod:`.fit`: the regularized Levenberg-Marquardt fit, standard errors, identifiability;
- :mod:`.plan`: a probe plan from the Fisher information, what the onboard arrays identify.

The as-built description itself: :mod:`designkit.design.asbuilt`. Reference: docs/calibration.md.
"""

from .fit import FitNotConverged, FitResult, actuation_error, fit, fitted_mask
from .measurements import (Measurements, onboard_plan, probe_plan, read_csv, sensor_groups,
                           simulate, workspace_points, write_csv)
from .model import ForwardModel, coupling_term

__all__ = ["FitNotConverged", "actuation_error", "FitResult", "ForwardModel", "Measurements", "coupling_term",
           "fit", "fitted_mask", "onboard_plan", "probe_plan", "read_csv", "sensor_groups", "simulate",
           "workspace_points", "write_csv"]
