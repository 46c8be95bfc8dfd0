"""What the multipole misses at the sensors, linearized in the magnet's pose: :class:`Corrections`.

Two parts, each evaluated exactly at a linearization pose (p0, u0) with its Jacobians, and used
as v0 + J_p (p - p0) + J_u (u - u0) while the pose stays near (u as a free 3-vector, |m|
fixed; both parts scale with |m|):

- 'exact': the exact cylinder's field minus the multipole, tabulated once
  (:class:`.magnet_table.CylinderExcess`); J_p by forward differences of the table (h = 0.1
  mm), J_u from J_p: the difference rotates rigidly with the moment
  (:func:`.pose.rotation_derivatives`);
- 'cores': the field of the cores the magnet magnetizes, ``model.induced`` (linear in the
  moment: J_u = |m| times its per-moment basis; J_p by forward differences, h = 0.25 mm).

Each part keeps its own pose and a reuse radius in d = |p - p0| + rho |u - u0| (rho = 20 mm:
1 degree ~ 0.35 mm), adapted at each refresh from the linearization's observed error so that
it stays near noise / 20 (0.1-5 mm). Reference: the position-only version of this scheme was
measured against re-evaluating at every iteration (docs/localization.md, "Magnet model").
"""

from __future__ import annotations

import math

import numpy as np

from .magnet import EYE3
from .magnet_table import cylinder_excess
from .pose import rotation_derivatives, tangent_axes

RHO_M = 0.02
"""Length that converts a change of the moment direction into the reuse distance, m/rad."""

EXACT_STEP_M = 1e-4
"""The forward-difference step of the exact part's position Jacobian, m (its difference from the
multipole varies on the scale of its distance, >= 10 mm)."""
_SHIFTS = np.r_[np.zeros((1, 3)), -EXACT_STEP_M * EYE3]
"""The sensors' shifts of :meth:`Corrections._exact`: the magnet moved by +h e_k."""


