"""Signed distance between convex solids given by their support functions (SI, m).

A convex solid K is known by its support point s_K(d) (a point of K farthest along d) and
support value h_K(d) = d . s_K(d). For two solids A, B the signed distance is

    sd(A, B) = min |a - b| (a in A, b in B)              when they are apart,
             = -min over unit n of [h_A(n) + h_B(-n)]     when they overlap (penetration depth),

both of the Minkowski difference K = A - B (s_K(d) = s_A(d) - s_B(-d)). Apart: Wolfe's
minimum-norm-point algorithm on K (the fully corrective form of Gilbert's algorithm behind
GJK), stopped when its certified bounds |x| >= sd >= -h_K(-x/|x|) meet within ``tol``;
for two parallel cylinders the closed form is used. Overlapping: the smallest support value
of K over the sphere (a Fibonacci grid, then a local polish). References: P. Wolfe, "Finding
the nearest point in a polytope", Math. Programming 11 (1976); E. G. Gilbert, D. W. Johnson,
S. S. Keerthi, IEEE J. Robotics Autom. 4 (1988).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize, nnls

DISTANCE_TOLERANCE_M = 1e-12
"""Certified gap of the distance of two solids that are apart, m."""
MAX_ITERATIONS = 400
"""Major iterations of the minimum-norm-point algorithm."""
SPHERE_DIRECTIONS = 600
"""Directions of the Fibonacci grid that starts the penetration depth."""
POLISHED_DIRECTIONS = 3
"""The best grid directions polished (Nelder-Mead on the sphere's angles)."""


@dataclass(frozen=True)
class Cylinder:
    """A solid circular cylinder: centre (3,) m, unit axis (3,), half length and radius, m."""

    centre: tuple[float, float, float]
    axis: tuple[float, float, float]
    half_length_m: float
    radius_m: float

    def support(self, d: np.ndarray) -> np.ndarray:
        """Support points along directions d (k, 3) -> (k, 3) m."""
        u, c = np.asarray(self.axis), np.asarray(self.centre)
        du = d @ u
        perp = d - du[:, None] * u
        n = np.linalg.norm(perp, axis=1)
        rad = np.where(n[:, None] > 1e-300, perp / np.where(n > 1e-300, n, 1.0)[:, None], 0.0)
        return c + np.where(du >= 0, 1.0, -1.0)[:, None] * self.half_length_m * u \
            + self.radius_m * rad

    def support_value(self, d: np.ndarray) -> np.ndarray:
        """h(d) for directions d (k, 3), m."""
        u = np.asarray(self.axis)
        du = d @ u
        perp2 = np.maximum(np.einsum("ij,ij->i", d, d) - du * du, 0.0)
        return d @ np.asarray(self.centre) + self.half_length_m * np.abs(du) \
            + self.radius_m * np.sqrt(perp2)

    @property
    def bounding_radius_m(self) -> float:
        return math.hypot(self.half_length_m, self.radius_m)


@dataclass(frozen=True)
class Box:
    """A solid box: centre (3,) m, rotation (3, 3) (columns: its axes), half extents (3,) m."""

    centre: tuple[float, float, float]
    rotation: tuple[tuple[float, float, float], ...]
    half_extents_m: tuple[float, float, float]

    def support(self, d: np.ndarray) -> np.ndarray:
        r = np.asarray(self.rotation)
        local = d @ r
        return np.asarray(self.centre) + (np.where(local >= 0, 1.0, -1.0)
                                          * np.asarray(self.half_extents_m)) @ r.T

    def support_value(self, d: np.ndarray) -> np.ndarray:
        r = np.asarray(self.rotation)
        return d @ np.asarray(self.centre) + np.abs(d @ r) @ np.asarray(self.half_extents_m)

    @property
    def bounding_radius_m(self) -> float:
        return float(np.linalg.norm(self.half_extents_m))


@dataclass(frozen=True)
class Prism:
    """A vertical prism: a convex outline (k, 2) m, counter-clockwise, from z0 to z1 m, its
    outline grown by ``radius_m`` (rounded corners: the outline swept by a disc)."""

    outline_m: tuple[tuple[float, float], ...]
    z0_m: float
    z1_m: float
    radius_m: float = 0.0

    def support(self, d: np.ndarray) -> np.ndarray:
        o = np.asarray(self.outline_m)
        k = np.argmax(d[:, :2] @ o.T, axis=1)
        n = np.linalg.norm(d[:, :2], axis=1)
        rad = np.where(n[:, None] > 1e-300, d[:, :2] / np.where(n > 1e-300, n, 1.0)[:, None],
                       0.0)
        xy = o[k] + self.radius_m * rad
        z = np.where(d[:, 2] >= 0, self.z1_m, self.z0_m)
        return np.c_[xy, z]

    def support_value(self, d: np.ndarray) -> np.ndarray:
        o = np.asarray(self.outline_m)
        zc, hz = 0.5 * (self.z0_m + self.z1_m), 0.5 * (self.z1_m - self.z0_m)
        return (np.max(d[:, :2] @ o.T, axis=1) + self.radius_m * np.linalg.norm(d[:, :2], axis=1)
                + d[:, 2] * zc + hz * np.abs(d[:, 2]))

    @property
    def centre(self) -> tuple[float, float, float]:
        o = np.asarray(self.outline_m)
        c = o.mean(axis=0)
        return (float(c[0]), float(c[1]), 0.5 * (self.z0_m + self.z1_m))

    @property
    def bounding_radius_m(self) -> float:
        o = np.asarray(self.outline_m)
        r = float(np.max(np.linalg.norm(o - o.mean(axis=0), axis=1))) + self.radius_m
        return math.hypot(r, 0.5 * (self.z1_m - self.z0_m))


Solid = Cylinder | Box | Prism


def _parallel_cylinders(a: Cylinder, b: Cylinder) -> float | None:
    """Closed-form signed distance of two cylinders with parallel (or opposite) axes, or
    None when the axes are not parallel."""
    u = np.asarray(a.axis)
    if abs(abs(float(u @ np.asarray(b.axis))) - 1.0) > 1e-12:
        return None
    d = np.asarray(b.centre, dtype=float) - np.asarray(a.centre, dtype=float)
    axial = float(d @ u)
    radial = float(np.linalg.norm(d - axial * u))
    gap_r = radial - a.radius_m - b.radius_m
    gap_z = abs(axial) - a.half_length_m - b.half_length_m
    if gap_r > 0 and gap_z > 0:
        return math.hypot(gap_r, gap_z)
    if gap_r > 0 or gap_z > 0:
        return max(gap_r, gap_z)
    # overlapping: the smallest move apart, sideways or along the axis
    return max(gap_r, gap_z)


def _min_norm_weights(points: np.ndarray) -> np.ndarray:
    """Weights w >= 0, sum 1, of the point of the convex hull of ``points`` (m, 3) nearest the
    origin: Lawson-Hanson NNLS with the sum as a heavily weighted extra row."""
    big = 1e4 * max(float(np.abs(points).max()), 1e-300)
    a = np.vstack([points.T, np.full((1, len(points)), big)])
    w = nnls(a, np.r_[0.0, 0.0, 0.0, big])[0]
    return w / w.sum()


def _distance_apart(a: Solid, b: Solid, tol: float) -> tuple[float, float]:
    """(upper, lower) bounds of the distance of A and B by the minimum-norm point of
    K = A - B over the support points found so far (fully corrective Frank-Wolfe: Wolfe's
    method); both 0 when the origin is in K."""
    def support(d):
        return a.support(d[None])[0] - b.support(-d[None])[0]

    pts = np.asarray([np.asarray(a.centre, float) - np.asarray(b.centre, float)])
    x = pts[0]
    lower = -np.inf
    for _ in range(MAX_ITERATIONS):
        nx = float(np.linalg.norm(x))
        if nx <= tol:
            return 0.0, 0.0
        s = support(-x)
        lower = max(lower, float(x @ s) / nx)
        if nx - lower <= tol or any(np.array_equal(s, p) for p in pts):
            return nx, max(lower, 0.0)
        pts = np.vstack([pts, s])
        w = _min_norm_weights(pts)
        keep = np.argsort(w)[::-1][:4]  # Caratheodory: at most 4 points in 3-D
        keep = keep[w[keep] > 0]
        pts, w = pts[keep], w[keep] / w[keep].sum()
        x_new = w @ pts
        if float(np.linalg.norm(x_new)) >= nx:  # no progress: the bounds are final
            return nx, max(lower, 0.0)
        x = x_new
    return float(np.linalg.norm(x)), max(lower, 0.0)


def _fibonacci_sphere(n: int) -> np.ndarray:
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = math.pi * (1.0 + 5.0 ** 0.5) * k
    r = np.sqrt(1.0 - z * z)
    return np.c_[r * np.cos(phi), r * np.sin(phi), z]


def _penetration(a: Solid, b: Solid) -> float:
    """Depth of overlap of A and B: min over unit n of h_A(n) + h_B(-n), m (>= 0)."""
    def h(n):
        return a.support_value(n) + b.support_value(-n)

    grid = _fibonacci_sphere(SPHERE_DIRECTIONS)
    vals = h(grid)
    best = float(vals.min())
    for k in np.argsort(vals)[:POLISHED_DIRECTIONS]:
        n0 = grid[k]
        theta0 = [math.acos(max(-1.0, min(1.0, n0[2]))), math.atan2(n0[1], n0[0])]

        def f(t):
            st = math.sin(t[0])
            return float(h(np.array([[st * math.cos(t[1]), st * math.sin(t[1]),
                                      math.cos(t[0])]]))[0])

        res = minimize(f, theta0, method="Nelder-Mead",
                       options={"xatol": 1e-9, "fatol": 1e-13, "maxiter": 200})
        best = min(best, float(res.fun))
    return max(best, 0.0)


def signed_distance(a: Solid, b: Solid, tol: float = DISTANCE_TOLERANCE_M) -> float:
    """Signed distance of two convex solids, m: the gap when they are apart (certified to
    ``tol``), minus the penetration depth when they overlap, 0 when they touch."""
    if isinstance(a, Cylinder) and isinstance(b, Cylinder):
        closed = _parallel_cylinders(a, b)
        if closed is not None:
            return closed
    upper, _ = _distance_apart(a, b, tol)
    if upper > tol:
        return upper
    return -_penetration(a, b)


def lower_bound_m(a: Solid, b: Solid) -> float:
    """A cheap lower bound of :func:`signed_distance`: the gap of their bounding spheres, m."""
    return float(np.linalg.norm(np.asarray(a.centre, float) - np.asarray(b.centre, float))
                 - a.bounding_radius_m - b.bounding_radius_m)
