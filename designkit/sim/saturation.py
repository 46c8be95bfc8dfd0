"""The simulated plant's saturating iron, from designkit's nonlinear core model -- never the map.

The array model is linear (:mod:`designkit.cores.coupled`: every core at its
``relative_permeability``). A core of 1010 steel (``Core(bh='steel1010')``) carries less
magnetization at high current; the plant adds to column k of the coupled A(p) the change that
coil k's own core makes at |I_k|, from the single coil's nonlinear axisymmetric solve
(:class:`designkit.cores.Core`, its B-H curve) against the same coil with the linear core, per
ampere, at the point itself::

    A_k(p, I) = A_k,coupled(p) + [A_k,steel(p, |I|) - |I| A_k,linear(p)] / |I|

(rows :data:`designkit.model.array.ROWS`; the winding's part cancels, only the cores' fields
enter). It is exact for one energized coil, to the nonlinear solve's accuracy (against the
nonlinear GetDP FEM: tests/data/saturation_refs.json), at every point -- unlike the map's one
factor per coil, taken at the design point. What several energized coils' fields do to one core
together is not modelled (their sum per coil; docs/coupling.md, "Saturation correction").

The change is tabulated at the currents ``LEVEL_STEP_A``, ``2 LEVEL_STEP_A``, ... up to the
largest current the drive can reach and interpolated linearly in |I| between them (held below
the first level, where the B-H curve's initial permeability keeps the factor constant, and
above the last); in position it is sampled along the scripted path like the rest of the plant
(:class:`designkit.sim.samples.Sampled`).
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

from ..cores.saturation import SaturationWarning
from ..model.array import CoilArray, g5_from_gradient

LEVEL_STEP_A = 0.5
"""Spacing of the currents the nonlinear cores are solved at, A (linear interpolation between
them: within ~0.1 % of the force at 6 A, where the factor bends most; docs/coupling.md)."""

PATH_STEP_M = 2e-3
"""The change is sampled where the path moved this far (it is ~8 % of a column, smooth on the
cores' scale), m."""


class PlantSaturation:
    """The cores' saturation of a simulated array (see the module docstring).

    Parameters
    ----------
    array : CoilArray -- the plant's array; coils with ``core.bh == 'steel1010'`` saturate
    max_current_a : float, A -- the largest |I| the plant can carry (the levels reach it)
    """

    def __init__(self, array: CoilArray, max_current_a: float):
        self.array = array
        self.coils = array.saturating_coils()
        top = LEVEL_STEP_A * max(1, math.ceil(float(max_current_a) / LEVEL_STEP_A - 1e-9))
        self.levels_a = np.arange(LEVEL_STEP_A, top + 1e-9, LEVEL_STEP_A)

    @classmethod
    def of(cls, array: CoilArray, max_current_a: float) -> "PlantSaturation | None":
        """The model, or None when no core saturates (air coils, linear cores)."""
        return cls(array, max_current_a) if array.saturating_coils() else None

    def deltas(self, points_m) -> np.ndarray:
        """(n, n_levels, 8, n_coils): the change of each column of A per ampere at each level,
        at ``points_m`` (n, 3) m (zero for coils that do not saturate)."""
        p = np.asarray(points_m, dtype=float).reshape(-1, 3)
        out = np.zeros((len(p), len(self.levels_a), 8, self.array.n_coils))
        with warnings.catch_warnings():
            # the linear reference core passes the knee at high current: that is the point
            warnings.simplefilter("ignore", SaturationWarning)
            for k in self.coils:
                coil = self.array.coils[k]
                steel = dataclasses.replace(coil, core=dataclasses.replace(coil.core,
                                                                           bh="steel1010"))
                linear = dataclasses.replace(coil, core=dataclasses.replace(coil.core,
                                                                            bh="linear"))
                b0, g0 = linear.field(p, 1.0, gradient=True, include="core")
                for j, i in enumerate(self.levels_a):
                    b, g = steel.field(p, float(i), gradient=True, include="core")
                    out[:, j, :3, k] = b / i - b0
                    out[:, j, 3:, k] = g5_from_gradient(g / i - g0)
        return out

    def columns(self, a_linear, deltas, currents_a) -> np.ndarray:
        """A at one point for these currents: (8, n_coils) from the linear ``a_linear`` (8,
        n_coils) and that point's ``deltas`` (n_levels, 8, n_coils), each column at |I_k|."""
        x = np.abs(np.asarray(currents_a, dtype=float)) / LEVEL_STEP_A - 1.0
        x = np.clip(x, 0.0, len(self.levels_a) - 1.0)
        j = np.minimum(x.astype(int), len(self.levels_a) - 2) if len(self.levels_a) > 1 \
            else np.zeros(len(x), int)
        w = x - j
        cols = np.arange(a_linear.shape[1])
        lo = deltas[j, :, cols]                      # (n_coils, 8)
        hi = deltas[np.minimum(j + 1, len(self.levels_a) - 1), :, cols]
        return a_linear + (lo + w[:, None] * (hi - lo)).T
