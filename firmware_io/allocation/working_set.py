"""The working set of the active-set method: one face of the feasible set.

Each coil is free (inside its box, with a sign) or fixed (at 0 or at +-u), and the budget
sum |I_i| <= I_t holds with equality or not. Scaled units (currents / u_max).
"""

from __future__ import annotations

import math

import numpy as np


class Face:
    """A working set: ``free`` (list of bool, per coil), ``sg`` (the sign of each free coil,
    +-1.0), ``fixv`` (the value a fixed coil is held at: 0 or +-u, scaled; 0.0 for a free one),
    ``bud`` (the budget holds with equality); ``j`` the free coils' indices and ``fe`` the array
    [fixv, 0] (fixed values and the budget's slot).

    ``free``, ``sg``, ``fixv`` and ``j`` are replaced when they change, never changed in place,
    so a stored face stays what it was (the warm start keeps one); ``fe`` is the active set's
    own and changes in place.
    """

    __slots__ = ("free", "sg", "fixv", "bud", "j", "fe")

    def __init__(self, free, sg, fixv, bud):
        self.free, self.sg, self.fixv, self.bud = free, sg, fixv, bud
        self.j = [i for i, fr in enumerate(free) if fr]
        self.fe = np.array(fixv + [0.0])

    @classmethod
    def of_point(cls, xl, usl, ts: float, budget_possible: bool) -> "Face":
        """The face of a feasible point x (list, scaled): :func:`point_face`."""
        return cls(*point_face(xl, usl, ts, budget_possible))


def point_face(xl, usl, ts: float, budget_possible: bool) -> tuple:
    """(free, sg, fixv, bud) of a feasible point x (list, scaled): free the coils strictly
    inside their box; the budget when it holds to 1e-12 (and can bind at all)."""
    free = [0.0 < abs(v) < ui for v, ui in zip(xl, usl)]
    sg = [1.0 if v >= 0.0 else -1.0 for v in xl]
    fixv = [0.0 if fr else v for v, fr in zip(xl, free)]
    bud = budget_possible and any(free) and math.fsum(map(abs, xl)) >= ts * (1 - 1e-12)
    return free, sg, fixv, bud
