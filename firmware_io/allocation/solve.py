"""`allocate` and `Allocator`: one bounded allocation solve, cold or warm, in named phases.

scale -> least-norm fast exit -> start (warm face or cold projection) -> active set -> polish
(eps -> 0) -> least-energy exact fit -> clamp to the bounds. Inputs and outputs in SI (A, N);
the phases work in the scaled units of :func:`.problem.scale` (:class:`.workspace.Workspace`).
With extra linear constraints on the currents the solve is :mod:`.constrained`'s. Method:
docs/allocation.md.
"""

from __future__ import annotations

import math

import numpy as np

from .active_set import active_set
from .cold_start import cold_start
from .faces import face_minimizer
from .feasible import inside, on_face
from .linalg import eye, fast_solve
from .polish import least_energy, polish
from .problem import EPS_REL, EXACT_FIT_TOL, FLOAT_MAX, MULT_TOL, check_inputs, scale
from .working_set import Face, point_face
from .workspace import Workspace


def allocate(force_matrix, target, current_limit, total_limit, *, unipolar: bool = False,
             bias=None, max_iter: int | None = None, warm: "Allocator | None" = None):
    """Currents that render ``target`` as closely as the bounds allow (thesis eq. 4.9).

    Parameters
    ----------
    force_matrix : array-like, shape (k, n)
        Force (and/or torque) per ampere of each coil at the magnet, N/A (N m/A for torque
        rows). A 1-D array is one row.
    target : array-like, shape (k,)
        Wanted force (torque), N (N m), in the same rows.
    current_limit : float or array-like (n,)
        Per-coil limit u_i >= 0, A.
    total_limit : float
        Budget I_t >= 0 on sum |I_i|, A (``inf``: none).
    unipolar : bool
        ``True``: 0 <= I_i <= u_i (the thesis); default ``False``: |I_i| <= u_i.
    bias : array-like (k,), optional
        The bias force F0(p) (magnet on the cores at zero current); the currents then render
        ``target - bias``.
    max_iter : int, optional
        Active-set iteration cap (default 50 + 10 n); the returned currents are feasible even
        if it is hit.
    warm : Allocator, optional
        Keeps the dual point of the previous solve as the start of this one (see `Allocator`);
        the answer is the same with or without it.

    Returns
    -------
    currents : ndarray (n,), A
        Always inside the bounds (clamped to them; the budget holds to 1e-12 relative).
    residual : float
        ||F I - (target - bias)||^2, N^2.

    Raises
    ------
    BadInputError (a ValueError)
        Non-finite matrix/target/bias, wrong shapes, negative or NaN limits, I_t < 0.
    """
    fm, t, u, tl, scale_e = check_inputs(force_matrix, target, current_limit, total_limit,
                                         bias)
    x = _solve(fm, t, u, tl, bool(unipolar), max_iter, warm)
    r = fm.dot(x) - t
    big = max(map(abs, r.tolist()))
    if big < 1e150:
        res = float(r.dot(r))
    else:  # the square of a target beyond 1e154: scaled, and capped at the largest float
        e = math.frexp(big)[1]
        rs = np.ldexp(r, -e)
        res, scale_e = float(rs.dot(rs)), scale_e + e
    if scale_e and res > 0.0:
        try:
            res = math.ldexp(res, 2 * scale_e)
        except OverflowError:  # beyond the float range: the largest float, never inf
            res = FLOAT_MAX
    return x, res


