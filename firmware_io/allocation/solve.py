"""`allocate` and `Allocator`: one bounded allocation solve, cold or warm, in named phases.

scale -> least-norm fast exit -> start (warm face or cold projection) -> active set -> polish
(eps -> 0) -> least-energy exact fit -> clamp to the bounds. Inputs and outputs in SI (A, N);
the phases work in the scaled units of :func:`.problem._scale`. Method: docs/allocation.md.
"""

from __future__ import annotations

import math

import numpy as np

from .active_set import _active_set, _cold_start
from .faces import _face_minimizer
from .feasible import _inside, _on_face
from .linalg import _eye, _fast_solve
from .polish import _least_energy, _polish
from .problem import (_EXACT_FIT_TOL, _FLOAT_MAX, _INF, _MULT_TOL, EPS_REL, _check_inputs,
                      _scale)


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
    fm, t, u, tl, scale_e = _check_inputs(force_matrix, target, current_limit, total_limit,
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
            res = _FLOAT_MAX
    return x, res


class Allocator:
    """`allocate` with a warm start, for a control loop that solves at nearby positions.

    It keeps the working set of the last solve (which coils were free, at 0, at +-u, and
    whether the budget held with equality) and tries that face first: when it is still optimal
    (the usual case between two control periods) the solve is one face solve, its multiplier
    check and the eps -> 0 polish. The result is the exact answer of `allocate` whatever the
    start (a stale face is only a start for the same active-set method). A call with another
    number of rows or coils, another drive mode, or limits that change which coils are off,
    starts cold.

    Usage::

        alloc = Allocator()
        currents_a, residual = alloc(F, f_n, 6.0, 54.0, unipolar=True)   # same as allocate
    """

    __slots__ = ("face", "key")

    def __init__(self):
        self.face = None    # (free, sg, fixed value / u_i, budget) of the last final face
        self.key = None     # (k, n, unipolar) it belongs to

    def reset(self) -> None:
        """Forget the warm start."""
        self.face = None
        self.key = None

    def __call__(self, force_matrix, target, current_limit, total_limit, *,
                 unipolar: bool = False, bias=None, max_iter: int | None = None):
        return allocate(force_matrix, target, current_limit, total_limit, unipolar=unipolar,
                        bias=bias, max_iter=max_iter, warm=self)


def _solve(fm, f, ul, tl, unipolar, max_iter, warm=None):
    """The currents (n,), A, for the checked inputs (F, f, u list, I_t) of `allocate`."""
    k, n = fm.shape
    umax = max(ul)
    tl_eff = min(tl, math.fsum(ul))
    if umax == 0.0 or tl_eff == 0.0:
        return np.zeros(n)
    scaled = _scale(fm, f, umax)
    if scaled is None:
        return np.zeros(n)
    fs, ft, c2, ffT, k = scaled
    inv_umax = 1.0 / umax
    usl = [ui * inv_umax for ui in ul]
    ts = tl_eff * inv_umax
    budget_possible = ts < math.fsum(usl) * (1 - 1e-15)
    tsb = ts if budget_possible else _INF
    eps = EPS_REL * max(c2, 1e-300)
    key = (k, n, unipolar)

    # ---- fast exit: the least-norm exact fit F^T (F F^T)^-1 f inside the bounds is the answer
    y0, x0 = _least_norm_fit(fs, ft, ffT, c2, k)
    xl = x0.tolist()
    ft2 = float(ft.dot(ft))
    if _inside(xl, usl, tsb, unipolar) and _fits(fs, ft, x0, ft2, c2):
        if warm is not None:
            warm.face = ([True] * n, [1.0 if v >= 0.0 else -1.0 for v in xl], [0.0] * n, False)
            warm.key = key
        return x0 * umax

    h = fs.T.dot(fs)
    q = fs.T.dot(ft)
    gscale = c2 + math.sqrt(float(q.dot(q))) + 1e-300
    tol = _MULT_TOL * gscale
    if max_iter is None:
        max_iter = 50 + 10 * n
    common = (fs, ft, h, q, usl, ts)
    state = _iterate(common, tsb, eps, tol, unipolar, budget_possible, k, n, max_iter, xl,
                     warm, key)
    x, y, res2, state = _polish_final(common, eps, tol, unipolar, budget_possible, k, n,
                                      max_iter, state)
    # ---- an exact fit: the least-energy stage on its own, free of eps (see _least_energy)
    lim = _EXACT_FIT_TOL * (math.sqrt(ft2) + math.sqrt(c2 * float(x.dot(x))))
    if res2 <= lim * lim:
        x2 = _least_energy(fs, ft, usl, tsb, unipolar, y0 if y is None else y, lim, c2, k)
        if x2 is not None:
            x = x2
            if warm is not None:
                state = _face_of(x, usl, ts, budget_possible)
    if warm is not None:
        _, free, sg, fixv, bud, _ = state
        warm.face = (free, sg, [v / ui if ui > 0.0 else 0.0 for v, ui in zip(fixv, usl)], bud)
        warm.key = key
    return _clamp(x, usl, ts, umax, 0.0 if unipolar else -1.0)


def _least_norm_fit(fs, ft, ffT, c2, k):
    """(y0, x0 = F^T y0): the least-norm exact fit F^T (F F^T)^-1 f. A 1e-14 shift keeps the
    solve regular whatever F; one refinement step removes it."""
    mreg = ffT + (1e-14 * c2) * _eye(k)
    y0 = _fast_solve(mreg, ft)
    y0 += _fast_solve(mreg, ft - ffT.dot(y0))
    return y0, fs.T.dot(y0)


def _fits(fs, ft, x0, ft2, c2):
    """x0 fits the target to _EXACT_FIT_TOL (relative to ||f|| + ||F|| ||x0||)."""
    r = fs.dot(x0) - ft
    lim = _EXACT_FIT_TOL * (math.sqrt(ft2) + math.sqrt(c2 * float(x0.dot(x0))))
    return float(r.dot(r)) <= lim * lim


def _iterate(common, tsb, eps, tol, unipolar, budget_possible, k, n, max_iter, xl, warm, key):
    """The active set from the warm face if its minimizer is feasible here, else from the
    cold start (`_cold_start`, from the least-norm fit ``xl``). Returns its state (x, free,
    sg, fixv, bud, final face system)."""
    fs, ft, h, q, usl, ts = common
    if warm is not None and warm.face is not None and warm.key == key:
        free, sg, rel, bud = warm.face
        fixv = [r * ui for r, ui in zip(rel, usl)]
        if bud and not budget_possible:
            bud = False
        kept = []
        xh = _face_minimizer(fs, ft, eps, free, sg, fixv, bud, ts, k, keep=kept)
        if _on_face(xh.tolist(), free, sg, usl, tsb, bud, unipolar):
            return _active_set(fs, ft, h, q, usl, ts, eps, tol, unipolar, budget_possible,
                               k, n, max_iter, xh, free, sg, fixv, bud, at_face=kept)
    xl = _cold_start(fs, ft, q, xl, usl, tsb, unipolar)
    x, free, sg, fixv, bud, _ = _face_of(np.array(xl), usl, ts, budget_possible, xl)
    return _active_set(fs, ft, h, q, usl, ts, eps, tol, unipolar, budget_possible, k, n,
                       max_iter, x, free, sg, fixv, bud)


def _face_of(x, usl, ts, budget_possible, xl=None):
    """The working set of a feasible point x: (x, free, sg, fixv, bud, []), free the coils
    strictly inside their box, bud when the budget holds to 1e-12."""
    xl = x.tolist() if xl is None else xl
    free = [0.0 < abs(v) < ui for v, ui in zip(xl, usl)]
    sg = [1.0 if v >= 0.0 else -1.0 for v in xl]
    fixv = [0.0 if fr else v for v, fr in zip(xl, free)]
    bud = budget_possible and any(free) and math.fsum(map(abs, xl)) >= ts * (1 - 1e-12)
    return x, free, sg, fixv, bud, []


def _polish_final(common, eps, tol, unipolar, budget_possible, k, n, max_iter, state):
    """The eps -> 0 limit on the final face (the lexicographic answer: least residual, then
    least energy) removes the Tikhonov bias when it stays on the face; if it leaves the face, a
    continuation pass with eps 1e4 x smaller (warm started, usually 1 face) first. Returns
    (x, y, residual^2, state)."""
    fs, ft, h, q, usl, ts = common
    x, ok, y, res2 = _polish(fs, ft, h, q, usl, ts, k, unipolar, *state, eps)
    if not ok:
        state = _active_set(fs, ft, h, q, usl, ts, eps * 1e-4, tol, unipolar, budget_possible,
                            k, n, max_iter, *state[:5])
        x, _, y, res2 = _polish(fs, ft, h, q, usl, ts, k, unipolar, *state, eps * 1e-4)
    if res2 is None:
        r = fs.dot(x) - ft
        res2 = float(r.dot(r))
    return x, y, res2, state


def _clamp(x, usl, ts, umax, lo):
    """The guarantee: never outside the bounds, whatever round-off did; back to amperes."""
    xl = [(v if v < ui else ui) if v > lo * ui else lo * ui for v, ui in zip(x.tolist(), usl)]
    tot = math.fsum(map(abs, xl))
    sc = umax * ts / tot if tot > ts else umax
    return np.array(xl) * sc
