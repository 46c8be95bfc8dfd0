"""The minimizer of the regularized objective ||F x - f||^2 + eps ||x||^2 on one working face.

A face: some coils free (each keeping its sign ``sg``), the others fixed at 0 or +-u, and
optionally the budget held with equality. Each face is solved in the smaller of two exact
forms: the primal normal equations on the free coils when at most k (+1 with the budget) are
free, else the kernel form x_J = F_J^T y (+ t s), exact in the row space (docs/allocation.md).
Scaled units: currents / u_max, forces / the force scale of :func:`.problem._scale`.
"""

from __future__ import annotations

import math

import numpy as np

from .linalg import _eps_diag, _eye, _lsolve


def _face_minimizer(fs, ft, eps, free, sg, fixv, bud, ts, k, want_y=False, heps=None, q=None,
                    aug=None, keep=None, jfe=None):
    """Minimizer of the regularized objective on the working face (free coils keep their sign;
    with ``bud`` the budget holds with equality). ``want_y``: also the kernel coefficients y
    (x_J = F_J^T y + t s) when the kernel form applies, else None. ``heps``, ``q``: F^T F +
    eps I and F^T f if the caller has them (the primal form then slices them: every numpy call
    saved counts). ``aug``: the (k + 1, n) matrix [F; sg] and the (k + 1,) vector [f; I_t] if
    the caller keeps them (a fixed coil's sign times its value is its |value|, so [f; I_t] -
    aug @ fixed is the kernel form's right-hand side). ``keep``: a list that receives this
    face's system (see `_polish`). ``jfe``: the free coils' indices and the array [fixv, 0], if
    the caller keeps them (``_active_set_loop``)."""
    n = len(fixv)
    if jfe is None:
        j = [i for i, fr in enumerate(free) if fr]
        fe = None
    else:
        j, fe = jfe
    nf = len(j)
    anyfix = any(fixv)
    if bud and aug is not None and 0 < nf <= k + 1:
        x = _bordered_face(aug, j, n, nf, fe, fixv, anyfix, eps, keep)
        return (x, None) if want_y else x
    if anyfix:  # a new array: written in place below
        fixed = np.array(fixv) if fe is None else fe[:n].copy()
    else:
        fixed = np.zeros(n)
    if nf == 0:
        return (fixed, None) if want_y else fixed
    c = ts - math.fsum(map(abs, fixv)) if bud and aug is None else None
    if nf > k + bud:
        x, w = _kernel_face(fs, ft, eps, sg, bud, k, n, j, fixed, anyfix, aug, c, keep)
        return (x, w[:k]) if want_y else x
    x = _primal_face(fs, ft, eps, sg, bud, j, nf, fixed, anyfix, heps, q, c, keep)
    return (x, None) if want_y else x


def _bordered_face(aug, j, n, nf, fe, fixv, anyfix, eps, keep):
    """A budget face's primal normal equations: a slice of the kept bordered system
    [[F^T F + eps I, sg], [sg^T, 0]], [F^T f; I_t] (``aug[2]``, ``aug[3]``)."""
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
    return x


def _kernel_face(fs, ft, eps, sg, bud, k, n, j, fixed, anyfix, aug, c, keep):
    """Kernel form: x_J = F_J^T y (+ t s), exact in the row space. Returns (x, w), w = [y; t]
    (``fixed`` is written in place and returned as x)."""
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
    return x, w


def _primal_face(fs, ft, eps, sg, bud, j, nf, fixed, anyfix, heps, q, c, keep):
    """Primal normal equations on the free coils (bordered by the budget row with ``bud``);
    ``fixed`` is written in place and returned."""
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
    return x
