"""Saturation of the cores: the warning of the linear models and the per-coil force factor.

The linear core models (``Core.bh == 'linear'``, ``model='thesis-uniform'``) overestimate the
field once the iron passes the knee of its B-H curve; they warn with
:class:`SaturationWarning`. The coupled array solve is linear; the map stores a per-coil
saturation correction, :func:`saturation_table`, from the single coil's nonlinear
(1010 steel) axisymmetric solve, applied by the runner as described in docs/coupling.md,
"Saturation correction".
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ..geometry.pose import Pose


class SaturationWarning(UserWarning):
    """The core's flux density passes the knee of the B-H curve: a linear model overestimates."""


@functools.lru_cache(maxsize=8)
def _saturation_cached(coil, height_m, currents):
    c = coil.core
    lin = dataclasses.replace(coil, pose=Pose(), core=dataclasses.replace(c, bh="linear"))
    nl = dataclasses.replace(coil, pose=Pose(), core=dataclasses.replace(c, bh="steel1010"))
    pt = np.array([[0.0, 0.0, coil.length / 2 + height_m]])
    _, g_lin = lin.field(pt, 1.0, gradient=True)
    out = []
    for i in currents:
        if i <= 0:
            out.append(1.0)
            continue
        _, g = nl.field(pt, float(i), gradient=True)
        out.append(float(g[0, 2, 2] / (i * g_lin[0, 2, 2])))
    return np.array(out)


def saturation_table(coil, height_m: float = 0.03, currents_a=None) -> dict:
    """Per-coil force factor of the nonlinear 1010-steel core vs |I|, at the design point.

    ``s(|I|) = dBz/dz_nonlinear(I) / (I * dBz/dz_linear(1 A))`` of the single coil (a
    :class:`designkit.Coil` with a core; its nonlinear axisymmetric solve,
    :class:`designkit.cores.Core` with ``bh='steel1010'``, against the linear core at
    ``relative_permeability``), on the axis ``height_m`` (m) above the coil's top (the design
    point; the vertical force on an upright magnet there scales the same way).

    How the runner applies it (per coil from its own current; per state from the equivalent
    own current ``I_eq,k = |sum_j C[k, j] I_j| / C[k, k]`` with C =
    :meth:`designkit.model.array.CoilArray.saturation_correction` ``core_flux_t_per_a``), and what
    that assumes: docs/coupling.md, "Saturation correction".

    Returns
    -------
    dict with ``current_a`` (k,) A (default 0, 1, ..., 6 A) and ``factor`` (k,).
    """
    currents = np.arange(0.0, 6.01, 1.0) if currents_a is None else np.asarray(currents_a,
                                                                               float)
    key = dataclasses.replace(coil, pose=Pose())
    factor = _saturation_cached(key, float(height_m), tuple(float(i) for i in currents))
    return {"current_a": currents, "factor": factor}