class Corrections:
    """The linearized corrections at the points ``points_m`` (n, 3) of a sensor model
    (module docstring). ``exact``, ``cores``: which parts; ``noise_t``: the readings' noise
    that sets the reuse radius."""

    def __init__(self, points_m: np.ndarray, model, *, exact: bool, cores: bool,
                 noise_t: float, first_radius_m: float, fixed_direction: bool = False):
        self.points = np.asarray(points_m, float)
        self.model = model
        self.moment = float(np.linalg.norm(model.moment_a_m2))
        # the cores' basis: along the model's moment alone when the direction is fixed
        self.directions = ((model.moment_a_m2 / self.moment)[:, None] if fixed_direction
                           else np.eye(3))
        self.noise_t = noise_t
        self.parts = (("exact",) if exact else ()) + (("cores",) if cores else ())
        self.excess = (cylinder_excess(*model.magnet_size_m, float(model.octupole_m2))
                       if exact else None)
        self.first = {"exact": 0.25e-3, "cores": first_radius_m}
        self.lin: dict = {}
        n = len(self.points)
        # the sum of the parts as const + J_p p + J_u u: (n, 3), (n, 3, 3), (n, 3, 3), views of
        # one array [J_p | J_u | const] (n, 3, 7)
        self.table = np.zeros((n, 3, 7))
        self.jac_pu = self.table[:, :, :6]
        self.jac_p = self.table[:, :, :3]
        self.jac_u = self.table[:, :, 3:6]
        self.const = self.table[:, :, 6]
        # (7, 6): the table to (pose columns J_p, J_u e1, J_u e2 | value at (p, u))
        self._apply = np.zeros((7, 6))
        self._apply[:3, :3] = EYE3
        self._apply[6, 5] = 1.0

    @property
    def active(self) -> bool:
        return bool(self.parts)

    def reset(self) -> None:
        """Forget every linearization (the next use re-evaluates)."""
        self.lin = {}

    def distance(self, part: str, p: np.ndarray, u: np.ndarray) -> float:
        """d = |p - p0| + rho |u - u0| from the part's linearization pose (inf: none)."""
        c = self.lin.get(part)
        if c is None:
            return math.inf
        return math.dist(p.tolist(), c[6]) + RHO_M * math.dist(u.tolist(), c[7])

    def within(self, p: np.ndarray, u: np.ndarray, slack: float = 1.0) -> bool:
        """Is (p, u) within ``slack`` times every part's reuse radius?"""
        pl, ul = p.tolist(), u.tolist()
        for part in self.parts:
            c = self.lin.get(part)
            if c is None or math.dist(pl, c[6]) + RHO_M * math.dist(ul, c[7]) > slack * c[5]:
                return False
        return True

    def update(self, p: np.ndarray, u: np.ndarray) -> None:
        """Re-linearize the parts (p, u) left (beyond their radius), then sum."""
        changed = False
        for part in self.parts:
            c = self.lin.get(part)
            d = self.distance(part, p, u)
            if c is not None and d <= c[5]:
                continue
            val, jp, ju = (self._exact if part == "exact" else self._cores)(p, u)
            radius = self.first[part]
            if c is not None:
                # the old linearization's error here grows as d^2: keep it near noise / 20
                err = float(np.abs(val - (c[2] + c[3] @ (p - c[0]) + c[4] @ (u - c[1]))).max())
                radius = (min(max(d * math.sqrt(0.05 * self.noise_t / err), 0.1e-3), 5e-3)
                          if err > 0 else 5e-3)
            self.lin[part] = (p.copy(), u.copy(), val, jp, ju, radius, p.tolist(), u.tolist())
            changed = True
        if changed:
            self.table[:] = 0.0
            for part in self.parts:
                p0, u0, val, jp, ju = self.lin[part][:5]
                self.const += val - jp @ p0 - ju @ u0
                self.jac_p += jp
                self.jac_u += ju

    def value(self, p: np.ndarray, u: np.ndarray) -> np.ndarray:
        """(n, 3) T: the summed linearization at (p, u)."""
        return self.const + self.jac_pu @ np.concatenate((p, u))

    def add_to(self, field: np.ndarray, cols: np.ndarray, p: np.ndarray, u: np.ndarray,
               axes: np.ndarray | None, scale: float = 1.0) -> None:
        """Add ``scale`` times the linearization at (p, u) to ``field`` (n, 3) and its pose
        Jacobian to ``cols`` (n, 3, >= 5): columns 0-2 J_p, 3-4 J_u along the rotations about
        ``axes`` (e1, e2) (the fit's orientation steps, :func:`.pose.rotated`); ``axes`` None:
        J_p alone (a fixed direction). One product of the table [J_p | J_u | const]."""
        apply = self._apply
        apply[:3, 5] = p
        apply[3:6, 5] = u
        if axes is not None:
            apply[3:6, 3:5] = axes.T
        x = self.table @ apply
        if scale != 1.0:
            x *= scale
        field += x[:, :, 5]
        if axes is None:
            cols[:, :, :3] += x[:, :, :3]
        else:
            cols[:, :, :5] += x[:, :, :5]

    def _exact(self, p, u):
        """The exact cylinder minus the multipole: value, J_p (forward differences, h = 0.1
        mm: the difference varies on the scale of its distance, >= 10 mm), J_u (module
        docstring)."""
        h = EXACT_STEP_M
        n = len(self.points)
        val, jp, ju = np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, 3, 3))
        rel = self.points - p
        near = np.einsum("ij,ij->i", rel, rel) < (self.excess.r_max + h) ** 2
        if not near.any():
            return val, jp, ju
        k = int(near.sum())
        # the magnet moved by +h e_k is the sensors moved by -h e_k
        pts = (self.points[near][None] + _SHIFTS[:, None]).reshape(-1, 3)
        d = self.moment * self.excess.field(pts, p, u).reshape(4, k, 3)
        val[near] = d[0]
        jp[near] = ((d[1:] - d[0]) / h).transpose(1, 2, 0)
        axes = tangent_axes(u)
        rot = rotation_derivatives(val[near], jp[near], rel[near], axes)
        # as a derivative in u (a free 3-vector): the two rotations plus |m|'s scaling along u
        ju[near] = rot @ axes + val[near][:, :, None] * u
        return val, jp, ju

    def _cores(self, p, u):
        """The cores' field: value, J_p (forward differences, h = 0.25 mm: the cores are
        >= 20 mm away, their field's curvature over h is far below the noise), J_u = |m|
        basis."""
        h = 0.25e-3
        basis = self.model.induced(np.r_[p[None], p + h * EYE3], self.directions)
        if self.directions.shape[1] == 1:              # the direction fixed: u is the model's
            val = self.moment * basis[0, ..., 0]
            jp = np.stack([self.moment * (basis[1 + k, ..., 0] - basis[0, ..., 0]) / h
                           for k in range(3)], -1)
            return val, jp, val[:, :, None] * u
        mom = self.moment * u
        val = basis[0] @ mom
        jp = np.stack([(basis[1 + k] - basis[0]) @ mom / h for k in range(3)], -1)
        return val, jp, self.moment * basis[0]
