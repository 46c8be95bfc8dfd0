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

from .._blas import one_blas_thread  # noqa: F401  (designkit.optimize.one_blas_thread)
from .axial_kernel import _phi, axial_gradient_per_current_density  # noqa: F401
from .candidate import device_candidate  # noqa: F401
from .coil_problem import (CORE_MODEL_NAMES, EXTRA_VARIABLES, MAGNET_CLEARANCE_M,  # noqa: F401
                           MIN_LENGTH_M, THESIS_CORE_PROTRUSION_M, VARIABLES, CoilDesignProblem,
                           CoreModelName, DesignResult, Evaluation, _constraint_table,
                           evaluate_design, force_field_engine)
from .device_check import evaluate_device  # noqa: F401
from .device_problem import (DEVICE_CONSTRAINTS, DEVICE_OBJECTIVES,  # noqa: F401
                             DEVICE_VARIABLES, PITCH_VARIABLE, SEARCH_VARIABLES, DeviceProblem,
                             _panel_core, _unit_of, device_problem_for)
from .device_solve import (DeviceResult, _best_pitch, _correct_for_wire,  # noqa: F401
                           _device_starts, _diagnose_infeasible, _fast_vs_panel, _solve_device,
                           device_design, round_design, solve_device)
from .fast_model import FAST_MODEL_ENVELOPE, RESIDUAL_BOUND, _FastModel, _local  # noqa: F401
from .nlopt_driver import LocalRun, _halton, _sobol, maximize  # noqa: F401
from .rendering import array_force_per_amp, array_render_forces, rendering_force  # noqa: F401
from .solve import (GLOBAL_METHODS, THESIS_FORCE_N, THESIS_POINT, THESIS_TURNS,  # noqa: F401
                    GlobalMethod, OptimizeResult, ParetoPoint, _isres, _starts, optimize_wire,
                    pareto_front, solve, thesis_point_summary)
from .verify import _verify_device, best_fast_ref, getdp_check, verify_device  # noqa: F401
from .wire_table import (AWG_DIAMETERS_M, GRADE1_INSULATION_RATIO,  # noqa: F401
                         METRIC_DIAMETERS_M, insulated_diameter_for)
from .workspace import (BOARD_THICKNESS_M, _fold_points, reachable_height_m,  # noqa: F401
                        workspace_region)
