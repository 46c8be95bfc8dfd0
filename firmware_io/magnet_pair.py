"""The force and torque one finger magnet exerts on another (two uniformly magnetized cylinders).

Magnet b's uniform magnetization M_b is a surface charge sigma = M_b . n on its end faces, so in
the field B_a of magnet a (curl-free outside a) the force and the torque about b's centre are

    F = M_b [int_top B_a dA - int_bottom B_a dA],
    tau = M_b [int_top (r - p_b) x B_a dA - int_bottom (r - p_b) x B_a dA],

exact for finite cylinders that do not overlap (the equivalent-charge form of F = int (M . grad) B
dV). B_a is the exact cylinder field (Derby & Olbert, :func:`firmware_io.localization.magnet.
cylinder_field`); the faces are integrated with Gauss-Legendre in r^2 and the trapezoid rule in
the azimuth, with a node count chosen from how close the faces come to magnet a (the integrand
is analytic on a face, its nearest singularity magnet a's edge). Far apart the pair tends to two
point dipoles. Positions m, moments A m^2, forces N, torques N m; numpy only (runs on the
controller, which compensates the pair's force at run time: it depends on both positions).
"""

from __future__ import annotations

import math

import numpy as np

from .localization.magnet import cylinder_field

MAX_NODES = 64
"""Most nodes per face direction: faces closer to the source than ~1 % of their radius are
integrated with this many, less accurately (such magnets are touching)."""


def face_nodes(n_r: int, n_phi: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit-disc quadrature: radii (k,), azimuths (k,), area weights (k,) summing to pi.

    Gauss-Legendre in s = r^2 (so the area element is uniform) times the trapezoid rule in the
    azimuth (exact for trigonometric polynomials of degree < n_phi)."""
    x, w = np.polynomial.legendre.leggauss(n_r)
    s = 0.5 * (x + 1.0)
    phi = 2.0 * math.pi * np.arange(n_phi) / n_phi
    r = np.repeat(np.sqrt(s), n_phi)
    ph = np.tile(phi, n_r)
    weights = np.repeat(0.5 * w * math.pi / n_phi, n_phi)
    return r, ph, weights


def nodes_for(distance_m: float, radius_m: float, tol: float) -> tuple[int, int]:
    """Nodes (radius, azimuth) per face for a relative error ``tol``, for faces of radius
    ``radius_m`` whose nearest point lies ``distance_m`` from the source magnet's edge circles
    (where its field is singular).

    Gauss-Legendre on an interval of half-length h converges like rho^-2n for an integrand
    analytic within the Bernstein ellipse of parameter rho = d/h + sqrt((d/h)^2 + 1), d the
    distance to the nearest singularity; the trapezoid rule in the azimuth like rho^-n."""
    q = max(distance_m, 1e-2 * radius_m) / radius_m
    rho = q + math.sqrt(q * q + 1.0)
    n = math.log(1.0 / tol) / math.log(rho)
    return (min(MAX_NODES, 2 + int(math.ceil(n / 2))), min(MAX_NODES, 4 + int(math.ceil(n))))


def edge_distance_m(a: "CylinderMagnet", b: "CylinderMagnet", n: int = 48) -> float:
    """Smallest distance from magnet a's two edge circles (sampled) to magnet b's end faces,
    m: where the face integrand comes closest to a singularity."""
    ua, ea1, ea2 = a.frame()
    ub = b.moment_a_m2 / np.linalg.norm(b.moment_a_m2)
    phi = 2.0 * math.pi * np.arange(n) / n
    ring = a.radius_m * (np.cos(phi)[:, None] * ea1 + np.sin(phi)[:, None] * ea2)
    best = math.inf
    for sa in (1.0, -1.0):
        edge = a.position_m + sa * 0.5 * a.length_m * ua + ring
        for sb in (1.0, -1.0):
            rel = edge - (b.position_m + sb * 0.5 * b.length_m * ub)
            axial = rel @ ub
            radial = np.linalg.norm(rel - axial[:, None] * ub, axis=1)
            out = np.maximum(radial - b.radius_m, 0.0)
            best = min(best, float(np.sqrt(axial * axial + out * out).min()))
    # the sampled circle can miss the nearest point by up to the chord's sagitta
    return max(best - a.radius_m * (1.0 - math.cos(math.pi / n)), 0.0)


def pair_force_torque(a: "CylinderMagnet", b: "CylinderMagnet", tol: float = 1e-6
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Force (3,) N on magnet b from magnet a, and the torque (3,) N m on b about b's centre,
    to a relative error of about ``tol`` (the face quadrature's; the field is exact).

    Newton's third law holds for the force (F on a = -F on b); the torques about the two
    centres do not cancel (the pair's angular momentum balance includes r x F).
    """
    u, e1, e2 = b.frame()
    mag_b = float(np.linalg.norm(b.moment_a_m2)) / (math.pi * b.radius_m**2 * b.length_m)
    n_r, n_phi = nodes_for(edge_distance_m(a, b), b.radius_m, tol)
    r, ph, w = face_nodes(n_r, n_phi)
    disc = b.radius_m * ((r * np.cos(ph))[:, None] * e1 + (r * np.sin(ph))[:, None] * e2)
    rel = np.r_[disc + 0.5 * b.length_m * u, disc - 0.5 * b.length_m * u]
    field = cylinder_field(b.position_m + rel, a.position_m, a.moment_a_m2, a.radius_m,
                           a.length_m)
    charge = mag_b * b.radius_m**2 * np.r_[w, -w]
    return charge @ field, charge @ np.cross(rel, field)


class CylinderMagnet:
    """A finger magnet where it is: centre ``position_m`` (3,) m, moment ``moment_a_m2`` (3,)
    A m^2 along its axis, ``radius_m`` and ``length_m`` m."""

    __slots__ = ("position_m", "moment_a_m2", "radius_m", "length_m")

    def __init__(self, position_m, moment_a_m2, radius_m: float, length_m: float):
        self.position_m = np.asarray(position_m, dtype=float)
        self.moment_a_m2 = np.asarray(moment_a_m2, dtype=float)
        self.radius_m = float(radius_m)
        self.length_m = float(length_m)

    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The unit axis u (along the moment) and two unit vectors e1, e2 across it."""
        u = self.moment_a_m2 / np.linalg.norm(self.moment_a_m2)
        e1 = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        return u, e1, np.cross(u, e1)

    @property
    def bounding_radius_m(self) -> float:
        """Radius of the sphere about the centre that holds the cylinder, m."""
        return math.hypot(self.radius_m, 0.5 * self.length_m)

    def overlaps(self, other: "CylinderMagnet") -> bool:
        """Do the two cylinders share a point? (exact for parallel axes, conservative
        otherwise: their bounding capsules)."""
        d = other.position_m - self.position_m
        u = self.moment_a_m2 / np.linalg.norm(self.moment_a_m2)
        v = other.moment_a_m2 / np.linalg.norm(other.moment_a_m2)
        if abs(abs(float(u @ v)) - 1.0) < 1e-12:
            axial = abs(float(d @ u))
            radial = float(np.linalg.norm(d - (d @ u) * u))
            return (axial < 0.5 * (self.length_m + other.length_m)
                    and radial < self.radius_m + other.radius_m)
        return float(np.linalg.norm(d)) < self.bounding_radius_m + other.bounding_radius_m
