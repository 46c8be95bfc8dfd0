"""Levenberg-Marquardt on the magnet's position (3 unknowns), the fits' inner solver.

``evaluate(p)`` returns the 4 x 4 Gram matrix of [J, -r] at the position p (m) as nested lists
(J: the weighted residual's Jacobian, r the weighted residual): its upper 3 x 3 block is J^T J
(the Fisher information, 1/m^2), its last column -J^T r and its corner the cost r^T r. The
3 x 3 normal equations are solved in closed form on Python floats (the small-array numpy
overhead dominates at this size); the position is kept inside the box [lo, hi] (m).
Returns (position (3,) m, cost, iterations, converged, Gram matrix at the position).
Reference: Madsen, Nielsen & Tingleff, "Methods for non-linear least squares problems" (2004).
numpy only (runs on the controller).
"""

from __future__ import annotations

import math

import numpy as np


def _solve3_damped(a, g, lam):
    """Solve (A + lam diag(A)) x = g for a symmetric 3 x 3 A (nested lists) by the adjugate;
    None when singular or not finite."""
    m00, m11, m22 = (a[0][0] * (1 + lam) + 1e-30, a[1][1] * (1 + lam) + 1e-30,
                     a[2][2] * (1 + lam) + 1e-30)
    m01, m02, m12 = a[0][1], a[0][2], a[1][2]
    c00 = m11 * m22 - m12 * m12
    c01 = m02 * m12 - m01 * m22
    c02 = m01 * m12 - m02 * m11
    det = m00 * c00 + m01 * c01 + m02 * c02
    if not (math.isfinite(det) and det != 0.0):
        return None
    c11 = m00 * m22 - m02 * m02
    c12 = m01 * m02 - m00 * m12
    c22 = m00 * m11 - m01 * m01
    g0, g1, g2 = g
    x = ((c00 * g0 + c01 * g1 + c02 * g2) / det, (c01 * g0 + c11 * g1 + c12 * g2) / det,
         (c02 * g0 + c12 * g1 + c22 * g2) / det)
    if not all(math.isfinite(v) for v in x):
        return None
    return x


def levenberg_marquardt(evaluate, p0, lo, hi, max_iterations: int):
    """Levenberg-Marquardt on the position (3 unknowns: the 3 x 3 normal equations are
    solved in closed form on Python floats, the small-array numpy overhead dominates
    here). ``evaluate(p)`` -> the Gram matrix of [J, -r] (4 x 4 nested lists)."""
    p = np.array(p0, dtype=float)
    gm = evaluate(p)
    cost = gm[3][3]
    lam = 1e-6
    converged = False
    it = 0
    for it in range(1, max_iterations + 1):
        a = gm
        g = (-gm[0][3], -gm[1][3], -gm[2][3])
        step = _solve3_damped(a, g, lam)
        if step is None:
            break
        # a Gauss-Newton step below 1/20 of the estimate's own noise (1 / sqrt(diag(J^T J))
        # per axis, <= the true standard deviation; 50 um at most): converged -- what it
        # leaves is far below that noise (and ~(step)^2 / 10 mm for exact data)
        xtol2 = min(0.0025 * (1.0 / (a[0][0] + 1e-300) + 1.0 / (a[1][1] + 1e-300)
                              + 1.0 / (a[2][2] + 1e-300)), 2.5e-9)
        s2 = step[0] * step[0] + step[1] * step[1] + step[2] * step[2]
        if lam < 1e-4 and s2 < xtol2:
            p = p + step
            converged = True
            break
        # the position stays in the plausible box: far outside it the magnet's field vanishes
        # and a step could run away on the (bounded) induced term alone
        pn = np.array([min(max(p[k] + step[k], lo[k]), hi[k]) for k in range(3)])
        gn = evaluate(pn)
        cn = gn[3][3]
        if math.isfinite(cn) and cn <= cost:
            p, gm = pn, gn
            # 0.1 um or a negligible cost decrease: far below what the noise allows
            small = s2 < 1e-14 or cost - cn <= 1e-7 * cost
            cost = cn
            lam = max(lam * 0.2, 1e-9)
            if small:
                converged = True
                break
        else:
            lam *= 10.0
            if lam > 1e8:
                converged = s2 < 1e-12
                break
    return p, cost, it, converged, gm
