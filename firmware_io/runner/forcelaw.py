"""What the force law needs of A(p): the rows a dipole's force uses and the matrix onto them.

F = M(m) G5 (thesis eq. 2.5) with G5 the five gradient rows (3..7) of A(p) (rows in the order
of :data:`firmware_io.actuation.ROWS`). A column of M(m) that is zero for the rendered axes
marks a row the runner need not evaluate: for a z-dipole the 3-D force needs four gradient
rows, Fz alone two (studies/bench_runner.py measures what that saves).
"""

from __future__ import annotations

import numpy as np


def force_law_rows(moment_a_m2, axes: str = "xyz") -> tuple[np.ndarray, np.ndarray]:
    """Rows of A(p) (indices into Bx, By, Bz, dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz) the force
    on a dipole ``moment_a_m2`` uses, and the matrix that maps them to the force per ampere.

    F = M(m) G5 (thesis eq. 2.5) with G5 = rows 3..7; a column of M(m) that is zero (for the
    rendered axes) marks a row not needed: for a z-dipole the 3-D force needs dBx/dx, dBx/dz,
    dBy/dy, dBy/dz, and Fz alone (``axes='z'``) dBx/dx and dBy/dy.

    Parameters
    ----------
    moment_a_m2 : array_like, shape (3,), A m^2
    axes : {'xyz', 'z'}

    Returns
    -------
    rows : ndarray of int, shape (r,)
    matrix : ndarray, shape (3, r) or (1, r) -- force per ampere = matrix @ A[rows]
    """
    mx, my, mz = (float(v) for v in moment_a_m2)
    # F = F(m) G5 (thesis eq. 2.5), the one numpy definition on the controller side
    full = np.array([[mx, my, mz, 0.0, 0.0],
                     [0.0, mx, 0.0, my, mz],
                     [-mz, 0.0, mx, -mz, my]])
    if axes == "z":
        full = full[2:3]
    used = np.flatnonzero(np.any(full != 0.0, axis=0))
    return used + 3, full[:, used].copy()
