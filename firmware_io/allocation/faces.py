"""The minimizer of the regularized objective ||F x - f||^2 + eps ||x||^2 on one working face.

A face (:class:`.working_set.Face`): some coils free (each keeping its sign), the others fixed
at 0 or +-u, and optionally the budget held with equality. Each face is solved in the smaller
of two exact forms: the primal normal equations on the free coils when at most k (+1 with the
budget) are free, else the kernel form x_J = F_J^T y (+ t s), exact in the row space
(docs/allocation.md). Scaled units: currents / u_max, forces / the force scale of
:func:`.problem.scale`.
"""

from __future__ import annotations

import math

import numpy as np

from .linalg import eps_diag, eye, lsolve


def face_minimizer(ws, face, eps, systems=None, keep=None, want_y=False):
    """Minimizer x (n,) of the regularized objective on ``face`` (free coils keep their sign;
    with ``face.bud`` the budget holds with equality).

    Parameters
    ----------
    ws : .workspace.Workspace
    face : .working_set.Face
    eps : float -- the Tikhonov weight (0: the polish)
    systems : .workspace.FaceSystems, optional
        The caller's F^T F + eps I, F^T f and bordered systems: the primal form then slices
        them (every numpy call saved counts); a budget face of at most k + 1 free coils slices
        the bordered system. None: every form is built from F.
    keep : list, optional -- receives this face's system (see :func:`.polish.polish`)
    want_y : bool -- also return the kernel coefficients y (x_J = F_J^T y + t s) when the
        kernel form applies, else None: (x, y)
    """
    fixv, j, bud, fe = face.fixv, face.j, face.bud, face.fe
    n = len(fixv)
    nf = len(j)
    anyfix = any(fixv)
    aug = None if systems is None else systems.aug
    k = ws.k
    if bud and aug is not None and 0 < nf <= k + 1:
        x = _bordered_face(aug, j, fe, n, anyfix, eps, keep)
        return (x, None) if want_y else x
    fixed = fe[:n].copy() if anyfix else np.zeros(n)  # written in place below
    if nf == 0:
        return (fixed, None) if want_y else fixed
    c = ws.ts - math.fsum(map(abs, fixv)) if bud and aug is None else None
    if nf > k + bud:
        x, w = _kernel_face(ws, face, eps, (fixed, anyfix), aug, c, keep)
        return (x, w[:k]) if want_y else x
    x = _primal_face(ws, face, eps, (fixed, anyfix), systems, c, keep)
    return (x, None) if want_y else x


def _bordered_face(aug, j, fe, n, anyfix, eps, keep):
    """A budget face's primal normal equations: a slice of the kept bordered system
    [[F^T F + eps I, sg], [sg^T, 0]], [F^T f; I_t] (``aug[2]``, ``aug[3]``); ``j`` the free
    coils, ``fe`` the fixed values and the budget's slot (n + 1,)."""
    hb, qb = aug[2], aug[3]
    jj = j + [n]
    hr = hb.take(jj, 0)
    if anyfix:
        rhs = qb.take(jj) - hr.dot(fe)
        x = fe[:n].copy()
    else:
        rhs = qb.take(jj)
        x = np.zeros(n)
    mat = hr.take(jj, 1)
    if keep is not None:
        keep[:] = (j, mat, rhs, None, len(j))
    x.put(j, lsolve(mat, rhs, eps > 0))  # put: the first nf values
    return x


def _kernel_face(ws, face, eps, fixed_any, aug, c, keep):
    """Kernel form: x_J = F_J^T y (+ t s), exact in the row space. Returns (x, w), w = [y; t];
    ``fixed_any`` = (the fixed values (n,), written in place and returned as x; any non-zero)."""
    fixed, anyfix = fixed_any
    fs, ft, k, n = ws.fs, ws.ft, ws.k, ws.n
    j = face.j
    if face.bud:
        # [F_J; s^T] [F_J; s^T]^T [y; t] = [r; c] (+ eps on the y block)
        if aug is not None:
            a, bt = aug[0], aug[1]
            aj = a.take(j, 1)
            rhs = (bt - a.dot(fixed)) if anyfix else bt
        else:
            a = np.empty((k + 1, n))
            a[:k] = fs
            a[k] = face.sg
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
        mat += eps_diag(eps, k, mat.shape[0])
    if keep is not None:
        keep[:] = (j, mat, rhs, aj, k)
    w = lsolve(mat, rhs, eps > 0)
    x = fixed
    x.put(j, aj.T.dot(w))
    return x, w


def _primal_face(ws, face, eps, fixed_any, systems, c, keep):
    """Primal normal equations on the free coils (bordered by the budget row on a budget
    face); ``fixed_any`` as :func:`_kernel_face`'s, the fixed values written in place and
    returned."""
    fixed, anyfix = fixed_any
    fs = ws.fs
    j = face.j
    nf = len(j)
    if systems is None:
        fj = fs.take(j, 1)
        hj = fj.T.dot(fj)
        if eps:
            hj += eps * eye(nf)
        b = fj.T.dot((ws.ft - fs.dot(fixed)) if anyfix else ws.ft)
    else:
        hr = systems.heps.take(j, 0)
        hj = hr.take(j, 1)
        b = systems.q.take(j)
        if anyfix:  # the eps part of heps meets only free coordinates, where fixed is 0
            b = b - hr.dot(fixed)
    x = fixed
    if face.bud:
        mat = np.empty((nf + 1, nf + 1))
        mat[:nf, :nf] = hj
        sg = face.sg
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
    x.put(j, lsolve(mat, rhs, eps > 0))
    return x
