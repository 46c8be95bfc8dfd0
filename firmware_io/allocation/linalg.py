"""Small dense solves of the allocator: identities, eps diagonals and the k x k / n x n solve.

The systems are tiny (n ~ 9 coils, k <= 6 rows), so the cost of a solve is numpy's per-call
overhead: identities are cached, and the solve calls the gufunc behind ``np.linalg.solve``
directly when this numpy has it (docs/allocation.md).
"""

from __future__ import annotations

import math

import numpy as np

_EYES = [np.eye(i) for i in range(16)]
_EYES_B = [np.diag([1.0] * i + [0.0]) for i in range(16)]


def eye(m):
    """The m x m identity (cached for m < 16: do not write into it)."""
    return _EYES[m] if m < 16 else np.eye(m)


def eye_bordered(m):
    """The (m + 1) x (m + 1) identity with a 0 in the last place (the border)."""
    return _EYES_B[m] if m < 16 else np.diag([1.0] * m + [0.0])


_EPS_DIAG = {}


def eps_diag(eps, k, m):
    """eps on the first k diagonal entries of an m x m matrix (cached per eps: one per solve)."""
    key = (eps, k, m)
    d = _EPS_DIAG.get(key)
    if d is None:
        if len(_EPS_DIAG) > 64:
            _EPS_DIAG.clear()
        d = np.zeros((m, m))
        d[range(k), range(k)] = eps
        _EPS_DIAG[key] = d
    return d


try:  # the gufunc behind np.linalg.solve without its Python wrapper and errstate (tiny systems)
    from numpy.linalg import _umath_linalg as _ul

    _solve1 = _ul.solve1
    _SIG = {"signature": "dd->d"}

    def fast_solve(mat, rhs):
        """``np.linalg.solve`` of a small system without its wrapper (no singularity check)."""
        return _solve1(mat, rhs, signature="dd->d")
except (ImportError, AttributeError):  # pragma: no cover - other numpy layouts
    fast_solve = np.linalg.solve
    _SIG = {}

    def _solve1(mat, rhs):
        return np.linalg.solve(mat, rhs)


def lsolve(mat, rhs, regularized=True):
    """Solve; ``regularized`` systems (eps > 0) are never singular, so they skip the
    floating-point guards; others fall back to least squares on an exactly singular face."""
    if regularized:
        out = _solve1(mat, rhs, **_SIG)
        if math.isfinite(sum(out.tolist())):  # inf - inf is nan: not finite either
            return out
    try:
        with np.errstate(invalid="raise", divide="raise", over="ignore"):
            out = fast_solve(mat, rhs)
        if all(map(math.isfinite, out.tolist())):
            return out
    except (np.linalg.LinAlgError, FloatingPointError):
        pass
    return np.linalg.lstsq(mat, rhs, rcond=None)[0]
