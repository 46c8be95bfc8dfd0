# SHIM: old path, removed at integration
"""Old path of :mod:`designkit.skipping` (the tolerance-driven field evaluator)."""

from .skipping import (OUTPUTS, RZTable, SkippingEvaluator as Scene,  # noqa: F401
                       SkippingResult as SceneResult, _COMP, _bound_at, _rz_direct, assemble,
                       build_table, evaluate, source_box, sphere_bounds)
