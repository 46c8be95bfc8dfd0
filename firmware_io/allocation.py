"""Exact bounded current allocation (thesis eq. 4.9) -- numpy only, it runs on the controller.

Problem, for one magnet position p with the force matrix F = F(p) (k, n) of the caller's rows
(k = 1: Fz only as in the thesis; k = 3: the force; k = 6: force and torque) and the target f::

    minimize    ||F I - f||^2                       (N^2, or the caller's row units squared)
    subject to  -u_i <= I_i <= u_i                   (bipolar, default: the MD10C reverses)
                 0   <= I_i <= u_i                   (unipolar=True: the thesis' drive)
                 sum_i |I_i| <= I_t                  (supply budget)

Among the minimizers (F has a null space as soon as n > k) the least-energy one (min sum I^2)
is returned, so the answer is unique and continuous in p.

Method: a primal active-set method on the strictly convex problem

    minimize ||F I - f||^2 + eps ||I||^2,   eps = 1e-10 * max_i ||F[:, i]||^2 * (u_max / s)^2

(in scaled units, see ``_solve``), written on the bipolar split I = I+ - I- (2n non-negative
variables, box + one linear inequality; each coil is free with a sign, at +-u, or at 0). The
Tikhonov term makes the solution unique and equal, up to the bias below, to the
lexicographic answer (least residual first, least energy second). Bias bound: if I* is the
least-energy minimizer, the returned I_eps satisfies

    ||F I_eps - f||^2 - ||F I* - f||^2 <= eps (||I*||^2 - ||I_eps||^2) <= eps * u_max * I_t',

with I_t' = min(I_t, sum u_i), i.e. <= 1e-10 of (max column force x u_max)^2 x n, and the
stationarity conditions of the unregularized problem hold up to eps ||I|| (1e-10 relative).
Each equality-constrained sub-problem is solved in the smaller of two exact forms: the primal
normal equations when at most k coils are free, otherwise the kernel form I_J = F_J^T y (+ t s),
which keeps the solution exactly in the row space (the least-energy direction) by construction.

The steps of one solve (each cheap for n ~ 9: the bookkeeping is plain Python over the coils,
numpy only for the products and the k x k / n x n solves; at this size each numpy call costs
~0.3-2 us of overhead, so the code counts them: ``ndarray.dot`` rather than the ``@`` operator,
~0.8 us dearer per call here; ``take``/``put`` with index lists rather than fancy or boolean
indexing, ~1.5 us dearer):

1. Fast exit: the least-norm exact fit F^T (F F^T)^-1 f, if inside the bounds, is the answer.
2. Start: the last final face (``Allocator``, warm) if its minimizer is still feasible, else
   (cold) the least-residual point between two projections onto the bounds, and its working
   set: of the least-norm fit, and of a far multiple of F^T f (the bang-bang pattern
   unreachable targets end at; from the least-norm fit alone each wrong-signed coil costs 2-4
   faces).
3. The primal active set above; then the eps -> 0 polish on its final face: the face's
   system as the active set last solved it, with its eps part subtracted (``keep`` of
   ``_face_minimizer``; rebuilt only if the iteration cap stopped the loop between faces).
   Bipolar, while the budget is not in the working set, the face does not depend on a free
   coil's sign, so a coil crosses 0 in one step (only +-u block it; the budget's ratio test
   follows sum |x|, piecewise linear along the step, ``_budget_hit``). Budget faces slice a
   kept bordered system [[F^T F + eps I, sg], [sg^T, 0]] (each face solve is ~10 small numpy
   calls).
4. Reachable targets: the least-energy stage exactly, as its own problem -- x = proj(F^T y) with
   F x = f, Newton on y (``_least_energy``). The eps-regularized active set resolves the
   tie-break only through eps-sized multipliers (to ~1e-3 relative in the currents); this step
   makes it exact, so the cold and the warm start give the same currents.

The bias force: the magnet's pull on the iron cores at zero current, F0(p), is not produced by
the currents, so the currents must render ``f - F0(p)``. Pass ``bias=F0`` (same rows as
``target``) or subtract it yourself; with map v2 it is ``MapFile.bias_force(points)``.

Usage::

    from firmware_io.allocation import Allocator, allocate
    currents_a, residual = allocate(F, f_n, 6.0, 54.0)               # bipolar
    currents_a, residual = allocate(F, f_n, 6.0, 54.0, unipolar=True)
    alloc = Allocator()                                               # in a control loop:
    currents_a, residual = alloc(F, f_n, 6.0, 54.0, unipolar=True)   # same answer, warm start
"""

