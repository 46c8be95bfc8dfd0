"""The damped Gauss-Newton (Levenberg-Marquardt) solve shared by the pose fits:
:func:`damped_step` and :func:`levenberg_marquardt`.

On a whitened residual r (the data minus the model, divided by sigma) with Jacobian J of the
model, the step delta solves (J^T J + lam diag(J^T J)) delta = J^T r (Marquardt's scaling:
the damping is invariant to the unknowns' units); g = delta . J^T r is the chi-square drop
the step predicts (for lam = 0 exactly that of the linearized model). The loop accepts a step
that does not raise chi2 and relaxes the damping (x 0.2), else stiffens it (x 10) and tries
again; it has converged when the undamped-enough step (lam < 1e-2) predicts a drop below
:data:`CONVERGED_GAIN`, i.e. the step is far inside the estimate's own noise (Mahalanobis
length sqrt(g)). Reference: Marquardt, J. SIAM 11, 431 (1963); Madsen, Nielsen & Tingleff,
"Methods for non-linear least squares problems" (2004), section 3.2. numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

CONVERGED_GAIN = 2.5e-3
"""The Gauss-Newton step's predicted chi-square drop below which a solve has converged (a step
of 1/20 of the estimate's own noise, Mahalanobis)."""


def damped_step(jac: np.ndarray, res: np.ndarray, lam: float):
    """(delta (P,), g) for the whitened Jacobian ``jac`` (m, P) and residual ``res`` (m,) with
    Marquardt's damping ``lam`` (module docstring); None when the normal matrix is singular or
    the predicted drop g is not finite."""
    a = jac.T @ jac
    g = jac.T @ res
    diag = a.reshape(-1)[::jac.shape[1] + 1]       # a view: a is a new contiguous array
    diag *= 1.0 + lam
    diag += 1e-300
    try:
        delta = np.linalg.solve(a, g)
    except np.linalg.LinAlgError:
        return None
    gain = float(delta @ g)
    if not math.isfinite(gain):
        return None
    return delta, gain


@dataclass(frozen=True)
class Outcome:
    """A solve's end: the state, the whitened Jacobian and residual at the last accepted
    state (before a converged final step), chi2 there, converged, iterations."""

    state: Any
    jac: np.ndarray
    res: np.ndarray
    chi2: float
    converged: bool
    iterations: int


GIVE_UP_AFTER = 3
"""Iterations before a solve with a ``give_up`` test may abandon (the first steps from a
dragged start are damped and far from linear)."""


def beyond(bound: float) -> Callable:
    """The ``give_up`` test of :func:`levenberg_marquardt` that abandons while the linearized
    chi2 exceeds ``bound``."""
    return lambda jac, res, linearized: linearized > bound


def levenberg_marquardt(state, rows: Callable, step: Callable, first: tuple,
                        max_iterations: int, quadratic: bool = False,
                        give_up: Callable | None = None) -> Outcome:
    """Levenberg-Marquardt from ``state``: ``rows(state)`` -> (jac, res) whitened, ``step(state,
    delta)`` -> the moved state, ``first`` the rows at ``state``. Converged as the module
    docstring says, or when chi2 stops falling (relative 1e-9), or -- ``quadratic`` -- when,
    converging quadratically (the last step was accepted nearly undamped), the step after this
    one would predict a tenth of :data:`CONVERGED_GAIN`: g_next ~ g^3 / g_prev^2 for the
    predicted drops g of successive steps (errors e_{k+1} ~ C e_k^2, g ~ e^2). A converged
    fit takes its last step unverified (the Jacobian and chi2 reported are those before it).
    ``give_up(jac, res, linearized) -> bool``: asked after :data:`GIVE_UP_AFTER`
    iterations at each nearly undamped step, with the linearized chi2 (chi2 - g: where the
    linear model says the minimum is); True ends the solve, not converged -- for a hypothesis
    that can only be kept below a test's threshold, e.g. :func:`beyond` a few times it."""
    jac, res = first
    cost = float(res @ res)
    lam, converged, it = 1e-4, False, 0
    prev_gain = 0.0         # the last accepted nearly undamped step's predicted drop (0: none)
    for it in range(1, max_iterations + 1):
        found = damped_step(jac, res, lam)
        if found is None:
            break
        delta, gain = found
        if (give_up is not None and it > GIVE_UP_AFTER and lam < 1e-2
                and give_up(jac, res, cost - gain)):
            break
        if lam < 1e-2 and (gain < CONVERGED_GAIN or (
                quadratic and gain ** 3 < 0.1 * CONVERGED_GAIN * prev_gain * prev_gain)):
            state = step(state, delta)
            converged = True
            break
        new = step(state, delta)
        jac2, res2 = rows(new)
        cost2 = float(res2 @ res2)
        if math.isfinite(cost2) and cost2 <= cost:
            small = cost - cost2 <= 1e-9 * cost
            state, jac, res, cost = new, jac2, res2, cost2
            prev_gain = gain if lam < 1e-3 else 0.0
            lam = max(lam * 0.2, 1e-9)
            if small:
                converged = True
                break
        else:
            prev_gain = 0.0
            lam *= 10.0
            if lam > 1e8:
                break
    return Outcome(state, jac, res, cost, converged, it)
