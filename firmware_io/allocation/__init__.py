"""Exact bounded current allocation (thesis eq. 4.9) -- numpy only, it runs on the controller.

For one magnet position with the force matrix F (k, n) (N/A; rows Fz, the force, or force and
torque) and the target f (k,) N::

    minimize ||F I - f||^2  subject to  |I_i| <= u_i (or 0 <= I_i <= u_i),  sum |I_i| <= I_t

Among the minimizers the least-energy one (min sum I^2) is returned: unique and continuous in
the position. Pass the magnet's pull on the cores at zero current as ``bias=F0`` (map v2:
``MapFile.bias_force``). Method, bias bound and cost model: docs/allocation.md. Usage::

    currents_a, residual = allocate(F, f_n, 6.0, 54.0)               # bipolar
    alloc = Allocator()                                               # in a control loop:
    currents_a, residual = alloc(F, f_n, 6.0, 54.0, unipolar=True)   # same answer, warm start
    currents_a, residual = allocate_within(F, f_n, 6.0, 54.0, (G, h))  # and G I <= h

``ray_limits``: for many positions at once, how far a force reaches along a ray within the
bounds (the force constant's per-point lambda).
"""

from __future__ import annotations

from .allocator import Allocator
from .constrained import allocate_within
from .problem import EPS_REL
from .reach import ray_limits
from .solve import allocate

__all__ = ["allocate", "allocate_within", "Allocator", "EPS_REL", "ray_limits"]
