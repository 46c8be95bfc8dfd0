"""The force and torque on the finger magnet per ampere from A(p), for the moment that is there.

F = grad(m . B) = M(m) G5 (thesis eq. 2.5) with G5 the five gradient rows (3..7) of A(p) (rows
in the order of :data:`firmware_io.actuation.ROWS`), and tau = m x B = Sk(m) B with B rows
0..2: both linear in the moment m (A m^2, array frame), so the runner takes the estimated
moment each step. For a known moment :func:`force_law_rows` names the rows a force needs (a
z-dipole's Fz: two; studies/bench_runner.py measures what that saves).
"""

from __future__ import annotations

import numpy as np


def force_law_matrix(moment_a_m2) -> np.ndarray:
    """M(m), shape (3, 5): the force per ampere is ``M(m) @ A[3:8]`` (N/A) for a dipole of
    moment ``moment_a_m2`` (3,) A m^2 (thesis eq. 2.5; the one numpy definition on the
    controller side)."""
    mx, my, mz = (float(v) for v in moment_a_m2)
    return np.array([[mx, my, mz, 0.0, 0.0],
                     [0.0, mx, 0.0, my, mz],
                     [-mz, 0.0, mx, -mz, my]])


def torque_matrix(moment_a_m2) -> np.ndarray:
    """Sk(m), shape (3, 3): the torque per ampere is ``Sk(m) @ A[0:3]`` (N m/A), tau = m x B."""
    mx, my, mz = (float(v) for v in moment_a_m2)
    return np.array([[0.0, -mz, my], [mz, 0.0, -mx], [-my, mx, 0.0]])


def force_law_rows(moment_a_m2, axes: str = "xyz") -> tuple[np.ndarray, np.ndarray]:
    """Rows of A(p) (indices into Bx, By, Bz, dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz) the force
    on a dipole ``moment_a_m2`` uses, and the matrix that maps them to the force per ampere.

    A column of :func:`force_law_matrix` that is zero (for the rendered axes) marks a row not
    needed: for a z-dipole the 3-D force needs dBx/dx, dBx/dz, dBy/dy, dBy/dz, and Fz alone
    (``axes='z'``) dBx/dx and dBy/dy.

    Parameters
    ----------
    moment_a_m2 : array_like, shape (3,), A m^2
    axes : {'xyz', 'z'}

    Returns
    -------
    rows : ndarray of int, shape (r,)
    matrix : ndarray, shape (3, r) or (1, r) -- force per ampere = matrix @ A[rows]
    """
    full = force_law_matrix(moment_a_m2)
    if axes == "z":
        full = full[2:3]
    used = np.flatnonzero(np.any(full != 0.0, axis=0))
    return used + 3, full[:, used].copy()
