"""One solve's scaled problem, and the systems of its faces kept for one eps.

:class:`Workspace` holds what every phase of a solve reads (F and f scaled, F^T F, F^T f, the
bounds in units of u_max, the drive mode, the tolerances); :class:`FaceSystems` the systems the
active set slices its faces from at one eps (F^T F + eps I and, with a budget, the bordered
system whose sign entries follow the working set). Scaled units: currents / u_max, forces /
the force scale of :func:`.problem.scale`. Built once per solve; the phases take it instead of
twenty positional arguments.
"""

from __future__ import annotations

import math

import numpy as np

from .linalg import eye


class Workspace:
    """The scaled problem of one solve.

    Attributes
    ----------
    fs, ft : F (k, n) and f (k,), scaled; h, q : F^T F (n, n) and F^T f (n,)
    usl : list of n floats -- per-coil limits / u_max
    ts : float -- the budget / u_max; tsb : it when it can bind, else inf
    budget_possible : bool -- the budget is below the sum of the limits
    unipolar : bool; k, n : rows and coils
    tol : float -- the multipliers' tolerance; max_iter : int
    """

    __slots__ = ("fs", "ft", "h", "q", "usl", "ts", "tsb", "budget_possible", "unipolar", "k",
                 "n", "tol", "max_iter")

    def __init__(self, fs, ft, usl, ts: float, budget_possible: bool, unipolar: bool, k: int):
        self.fs, self.ft, self.usl, self.ts, self.unipolar, self.k = fs, ft, usl, ts, unipolar, k
        self.n = len(usl)
        self.budget_possible = budget_possible
        self.tsb = ts if budget_possible else math.inf
        self.h = fs.T.dot(fs)
        self.q = fs.T.dot(ft)
        self.tol = 0.0
        self.max_iter = 0


class FaceSystems:
    """F^T F + eps I (``heps``), F^T f (``q``) and, when the budget can bind, ``aug`` = ([F; sg]
    (k + 1, n), [f; I_t] (k + 1,), the bordered [[F^T F + eps I, sg], [sg^T, 0]], [F^T f; I_t])
    with the signs ``sg`` of the working set (the active set keeps them in step)."""

    __slots__ = ("heps", "q", "aug")

    def __init__(self, heps, q, aug=None):
        self.heps, self.q, self.aug = heps, q, aug

    @classmethod
    def build(cls, ws: Workspace, eps: float, sg) -> "FaceSystems":
        n, k = ws.n, ws.k
        heps = ws.h + eps * eye(n)
        if not ws.budget_possible:  # no budget face will be solved
            return cls(heps, ws.q)
        aug_a = np.empty((k + 1, n))
        aug_a[:k] = ws.fs
        aug_a[k] = sg
        aug_b = np.empty(k + 1)
        aug_b[:k] = ws.ft
        aug_b[k] = ws.ts
        # the bordered [[F^T F + eps I, sg], [sg^T, 0]] and [F^T f; I_t]: a budget face's primal
        # system is their (free coils + budget) slice
        hb = np.empty((n + 1, n + 1))
        hb[:n, :n] = heps
        hb[n, :n] = sg
        hb[:n, n] = sg
        hb[n, n] = 0.0
        qb = np.empty(n + 1)
        qb[:n] = ws.q
        qb[n] = ws.ts
        return cls(heps, ws.q, (aug_a, aug_b, hb, qb))

    def set_signs(self, sg, k: int, n: int) -> None:
        """Every sign ``sg`` (list) into the bordered systems."""
        aug_a, hb = self.aug[0], self.aug[2]
        aug_a[k] = sg
        hb[n, :n] = sg
        hb[:n, n] = sg
