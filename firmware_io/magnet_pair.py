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
point dipoles.

At run time (:class:`MagnetPairs`, :func:`pair_forces`) a pair whose centres are far enough
apart for the proven bound of :mod:`firmware_io.magnet_charges` (each magnet as 4 pairs of
charges on its axis, its multipoles to l = 7) is computed from the charges; the face quadrature
runs only for closer pairs. Positions m, moments A m^2, forces N, torques N m; numpy only (runs
on the controller, which compensates the pair's force at run time: it depends on both
positions).
"""

from __future__ import annotations

import math

import numpy as np

from .cylinder_magnet import CylinderMagnet, check_apart
from .errors import BadInputError
from .localization.magnet import cylinder_field
from .magnet_charges import AxialCharges, PairBound, charge_forces

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


PAIR_TOL = 1e-4
"""Default error of :class:`MagnetPairs`, relative to the pair's dipole scale 3 mu0 |m_a|
|m_b| / (4 pi R^4) (force) and 2 mu0 |m_a| |m_b| / (4 pi R^3) (torque)."""


class MagnetPairs:
    """The finger magnets' pull on each other, for a fixed set of N magnets (cylinders of
    ``radii_m`` and ``lengths_m``, (N,) m; ``names`` for the messages), to ``tol`` relative to
    each pair's dipole scale (:data:`PAIR_TOL`).

    Built once (the charge models and, per pair, the distance from which their proven bound
    holds: ``switch_distance_m`` (N, N) m); :meth:`forces` at run time."""

    def __init__(self, radii_m, lengths_m, tol: float = PAIR_TOL, names=None):
        r = np.asarray(radii_m, float).ravel()
        length = np.asarray(lengths_m, float).ravel()
        if (r.shape != length.shape or not len(r) or not np.all(np.isfinite(r))
                or not np.all(np.isfinite(length)) or np.any(r <= 0) or np.any(length <= 0)):
            raise BadInputError("radii_m, lengths_m", "equal numbers of positive sizes, m",
                                f"{r.tolist()}, {length.tolist()}")
        if not (math.isfinite(tol) and 0.0 < tol < 1.0):
            raise BadInputError("tol", "in (0, 1)", tol)
        self.radii_m, self.lengths_m, self.tol = r, length, float(tol)
        self.names = [str(k) for k in range(len(r))] if names is None else list(names)
        geo = {}
        self.models = [geo.setdefault((a, b), AxialCharges(a, b)) for a, b in zip(r, length)]
        n = len(r)
        self.switch_distance_m = np.full((n, n), np.inf)
        for i in range(n):
            for j in range(i + 1, n):
                d = PairBound(self.models[i], self.models[j]).switch_distance_m(self.tol)
                self.switch_distance_m[i, j] = self.switch_distance_m[j, i] = d
        # compared with squared distances; a magnet and itself: no pair (-1 < any square)
        self.switch_squared_m2 = self.switch_distance_m ** 2
        np.fill_diagonal(self.switch_squared_m2, -1.0)

    def forces(self, positions_m, moments_a_m2) -> tuple[np.ndarray, np.ndarray]:
        """Force (N, 3) N and torque (N, 3) N m (about its centre) on each magnet from all the
        others, magnets at ``positions_m`` (N, 3) m with ``moments_a_m2`` (N, 3) A m^2 (each
        along its axis). Overlapping magnets are refused (:func:`check_apart`)."""
        pos = np.asarray(positions_m, float)
        mom = np.asarray(moments_a_m2, float)
        n = len(self.models)
        # one reduction for both (a NaN or an Inf makes the sum non-finite; the element-wise
        # test only when it is, so that a sum that overflows does not refuse finite input)
        finite = (math.isfinite(float(np.abs(pos).sum() + np.abs(mom).sum()))
                  or bool(np.all(np.isfinite(pos)) and np.all(np.isfinite(mom))))
        if pos.shape != (n, 3) or mom.shape != (n, 3) or not finite:
            raise BadInputError("positions_m, moments_a_m2", f"finite arrays of shape ({n}, 3)",
                                f"shapes {pos.shape}, {mom.shape}")
        diff = pos[:, None, :] - pos[None, :, :]
        close = np.einsum("ijk,ijk->ij", diff, diff) < self.switch_squared_m2
        force, torque = (charge_forces(pos, mom, self.models, ~close) if n > 1
                         else (np.zeros((1, 3)), np.zeros((1, 3))))
        if close.any():
            mags = [CylinderMagnet(p, m, a, b) for p, m, a, b in zip(pos, mom, self.radii_m,
                                                                       self.lengths_m)]
            check_apart(mags, self.names)
            for i, j in zip(*np.nonzero(np.triu(close, 1))):
                f, t = pair_force_torque(mags[i], mags[j], self.tol)
                force[j] += f
                force[i] -= f
                torque[j] += t
                torque[i] += pair_force_torque(mags[j], mags[i], self.tol)[1]
        return force, torque


def pair_forces(positions_m, moments_a_m2, radii_m, lengths_m, tol: float = PAIR_TOL):
    """Force (N, 3) N and torque (N, 3) N m on each of N cylinder magnets from the others
    (:class:`MagnetPairs`, built for this call: a runner keeps one)."""
    return MagnetPairs(radii_m, lengths_m, tol).forces(positions_m, moments_a_m2)