from __future__ import annotations

import math

import numpy as np

from .errors import BadInputError

EPS_REL = 1e-10
"""Tikhonov weight relative to the largest squared column norm of the scaled F (see above)."""

_MULT_TOL = 1e-13
"""Multipliers above -_MULT_TOL x (gradient scale) count as non-negative (rounding level,
three decades below the eps-level multipliers of the tie-break)."""

_EXACT_FIT_TOL = 1e-11
"""The least-norm exact fit is accepted when ||F x - f|| <= this x (||f|| + ||F|| ||x||): two
decades inside the 1e-9 KKT tolerance (the gradient F^T r is at most ||F|| ||r||)."""


_INF = math.inf
_FLOAT_MAX = float.fromhex("0x1.fffffffffffffp+1023")


def _bad_matrix(fm):
    bad = np.argwhere(~np.isfinite(fm))[0]
    raise BadInputError("force_matrix", "finite (no NaN or Inf), N/A",
                        f"{fm[tuple(bad)]} at index {tuple(int(b) for b in bad)}")


def _check_inputs(force_matrix, target, current_limit, total_limit, bias):
    """(F (k, n) ndarray, f (k,) ndarray, u list of n floats, I_t float); cheap checks first
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
        if not 0.0 <= ui < _INF:
            raise BadInputError("current_limit", "finite and >= 0 (per coil), A", ui)
    try:
        tl = float(total_limit)
    except (TypeError, ValueError):
        raise BadInputError("total_limit", ">= 0 A (inf: no budget)", total_limit) from None
    if not tl >= 0.0:
        raise BadInputError("total_limit", ">= 0 A (inf: no budget); a negative budget "
                            "makes sum |I| <= I_t infeasible", tl)
    return fm, t, u, tl, scale_e


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
        self.face = None    # (free, sign, fixed value / u_i, budget) of the last final face
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
    k, n = fm.shape
    umax = max(ul)
    tl_eff = min(tl, math.fsum(ul))
    if umax == 0.0 or tl_eff == 0.0:
        return np.zeros(n)
    # scale currents by u_max and forces by the largest achievable column force u_max |F_i|
    # (or the target, if larger)
    cmax = max(fm.T.dot(fm).diagonal().tolist())  # entries < 1e150 here (_check_inputs)
    fmax = max(map(abs, f.tolist()))
    cs = math.sqrt(cmax) * umax
    fscale = cs if cs > fmax else fmax
    if fscale == 0.0:
        return np.zeros(n)
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
                return np.zeros(n)
            fs, ft = fs.take(keep, 0), ft.take(keep)
            k = len(keep)
            ffT = ffT.take(keep, 0).take(keep, 1)
    inv_umax = 1.0 / umax
    usl = [ui * inv_umax for ui in ul]
    ts = tl_eff * inv_umax
    budget_possible = ts < math.fsum(usl) * (1 - 1e-15)
    tsb = ts if budget_possible else _INF
    eps = EPS_REL * max(c2, 1e-300)
    lo = 0.0 if unipolar else -1.0

    # ---- fast exit: the least-norm exact fit F^T (F F^T)^-1 f inside the bounds is the answer
    # (a 1e-14 shift keeps the solve regular whatever F; one refinement step removes it)
    mreg = ffT + (1e-14 * c2) * _eye(k)
    y0 = _fast_solve(mreg, ft)
    y0 += _fast_solve(mreg, ft - ffT.dot(y0))
    x0 = fs.T.dot(y0)
    xl = x0.tolist()
    ft2 = float(ft.dot(ft))
    if _inside(xl, usl, tsb, unipolar):
        r = fs.dot(x0) - ft
        lim = _EXACT_FIT_TOL * (math.sqrt(ft2) + math.sqrt(c2 * float(x0.dot(x0))))
        if float(r.dot(r)) <= lim * lim:
            if warm is not None:
                warm.face = ([True] * n, [1.0 if v >= 0.0 else -1.0 for v in xl], [0.0] * n,
                             False)
                warm.key = (k, n, unipolar)
            return x0 * umax

    h = fs.T.dot(fs)
    q = fs.T.dot(ft)
    gscale = c2 + math.sqrt(float(q.dot(q))) + 1e-300
    tol = _MULT_TOL * gscale
    if max_iter is None:
        max_iter = 50 + 10 * n
    state = None
    key = (k, n, unipolar)
    if warm is not None and warm.face is not None and warm.key == key:
        # ---- warm start: the last final face, if its minimizer is feasible here
        free, sg, rel, bud = warm.face
        fixv = [r * ui for r, ui in zip(rel, usl)]
        if bud and not budget_possible:
            bud = False
        kept = []
        xh = _face_minimizer(fs, ft, eps, free, sg, fixv, bud, ts, k, keep=kept)
        if _on_face(xh.tolist(), free, sg, usl, tsb, bud, unipolar):
            state = _active_set(fs, ft, h, q, usl, ts, eps, tol, unipolar, budget_possible,
                                k, n, max_iter, xh, free, sg, fixv, bud, at_face=kept)
    if state is None:
        # ---- cold start: a feasible point between two projections (_cold_start), its face
        xl = _cold_start(fs, ft, q, xl, usl, tsb, unipolar)
        x = np.array(xl)
        free = [0.0 < abs(v) < ui for v, ui in zip(xl, usl)]
        sg = [1.0 if v >= 0.0 else -1.0 for v in xl]
        fixv = [0.0 if fr else v for v, fr in zip(xl, free)]
        bud = budget_possible and any(free) and math.fsum(map(abs, xl)) >= ts * (1 - 1e-12)
        state = _active_set(fs, ft, h, q, usl, ts, eps, tol, unipolar, budget_possible, k, n,
                            max_iter, x, free, sg, fixv, bud)
    # ---- polish: the eps -> 0 limit on the final face (the lexicographic answer: least residual,
    # then least energy) removes the Tikhonov bias when it stays on the face; if it leaves the
    # face, a continuation pass with eps 1e4 x smaller (warm started, usually 1 face) first
    # (state: x, free, sg, fixv, bud and the final face's system, see _active_set)
    x, ok, y, res2 = _polish(fs, ft, h, q, usl, ts, k, unipolar, *state, eps)
    if not ok:
        state = _active_set(fs, ft, h, q, usl, ts, eps * 1e-4, tol, unipolar, budget_possible,
                            k, n, max_iter, *state[:5])
        x, _, y, res2 = _polish(fs, ft, h, q, usl, ts, k, unipolar, *state, eps * 1e-4)
    if res2 is None:
        r = fs.dot(x) - ft
        res2 = float(r.dot(r))
    # ---- an exact fit: the least-energy stage on its own, free of eps (see _least_energy)
    lim = _EXACT_FIT_TOL * (math.sqrt(ft2) + math.sqrt(c2 * float(x.dot(x))))
    if res2 <= lim * lim:
        x2 = _least_energy(fs, ft, usl, tsb, unipolar, y0 if y is None else y, lim, c2, k)
        if x2 is not None:
            x = x2
            if warm is not None:
                xl = x.tolist()
                free = [0.0 < abs(v) < ui for v, ui in zip(xl, usl)]
                state = (x, free, [1.0 if v >= 0.0 else -1.0 for v in xl],
                         [0.0 if fr else v for v, fr in zip(xl, free)],
                         budget_possible and any(free)
                         and math.fsum(map(abs, xl)) >= ts * (1 - 1e-12), [])
    if warm is not None:
        _, free, sg, fixv, bud, _ = state
        warm.face = (free, sg, [v / ui if ui > 0.0 else 0.0 for v, ui in zip(fixv, usl)], bud)
        warm.key = key
    # ---- guarantee: never outside the bounds, whatever round-off did
    xl = [(v if v < ui else ui) if v > lo * ui else lo * ui for v, ui in zip(x.tolist(), usl)]
    tot = math.fsum(map(abs, xl))
    sc = umax * ts / tot if tot > ts else umax
    return np.array(xl) * sc


_EYES = [np.eye(i) for i in range(16)]
_EYES_B = [np.diag([1.0] * i + [0.0]) for i in range(16)]


def _eye(m):
    return _EYES[m] if m < 16 else np.eye(m)


def _eye_bordered(m):
    """The (m + 1) x (m + 1) identity with a 0 in the last place (the border)."""
    return _EYES_B[m] if m < 16 else np.diag([1.0] * m + [0.0])


def _inside(xl, usl, ts, unipolar):
    """x (list) inside the box and the budget."""
    tot = 0.0
    if unipolar:
        for v, ui in zip(xl, usl):
            if not 0.0 <= v <= ui:
                return False
            tot += v
    else:
        for v, ui in zip(xl, usl):
            a = abs(v)
            if not a <= ui:
                return False
            tot += a
    return tot <= ts


def _on_face(xl, free, sg, usl, ts, bud, unipolar):
    """x (list) feasible and on the working face: free coils on their side inside the box
    (either side, bipolar without the budget), fixed ones where they were put, the budget
    kept."""
    tot = 0.0
    signfree = not (unipolar or bud)
    for v, fr, s, ui in zip(xl, free, sg, usl):
        a = abs(v) if signfree else s * v
        if fr and not 0.0 <= a <= ui:
            return False
        tot += abs(v)
    return bud or tot <= ts


def _polish(fs, ft, h, q, usl, ts, k, unipolar, x, free, sg, fixv, bud, kept, eps):
    """(x, accepted, y): the eps = 0 face minimizer if it stays on the face (box and budget)
    and is no worse; y its kernel coefficients (None in the primal form). Bipolar without the
    budget in the working set, a free coil may take either sign (see `_active_set`). ``h``,
    ``q``: F^T F and F^T f. ``kept``: this face's system as the active set last solved it
    (`_face_minimizer`'s ``keep``; empty if it did not), whose eps part is taken out."""
    if not any(free):
        r = fs.dot(x) - ft
        return x, True, None, float(r.dot(r))
    if kept:
        j, mat, rhs, aj, m = kept
        size = mat.shape[0]
        mat = mat - eps * (_eye(size) if m == size else _eye_bordered(m))
        sol = _lsolve(mat, rhs, False)
        xp = np.array(fixv)
        if aj is None:
            xp.put(j, sol)
            y = None
        else:
            xp.put(j, aj.T.dot(sol))
            y = sol[:k]
    else:
        xp, y = _face_minimizer(fs, ft, 0.0, free, sg, fixv, bud, ts, k, want_y=True, heps=h,
                                q=q)
    xpl = xp.tolist()
    slack = 1e-12 * max(usl)
    signfree = not (unipolar or bud)
    clamped = False
    for i, fr in enumerate(free):
        if fr:
            a, ui = xpl[i], usl[i]
            if signfree:
                if not -ui - slack <= a <= ui + slack:
                    return x, False, None, None
                if not -ui <= a <= ui:
                    xpl[i] = min(max(a, -ui), ui)
                    clamped = True
                continue
            s = sg[i]
            if not -slack <= s * a <= ui + slack:
                return x, False, None, None
            if not 0.0 <= s * a <= ui:
                xpl[i] = s * min(max(s * a, 0.0), ui)
                clamped = True
    if not bud and math.fsum(map(abs, xpl)) > ts * (1 + 1e-12):
        return x, False, None, None  # the Tikhonov bias kept it inside the budget; eps -> 0 does not
    if clamped:
        xp = np.array(xpl)
    rp, rx = fs.dot(xp) - ft, fs.dot(x) - ft
    ep, ex = float(rp.dot(rp)), float(rx.dot(rx))
    # "no worse" up to rounding: the two objectives often agree to 1e-16 relative (eps only
    # shifts a determined face by ~1e-10), and a coin flip there would send a third of the
    # hard problems through the continuation pass for nothing
    if ep <= ex * (1.0 + 1e-12) + 1e-24 * float(ft.dot(ft)):
        return xp, True, y, ep
    return x, False, None, ex


def _active_set(fs, ft, h, q, usl, ts, eps, tol, unipolar, budget_possible, k, n, max_iter,
                x, free, sg, fixv, bud, at_face=None):
    """Primal active-set iterations from a feasible point x and its working set: ``free``
    (list of bool), the sign ``sg`` of each free coil, the value ``fixv`` of each fixed one and
    ``bud`` (the budget held with equality). ``at_face``: x is already this face's minimizer,
    and this (a list, maybe empty) its system from `_face_minimizer`'s ``keep``. Returns
    (x, free, sg, fixv, bud, system of the final face as ``keep`` has it, or [])."""
    heps = h + eps * _eye(n)
    if not budget_possible:  # no budget face will be solved
        return _active_set_loop(fs, ft, heps, q, usl, ts, tol, unipolar, False, k, n,
                                max_iter, x, free, sg, fixv, bud, at_face, eps, None)
    aug_a = np.empty((k + 1, n))
    aug_a[:k] = fs
    aug_a[k] = sg
    aug_b = np.empty(k + 1)
    aug_b[:k] = ft
    aug_b[k] = ts
    # the bordered [[F^T F + eps I, sg], [sg^T, 0]] and [F^T f; I_t]: a budget face's primal
    # system is their (free coils + budget) slice
    hb = np.empty((n + 1, n + 1))
    hb[:n, :n] = heps
    hb[n, :n] = sg
    hb[:n, n] = sg
    hb[n, n] = 0.0
    qb = np.empty(n + 1)
    qb[:n] = q
    qb[n] = ts
    aug = (aug_a, aug_b, hb, qb)
    return _active_set_loop(fs, ft, heps, q, usl, ts, tol, unipolar, True, k, n,
                            max_iter, x, free, sg, fixv, bud, at_face, eps, aug)


def _active_set_loop(fs, ft, heps, q, usl, ts, tol, unipolar, budget_possible, k, n, max_iter,
                     x, free, sg, fixv, bud, at_face, eps, aug):
    rng = range(n)
    if aug is not None:
        aug_a, hb = aug[0], aug[2]
    xl = x.tolist()
    keep = at_face if at_face is not None else []  # the last face system solved (the polish)
    j = [i for i in rng if free[i]]  # the free coils and [fixv, 0], kept with free and fixv
    fe = np.array(fixv + [0.0])
    for _ in range(max_iter):
        if at_face is not None:
            xh, at_face = x, None
        else:
            xh = _face_minimizer(fs, ft, eps, free, sg, fixv, bud, ts, k, heps=heps, q=q,
                                 aug=aug, keep=keep, jfe=(j, fe))
        if j:
            hl = xh.tolist()
            alpha, block, kind, rate = 1.0, -1, 0, 0.0
            if unipolar or bud:
                for i in j:
                    s = sg[i]
                    sp = s * (hl[i] - xl[i])
                    rate += sp
                    if sp < 0.0:
                        a = s * xl[i] / -sp
                        if a < alpha:
                            alpha, block, kind = a, i, 0
                    elif sp > 0.0:
                        a = (usl[i] - s * xl[i]) / sp
                        if a < alpha:
                            alpha, block, kind = a, i, 1
                if budget_possible and not bud and rate > 0.0:
                    a = (ts - math.fsum(map(abs, xl))) / rate
                    if a < alpha:
                        alpha, block, kind = max(a, 0.0), -1, 2
            else:
                # bipolar, budget not in the working set: the face does not depend on a free
                # coil's sign, so a coil crosses 0 in one step (the split form's -u -> 0 -> +u
                # would cost two extra faces); only +-u block, and the budget, whose sum |x|
                # is piecewise linear along the step
                bsign = 1.0
                for i in j:
                    d = hl[i] - xl[i]
                    if d > 0.0:
                        a = (usl[i] - xl[i]) / d
                        if a < alpha:
                            alpha, block, kind, bsign = a, i, 1, 1.0
                    elif d < 0.0:
                        a = (usl[i] + xl[i]) / -d
                        if a < alpha:
                            alpha, block, kind, bsign = a, i, 1, -1.0
                if budget_possible:
                    a = _budget_hit(xl, hl, alpha, ts)
                    if a < alpha:
                        alpha, block, kind = a, -1, 2
                if kind == 1:
                    sg = list(sg)
                    sg[block] = bsign
                    if aug is not None:
                        aug_a[k, block] = hb[n, block] = hb[block, n] = bsign
            if alpha < 1.0:
                alpha = max(alpha, 0.0)
                for i in j:  # (a fixed coil is at its value in both xl and hl)
                    v = xl[i]
                    xl[i] = v + alpha * (hl[i] - v)
                if kind == 2:
                    if not bud and not unipolar:
                        # the budget face fixes each free coil's sign: the side it is on (or
                        # moving to, at 0)
                        sg = list(sg)
                        for i in j:
                            v = xl[i]
                            sg[i] = (1.0 if v > 0.0 else -1.0) if v != 0.0 else (
                                1.0 if hl[i] >= 0.0 else -1.0)
                        aug_a[k] = sg
                        hb[n, :n] = sg
                        hb[:n, n] = sg
                    bud = True
                else:
                    free = list(free)
                    fixv = list(fixv)
                    free[block] = False
                    fixv[block] = fe[block] = xl[block] = (0.0 if kind == 0
                                                           else sg[block] * usl[block])
                    j = [i for i in j if i != block]
                # keep free coordinates on their side and inside the box under round-off
                if unipolar or bud:
                    for i in j:
                        s = sg[i]
                        xl[i] = s * min(max(s * xl[i], 0.0), usl[i])
                else:
                    for i in j:
                        ui = usl[i]
                        xl[i] = min(max(xl[i], -ui), ui)
                x = None
                if bud and not j:
                    bud = False  # implied by the bounds: a redundant working constraint
                continue
            xl = hl
        else:
            xl = xh.tolist()
        x = xh
        # ---- at the face minimizer: multipliers of the working constraints
        g = (heps.dot(x) - q).tolist()
        nu = 0.0
        if bud and j:
            acc = 0.0
            for i in j:
                acc += sg[i] * g[i]
            nu = -acc / len(j)
        best, m = _INF, -1
        for i in rng:
            if free[i] or usl[i] == 0.0:  # a coil with u_i = 0 is off: nothing to release
                continue
            fv = fixv[i]
            if fv == 0.0:
                lam = g[i] + nu if unipolar else nu - abs(g[i])
            else:
                lam = -(g[i] + nu) if fv > 0.0 else g[i] - nu
            if lam < best:
                best, m = lam, i
        lam_b = nu if bud else _INF
        if min(best, lam_b) >= -tol:
            break
        if lam_b < best:
            bud = False
        else:
            free = list(free)
            sg = list(sg)
            fixv = list(fixv)
            free[m] = True
            fv = fixv[m]
            if fv == 0.0:
                sg[m] = 1.0 if (unipolar or g[m] < 0.0) else -1.0
            else:
                sg[m] = 1.0 if fv > 0.0 else -1.0
            if aug is not None:
                aug_a[k, m] = hb[n, m] = hb[m, n] = sg[m]
            fixv[m] = fe[m] = 0.0
            j = sorted(j + [m])
    if x is None:  # the iteration cap hit after a step: the current feasible point
        x = np.array(xl)
        keep = []
    return x, free, sg, fixv, bud, keep


def _cold_start(fs, ft, q, xl, usl, ts, unipolar):
    """The cold start: the least-residual point on the segment between two feasible
    projections (feasible too: the set is convex), of the least-norm exact fit ``xl`` and of a
    far multiple of F^T f (the bang-bang guess: coils at their limits with the sign of their
    correlation with the target, the budget spent on the best-correlated ones). Unreachable
    targets end at such a pattern; starting from the least-norm fit alone, each coil whose sign
    is wrong there costs 2-4 faces to flip. The residual is quadratic along the segment (its
    minimum from the two end residuals); within 5 % of an end, that end itself. On the
    benchmark's random mix this saves ~3 % of the faces against the better end alone."""
    cand = _proj_list(xl, usl, ts, unipolar)[0]
    fq = fs.dot(q)
    den = float(fq.dot(fq))
    if not den > 0.0:
        return cand
    c = min(1e3 * float(ft.dot(fq)) / den, 1e290)  # scaled |q_i| <= k: no overflow below
    cand2 = _proj_list([c * v for v in q.tolist()], usl, ts, unipolar)[0]
    r = np.array([cand, cand2]).dot(fs.T) - ft
    r1, d = r[0], r[1] - r[0]
    dd = float(d.dot(d))
    t = -float(r1.dot(d)) / dd if dd > 0.0 else 0.0
    if t < 0.05:
        return cand
    if t > 0.95:
        return cand2
    return [a + t * (b - a) for a, b in zip(cand, cand2)]


def _budget_hit(xl, hl, alpha, ts):
    """The first step a in [0, alpha] at which sum |x + a (h - x)| reaches ts (lists; convex
    and piecewise linear in a, breakpoints where a coordinate crosses 0); _INF if it stays
    within ts up to alpha."""
    if math.fsum(map(abs, hl)) <= ts:  # x is feasible and sum |.| convex: never above ts
        return _INF
    d = [w - v for v, w in zip(xl, hl)]
    t0 = math.fsum(map(abs, xl))
    tend = math.fsum(abs(v + alpha * e) for v, e in zip(xl, d))
    if tend <= ts:
        return _INF
    bps = sorted(-v / e for v, e in zip(xl, d) if e != 0.0 and 0.0 < -v / e < alpha)
    a0 = 0.0
    for a1 in bps + [alpha]:
        t1 = tend if a1 == alpha else math.fsum(abs(v + a1 * e) for v, e in zip(xl, d))
        if t1 > ts and t1 > t0:  # convex: once rising, it keeps rising
            return max(a0, a0 + (a1 - a0) * (ts - t0) / (t1 - t0))
        a0, t0 = a1, t1
    return alpha


def _face_minimizer(fs, ft, eps, free, sg, fixv, bud, ts, k, want_y=False, heps=None, q=None,
                    aug=None, keep=None, jfe=None):
    """Minimizer of the regularized objective on the working face (free coils keep their sign;
    with ``bud`` the budget holds with equality). ``want_y``: also the kernel coefficients y
    (x_J = F_J^T y + t s) when the kernel form applies, else None. ``heps``, ``q``: F^T F +
    eps I and F^T f if the caller has them (the primal form then slices them; one solve is
    ~10 small numpy calls, so every call saved counts). ``aug``: the (k + 1, n) matrix [F; sg]
    and the (k + 1,) vector [f; I_t] if the caller keeps them (a fixed coil's sign times its
    value is its |value|, so [f; I_t] - aug @ fixed is the kernel form's right-hand side).
    ``keep``: a list that receives this face's system (see `_polish`). ``jfe``: the free
    coils' indices and the array [fixv, 0], if the caller keeps them (``_active_set_loop``)."""
    n = len(fixv)
    if jfe is None:
        j = [i for i, fr in enumerate(free) if fr]
        fe = None
    else:
        j, fe = jfe
    nf = len(j)
    anyfix = any(fixv)
    if bud and aug is not None and 0 < nf <= k + 1:
        # primal normal equations of a budget face: a slice of the kept bordered system
        hb, qb = aug[2], aug[3]
        jj = j + [n]
        hr = hb.take(jj, 0)
        if anyfix:
            if fe is None:
                fe = np.array(fixv + [0.0])
            rhs = qb.take(jj) - hr.dot(fe)
            x = fe[:n].copy()
        else:
            rhs = qb.take(jj)
            x = np.zeros(n)
        mat = hr.take(jj, 1)
        if keep is not None:
            keep[:] = (j, mat, rhs, None, nf)
        x.put(j, _lsolve(mat, rhs, eps > 0))  # put: the first nf values
        return (x, None) if want_y else x
    if anyfix:  # a new array: written in place below
        fixed = np.array(fixv) if fe is None else fe[:n].copy()
    else:
        fixed = np.zeros(n)
    if nf == 0:
        return (fixed, None) if want_y else fixed
    if bud and aug is None:
        c = ts - math.fsum(map(abs, fixv))
    if nf > k + bud:
        # kernel form: x_J = F_J^T y (+ t s), exact in the row space
        if bud:
            # [F_J; s^T] [F_J; s^T]^T [y; t] = [r; c] (+ eps on the y block)
            if aug is not None:
                a, bt = aug[0], aug[1]
                aj = a.take(j, 1)
                rhs = (bt - a.dot(fixed)) if anyfix else bt
            else:
                a = np.empty((k + 1, n))
                a[:k] = fs
                a[k] = sg
                aj = a.take(j, 1)
                rhs = np.empty(k + 1)
                rhs[:k] = (ft - fs.dot(fixed)) if anyfix else ft
                rhs[k] = c
            mat = aj.dot(aj.T)
        else:
            aj = fs.take(j, 1)
            mat = aj.dot(aj.T)
            rhs = (ft - fs.dot(fixed)) if anyfix else ft
        if eps:
            mat += _eps_diag(eps, k, mat.shape[0])
        if keep is not None:
            keep[:] = (j, mat, rhs, aj, k)
        w = _lsolve(mat, rhs, eps > 0)
        x = fixed
        x.put(j, aj.T.dot(w))
        return (x, w[:k]) if want_y else x
    # primal normal equations on the free coils
    if heps is None:
        fj = fs.take(j, 1)
        hj = fj.T.dot(fj)
        if eps:
            hj += eps * _eye(nf)
        b = fj.T.dot((ft - fs.dot(fixed)) if anyfix else ft)
    else:
        hr = heps.take(j, 0)
        hj = hr.take(j, 1)
        b = q.take(j)
        if anyfix:  # the eps part of heps meets only free coordinates, where fixed is 0
            b = b - hr.dot(fixed)
    x = fixed
    if bud:
        mat = np.empty((nf + 1, nf + 1))
        mat[:nf, :nf] = hj
        sj = [sg[i] for i in j]
        mat[:nf, nf] = sj
        mat[nf, :nf] = sj
        mat[nf, nf] = 0.0
        rhs = np.empty(nf + 1)
        rhs[:nf] = b
        rhs[nf] = c
    else:
        mat, rhs = hj, b
    if keep is not None:
        keep[:] = (j, mat, rhs, None, nf)
    x.put(j, _lsolve(mat, rhs, eps > 0))
    return (x, None) if want_y else x


_EPS_DIAG = {}


def _eps_diag(eps, k, m):
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

    def _fast_solve(mat, rhs):
        return _solve1(mat, rhs, signature="dd->d")
except (ImportError, AttributeError):  # pragma: no cover - other numpy layouts
    _fast_solve = np.linalg.solve
    _SIG = {}

    def _solve1(mat, rhs):
        return np.linalg.solve(mat, rhs)


def _lsolve(mat, rhs, regularized=True):
    """Solve; ``regularized`` systems (eps > 0) are never singular, so they skip the
    floating-point guards; others fall back to least squares on an exactly singular face."""
    if regularized:
        out = _solve1(mat, rhs, **_SIG)
        if math.isfinite(sum(out.tolist())):  # inf - inf is nan: not finite either
            return out
    try:
        with np.errstate(invalid="raise", divide="raise", over="ignore"):
            out = _fast_solve(mat, rhs)
        if all(map(math.isfinite, out.tolist())):
            return out
    except (np.linalg.LinAlgError, FloatingPointError):
        pass
    return np.linalg.lstsq(mat, rhs, rcond=None)[0]


def _proj_list(v, us, ts, unipolar):
    """Euclidean projection of v (list) onto {lo <= x <= u, sum |x| <= ts} in plain Python
    floats (n ~ 9: a loop is cheaper than a dozen numpy calls). Returns (x, tau), tau the
    budget's soft threshold."""
    if unipolar:
        a = v
        c = [(ai if ai < ui else ui) if ai > 0.0 else 0.0 for ai, ui in zip(a, us)]
    else:
        a = list(map(abs, v))
        c = list(map(min, a, us))
    s = math.fsum(c)
    tau = 0.0
    if s > ts:
        # sum_i clip(a_i - tau, 0, u_i) is piecewise linear and decreasing in tau: sweep its
        # breakpoints (coil i enters the sloped part at max(a_i - u_i, 0), leaves it at a_i)
        ev = []
        for ai, ui in zip(a, us):
            if ai > 0.0 and ui > 0.0:
                lo = ai - ui
                ev.append((lo if lo > 0.0 else 0.0, -1))
                ev.append((ai, 1))
        ev.sort()
        t0, s0, slope = 0.0, s, 0
        tau = ev[-1][0]
        for t, e in ev:
            st = s0 + slope * (t - t0)
            if st <= ts:
                tau = t0 + (s0 - ts) / -slope
                break
            t0, s0 = t, st
            slope += e
        c = [min(max(ai - tau, 0.0), ui) for ai, ui in zip(a, us)]
    if unipolar:
        return c, tau
    return list(map(math.copysign, c, v)), tau


def _least_energy(fs, ft, usl, ts, unipolar, y, lim, c2, k, steps=6):
    """The least-energy exact fit: min ||x||^2 over {x in X, F x = f} for a reachable f.

    Its optimality conditions are x = proj_X(F^T y) with F x = f (y the multiplier of the fit),
    a k-dimensional piecewise-linear equation solved by Newton from the polished face's y
    (usually 0-1 steps). Unlike the eps-regularized active set, whose tie-break multipliers
    are eps-small and so resolved only to ~1e-3 relative, this is exact. Returns None if
    Newton does not land within ``steps`` (the caller keeps its answer)."""
    shift = (1e-14 * c2) * _eye(k)
    lim2 = lim * lim
    for _ in range(steps):
        xl, tau = _proj_list(fs.T.dot(y).tolist(), usl, ts, unipolar)
        x = np.array(xl)
        r = ft - fs.dot(x)
        if float(r.dot(r)) <= lim2:
            return x
        j = [i for i, (v, ui) in enumerate(zip(xl, usl)) if 0.0 < abs(v) < ui]
        if not j:
            return None
        fj = fs.take(j, 1)
        m = fj.dot(fj.T) + shift
        if tau > 0.0:
            wv = fj.dot(np.array([1.0 if xl[i] > 0.0 else -1.0 for i in j]))
            m -= np.outer(wv, wv) / len(j)
        y = y + _fast_solve(m, r)
    return None