def _solve(fm, f, ul, tl, unipolar, max_iter, warm=None):
    """The currents (n,), A, for the checked inputs (F, f, u list, I_t) of `allocate`."""
    k, n = fm.shape
    umax = max(ul)
    tl_eff = min(tl, math.fsum(ul))
    if umax == 0.0 or tl_eff == 0.0:
        return np.zeros(n)
    scaled = scale(fm, f, umax)
    if scaled is None:
        return np.zeros(n)
    fs, ft, c2, ffT, k = scaled
    inv_umax = 1.0 / umax
    usl = [ui * inv_umax for ui in ul]
    ts = tl_eff * inv_umax
    budget_possible = ts < math.fsum(usl) * (1 - 1e-15)
    tsb = ts if budget_possible else math.inf
    key = (k, n, unipolar)

    # ---- fast exit: the least-norm exact fit F^T (F F^T)^-1 f inside the bounds is the answer
    y0, x0 = _least_norm_fit(fs, ft, ffT, c2, k)
    xl = x0.tolist()
    ft2 = float(ft.dot(ft))
    if inside(xl, usl, tsb, unipolar) and _fits(fs, ft, x0, ft2, c2):
        if warm is not None:
            warm.face = ([True] * n, [1.0 if v >= 0.0 else -1.0 for v in xl], [0.0] * n, False)
            warm.key = key
        return x0 * umax

    ws = Workspace(fs, ft, usl, ts, budget_possible, unipolar, k)
    eps = EPS_REL * max(c2, 1e-300)
    gscale = c2 + math.sqrt(float(ws.q.dot(ws.q))) + 1e-300
    ws.tol = MULT_TOL * gscale
    ws.max_iter = 50 + 10 * n if max_iter is None else max_iter
    x, face, keep = _iterate(ws, eps, xl, warm, key)
    x, y, res2, face = _polish_final(ws, eps, x, face, keep)
    final = (face.free, face.sg, face.fixv, face.bud)
    # ---- an exact fit: the least-energy stage on its own, free of eps (see least_energy)
    lim = EXACT_FIT_TOL * (math.sqrt(ft2) + math.sqrt(c2 * float(x.dot(x))))
    if res2 <= lim * lim:
        x2 = least_energy(ws, y0 if y is None else y, lim, c2)
        if x2 is not None:
            x = x2
            if warm is not None:
                final = point_face(x.tolist(), usl, ts, budget_possible)
    if warm is not None:
        free, sg, fixv, bud = final
        warm.face = (free, sg, [v / ui if ui > 0.0 else 0.0 for v, ui in zip(fixv, usl)], bud)
        warm.key = key
    return _clamp(x, usl, ts, umax, 0.0 if unipolar else -1.0)


def _least_norm_fit(fs, ft, ffT, c2, k):
    """(y0, x0 = F^T y0): the least-norm exact fit F^T (F F^T)^-1 f. A 1e-14 shift keeps the
    solve regular whatever F; one refinement step removes it."""
    mreg = ffT + (1e-14 * c2) * eye(k)
    y0 = fast_solve(mreg, ft)
    y0 += fast_solve(mreg, ft - ffT.dot(y0))
    return y0, fs.T.dot(y0)


def _fits(fs, ft, x0, ft2, c2):
    """x0 fits the target to EXACT_FIT_TOL (relative to ||f|| + ||F|| ||x0||)."""
    r = fs.dot(x0) - ft
    lim = EXACT_FIT_TOL * (math.sqrt(ft2) + math.sqrt(c2 * float(x0.dot(x0))))
    return float(r.dot(r)) <= lim * lim


def _iterate(ws, eps, xl, warm, key):
    """The active set from the warm face if its minimizer is feasible here, else from the
    cold start (:func:`.cold_start.cold_start`, from the least-norm fit ``xl``). Returns
    (x, face, final face system)."""
    usl = ws.usl
    if warm is not None and warm.face is not None and warm.key == key:
        free, sg, rel, bud = warm.face
        fixv = [r * ui for r, ui in zip(rel, usl)]
        if bud and not ws.budget_possible:
            bud = False
        face = Face(free, sg, fixv, bud)
        kept = []
        xh = face_minimizer(ws, face, eps, keep=kept)
        if on_face(xh.tolist(), face, usl, ws.tsb, ws.unipolar):
            return active_set(ws, eps, xh, face, at_face=kept)
    xl = cold_start(ws, xl)
    return active_set(ws, eps, np.array(xl), Face.of_point(xl, usl, ws.ts, ws.budget_possible))


def _polish_final(ws, eps, x, face, keep):
    """The eps -> 0 limit on the final face (the lexicographic answer: least residual, then
    least energy) removes the Tikhonov bias when it stays on the face; if it leaves the face, a
    continuation pass with eps 1e4 x smaller (warm started, usually 1 face) first. Returns
    (x, y, residual^2, face)."""
    x, ok, y, res2 = polish(ws, x, face, keep, eps)
    if not ok:
        x, face, keep = active_set(ws, eps * 1e-4, x, face)
        x, _, y, res2 = polish(ws, x, face, keep, eps * 1e-4)
    if res2 is None:
        r = ws.fs.dot(x) - ws.ft
        res2 = float(r.dot(r))
    return x, y, res2, face


def _clamp(x, usl, ts, umax, lo):
    """The guarantee: never outside the bounds, whatever round-off did; back to amperes."""
    xl = [(v if v < ui else ui) if v > lo * ui else lo * ui for v, ui in zip(x.tolist(), usl)]
    tot = math.fsum(map(abs, xl))
    sc = umax * ts / tot if tot > ts else umax
    return np.array(xl) * sc
