"""`Allocator`: the allocation for a control loop, warm-started from the last solve.

It keeps the working set of the last solve (which coils were free, at 0, at +-u, and whether
the budget held with equality) and tries that face first: when it is still optimal (the usual
case between two control periods) the solve is one face solve, its multiplier check and the
eps -> 0 polish. The result is the exact answer of :func:`.solve.allocate` whatever the start.
With ``inequalities`` it is :func:`.constrained.allocate_within`'s (its solve without them
warm-started alike).
"""

from __future__ import annotations

from .constrained import allocate_within
from .solve import allocate


class Allocator:
    """`allocate` with a warm start, for a control loop that solves at nearby positions.

    A stale face is only a start for the same active-set method. A call with another number
    of rows or coils, another drive mode, or limits that change which coils are off, starts
    cold.

    Usage::

        alloc = Allocator()
        currents_a, residual = alloc(F, f_n, 6.0, 54.0, unipolar=True)   # same as allocate
        currents_a, residual = alloc(F, f_n, 6.0, 54.0, inequalities=(G, h))   # G I <= h too
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
                 unipolar: bool = False, bias=None, max_iter: int | None = None,
                 inequalities=None):
        if inequalities is not None:
            return allocate_within(force_matrix, target, current_limit, total_limit,
                                   inequalities, unipolar=unipolar, bias=bias, warm=self)
        return allocate(force_matrix, target, current_limit, total_limit, unipolar=unipolar,
                        bias=bias, max_iter=max_iter, warm=self)
