"""The allocation problem's inputs: their checks and the scaling the solver works in.

Inputs: F (k, n) force per ampere (N/A, N m/A for torque rows), the target f (k,) N, per-coil
limits u (n,) A and the budget I_t A. The solver works on currents in units of u_max and forces
in units of the largest achievable column force u_max |F_i| (or of the target, if larger), so
its tolerances are relative. See docs/allocation.md.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import BadInputError

EPS_REL = 1e-10
"""Tikhonov weight relative to the largest squared column norm of the scaled F (see
docs/allocation.md)."""

MULT_TOL = 1e-13
"""Multipliers above -MULT_TOL x (gradient scale) count as non-negative (rounding level,
three decades below the eps-level multipliers of the tie-break)."""

EXACT_FIT_TOL = 1e-11
"""The least-norm exact fit is accepted when ||F x - f|| <= this x (||f|| + ||F|| ||x||): two
decades inside the 1e-9 KKT tolerance (the gradient F^T r is at most ||F|| ||r||)."""

FLOAT_MAX = float.fromhex("0x1.fffffffffffffp+1023")
"""The largest float: a residual beyond the float range is reported as this, never inf."""


def _bad_matrix(fm):
    bad = np.argwhere(~np.isfinite(fm))[0]
    raise BadInputError("force_matrix", "finite (no NaN or Inf), N/A",
                        f"{fm[tuple(bad)]} at index {tuple(int(b) for b in bad)}")


def check_inputs(force_matrix, target, current_limit, total_limit, bias):
    """(F (k, n) ndarray, f (k,) ndarray, u list of n floats, I_t float, power-of-two scale
    exponent of F) of :func:`firmware_io.allocation.allocate`'s inputs; cheap checks first
    (this runs every control period), the precise message only on failure."""
    try:
        fm = np.asarray(force_matrix, dtype=float)
    except (TypeError, ValueError):
        raise BadInputError("force_matrix", "a (k, n) array of finite numbers, N/A",
                            type(force_matrix).__name__) from None
    if fm.ndim != 2:
        if fm.ndim != 1:
            raise BadInputError("force_matrix", "a (k, n) array with k, n >= 1, N/A",
                                f"shape {fm.shape}")
        fm = fm[None, :]
    k, n = fm.shape
    if k < 1 or n < 1:
        raise BadInputError("force_matrix", "a (k, n) array with k, n >= 1, N/A",
                            f"shape {fm.shape}")
    asum = float(np.add.reduce(np.abs(fm), axis=None))
    if not math.isfinite(asum):
        if not np.all(np.isfinite(fm)):  # else only the sum overflowed
            _bad_matrix(fm)
    if not 1e-150 < asum < 1e150 and asum > 0.0:
        # entries near the ends of the float range: an exact power-of-two rescale of F and the
        # target (the currents do not change; the residual is scaled back) keeps F^T F finite
        amax = float(np.maximum.reduce(np.abs(fm), axis=None))
        e = math.frexp(amax)[1]
        fm = np.ldexp(fm, -e)
        scale_e = e
    else:
        scale_e = 0
    try:
        t = np.asarray(target, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise BadInputError("target", f"{k} finite numbers (N)", target) from None
    if t.shape != (k,):
        raise BadInputError("target", f"{k} values (one per row of force_matrix), N",
                            f"shape {np.shape(target)}")
    tl_ = t.tolist()
    if not all(map(math.isfinite, tl_)):
        raise BadInputError("target", "finite (no NaN or Inf), N", tl_)
    if bias is not None:
        b = np.asarray(bias, dtype=float).reshape(-1)
        if b.shape != (k,) or not all(map(math.isfinite, b.tolist())):
            raise BadInputError("bias", f"{k} finite values (the map's F0 in the target's "
                                "rows), N", np.asarray(bias).tolist())
        t = t - b
    if scale_e:
        t = np.ldexp(t, -scale_e)
    if isinstance(current_limit, (float, int)) and not isinstance(current_limit, bool):
        u = [float(current_limit)] * n
    elif type(current_limit) is np.ndarray and current_limit.shape == (n,):
        u = current_limit.astype(float).tolist()
    else:
        try:
            u = np.broadcast_to(np.asarray(current_limit, dtype=float), (n,)).tolist()
        except (TypeError, ValueError):
            raise BadInputError("current_limit", f"a number or {n} numbers >= 0, A",
                                current_limit) from None
    for ui in u:
        if not 0.0 <= ui < math.inf:
            raise BadInputError("current_limit", "finite and >= 0 (per coil), A", ui)
    try:
        tl = float(total_limit)
    except (TypeError, ValueError):
        raise BadInputError("total_limit", ">= 0 A (inf: no budget)", total_limit) from None
    if not tl >= 0.0:
        raise BadInputError("total_limit", ">= 0 A (inf: no budget); a negative budget "
                            "makes sum |I| <= I_t infeasible", tl)
    return fm, t, u, tl, scale_e


def scale(fm, f, umax):
    """The scaled problem: (fs (k', n), ft (k',), c2, F F^T (k', k'), k'), currents in units
    of u_max and forces in units of the largest achievable column force (or the target, if
    larger); c2 the largest squared column norm of fs. All-zero rows (e.g. torque about m: a
    constant residual only) are dropped, k' <= k. None when the answer is all zeros."""
    k = fm.shape[0]
    cmax = max(fm.T.dot(fm).diagonal().tolist())  # entries < 1e150 here (_check_inputs)
    fmax = max(map(abs, f.tolist()))
    cs = math.sqrt(cmax) * umax
    fscale = cs if cs > fmax else fmax
    if fscale == 0.0:
        return None
    if math.isfinite(fscale):
        fs = fm * (umax / fscale)
        ft = f / fscale
        c2 = cmax * (umax / fscale) ** 2
    else:  # limits near the float range: the same scaling written as ratios
        cn = math.sqrt(cmax)
        rt = fmax / umax  # inf for a target beyond the float range here: fs -> 0 below
        denom = cn if cn >= rt else rt
        fs = fm / denom
        ft = (f / umax) / cn if cn >= rt else f / fmax
        c2 = cmax / (denom * denom)
    ffT = fs.dot(fs.T)
    if 0.0 in ffT.diagonal().tolist():  # a zero row, or one whose squares underflow
        rows = np.logical_or.reduce(fs != 0.0, axis=1).tolist()
        if not all(rows):  # an all-zero row (e.g. torque about m): a constant residual only
            keep = [i for i, nz in enumerate(rows) if nz]
            if not keep:
                return None
            fs, ft = fs.take(keep, 0), ft.take(keep)
            k = len(keep)
            ffT = ffT.take(keep, 0).take(keep, 1)
    return fs, ft, c2, ffT, k
