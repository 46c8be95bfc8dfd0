"""nlopt coil design: thesis eq. 2.14 and the real device (winding, wire, 1010-steel core).

Two problems on a :class:`designkit.design.Design`, each the design plus a search space:

- :class:`CoilDesignProblem` (:mod:`.coil_problem`, solved by :func:`solve`): maximize the
  vertical force on the finger magnet at the design height over the winding's radii and
  length, for a fixed wire, under R < Rmax and 5 L/R < T (thesis section 2.2, eq. 2.14).
- :class:`DeviceProblem` (:mod:`.device_problem`, solved by :func:`solve_device`): winding,
  standard wire and saturating core together under the resistance, supply, settling,
  thermal and window constraints, objective the design-point force or the smallest force
  the array renders over the workspace (:mod:`.rendering`); the fast core model's numbers are
  checked a posteriori against the panel model (:mod:`.fast_model`), the optimum globally by
  :func:`verify_device` and against GetDP by :func:`getdp_check`.

Units SI throughout. Models, derivations, the proof of the fast model and measured numbers:
docs/optimize.md.
"""

from __future__ import annotations

from .axial_kernel import axial_gradient_per_current_density
from .candidate import device_candidate
from .coil_problem import (CORE_MODEL_NAMES, EXTRA_VARIABLES, MAGNET_CLEARANCE_M, MIN_LENGTH_M,
                           THESIS_CORE_PROTRUSION_M, VARIABLES, CoilDesignProblem, CoreModelName,
                           DesignResult, Evaluation, evaluate_design, force_field_engine)
from .device_check import evaluate_device, rule_table
from .device_problem import (DEVICE_CONSTRAINTS, DEVICE_OBJECTIVES, DEVICE_VARIABLES,
                             PITCH_VARIABLE, DeviceProblem, OperatingConditions,
                             device_problem_for)
from .device_solve import DeviceResult, device_design, round_design, solve_device
from .fast_model import FAST_MODEL_ENVELOPE, RESIDUAL_BOUND
from .nlopt_driver import LocalRun, SolverOptions, maximize
from .rendering import RodCoil, array_force_per_amp, array_render_forces, rendering_force
from .search_space import LAYOUT_VARIABLES, SEARCH_VARIABLES, SearchSpace, Variable
from .solve import (GLOBAL_METHODS, THESIS_FORCE_N, THESIS_POINT, THESIS_TURNS, GlobalMethod,
                    OptimizeResult, ParetoPoint, optimize_wire, pareto_front, solve,
                    thesis_point_summary)
from .verify import best_fast_ref, getdp_check, verify_device
from .wire_table import (AWG_DIAMETERS_M, GRADE1_INSULATION_RATIO, METRIC_DIAMETERS_M,
                         insulated_diameter_for)
from ..rules import reachable_height_m
from .workspace import workspace_region
