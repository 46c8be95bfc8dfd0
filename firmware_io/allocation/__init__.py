"""Exact bounded current allocation (thesis eq. 4.9) -- numpy only, it runs on the controller.

For one magnet position with the force matrix F (k, n) (N/A; rows Fz, the force, or force and
torque) and the target f (k,) N::

    minimize ||F I - f||^2  subject to  |I_i| <= u_i (or 0 <= I_i <= u_i),  sum |I_i| <= I_t

Among the minimizers the least-energy one (min sum I^2) is returned: unique and continuous in
the position. Method (a primal active set on the eps-regularized split problem, an eps -> 0
polish and an exact least-energy stage), its bias bound and the cost model: docs/allocation.md.

The magnet's pull on the cores at zero current, F0(p), is not produced by the currents: pass
``bias=F0`` (same rows as ``target``) or subtract it; with map v2 it is
``MapFile.bias_force(points)``.

Usage::

    from firmware_io.allocation import Allocator, allocate
    currents_a, residual = allocate(F, f_n, 6.0, 54.0)               # bipolar
    currents_a, residual = allocate(F, f_n, 6.0, 54.0, unipolar=True)
    alloc = Allocator()                                               # in a control loop:
    currents_a, residual = alloc(F, f_n, 6.0, 54.0, unipolar=True)   # same answer, warm start

``allocate_within(F, f_n, 6.0, 54.0, (G, h))`` (constrained.py): the same with G I <= h too
(e.g. Hall sensors kept in their linear range).

``ray_limits`` (reach.py): for many positions at once, how far a force reaches along a ray
within the bounds (the force constant's per-point lambda; docs/allocation.md).
"""

from __future__ import annotations

from .allocator import Allocator
from .constrained import allocate_within
from .problem import EPS_REL
from .reach import ray_limits
from .solve import allocate

__all__ = ["allocate", "allocate_within", "Allocator", "EPS_REL", "ray_limits"]
