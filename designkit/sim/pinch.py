"""The scripted pinch: two fingertips approach a block from both sides and squeeze it.

Each magnet's centre is its fingertip's contact point (as for one finger). The block is a
``block_width_m`` square box standing on the coil tops, ``block_height_m`` high; the fingers
move along x at ``finger_z_m`` (the thumb's magnet on -x, the index's on +x, in the design's
magnet order), start ``start_gap_m`` apart (centre to centre), close onto the block's faces,
press ``depth_m`` into it, hold, release and open again (smooth cosine ramps). Times s,
positions m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from firmware_io.cylinder_magnet import CylinderMagnet

from ..errors import BadInputError
from ..render.objects import Plane

PINCH_PHASES_S = (0.0, 0.6, 1.0, 1.8, 2.2, 2.5)
"""Start, contact, full squeeze, end of hold, contact again, open (s, at duration 2.5 s)."""


@dataclass(frozen=True)
class MagnetsTrajectory:
    """N magnets' centres over time: ``t_s`` (k,) s increasing, ``positions_m`` (N, k, 3) m."""

    t_s: np.ndarray
    positions_m: np.ndarray

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])

    @property
    def n_magnets(self) -> int:
        return int(self.positions_m.shape[0])

    def at(self, t_s: float) -> np.ndarray:
        """(N, 3) m at ``t_s`` (linear in between, held outside)."""
        return np.array([[np.interp(t_s, self.t_s, p[:, k]) for k in range(3)]
                         for p in self.positions_m])


@dataclass(frozen=True)
class Pinch:
    """The pinch's geometry (module docstring), m; ``duration_s`` s."""

    block_width_m: float = 0.036
    block_height_m: float = 0.045
    finger_z_m: float = 0.035
    start_gap_m: float = 0.052
    depth_m: float = 0.003
    duration_s: float = 2.5

    def block(self) -> Plane:
        """The block as a virtual object (a square box on the coil tops)."""
        return Plane(size_m=self.block_width_m, height_m=self.block_height_m)

    def gap_m(self, t_s) -> np.ndarray:
        """Centre-to-centre distance of the two fingers at the times ``t_s`` (k,) s, m."""
        ph = np.asarray(PINCH_PHASES_S) * self.duration_s / PINCH_PHASES_S[-1]
        contact = self.block_width_m
        closed = contact - 2 * self.depth_m
        levels = (self.start_gap_m, contact, closed, closed, contact, self.start_gap_m)
        t = np.atleast_1d(np.asarray(t_s, float))
        out = np.full(len(t), levels[-1])
        for a, b, la, lb in zip(ph[:-1], ph[1:], levels[:-1], levels[1:]):
            inside = (t >= a) & (t <= b)
            s = 0.5 - 0.5 * np.cos(math.pi * (t[inside] - a) / (b - a))
            out[inside] = la + (lb - la) * s
        return out


def pinch_trajectory(pinch: Pinch, magnets, bounds, *, step_s: float = 1e-3
                     ) -> MagnetsTrajectory:
    """The pinch's two paths (module docstring) for the design's ``magnets`` (specs with
    ``name``, ``radius_m``, ``length_m``, ``moment_vector_a_m2``) inside the map's box
    ``bounds`` ((3,), (3,)) m. Refused in one line: not exactly two magnets, a path leaving
    the box, or magnets that overlap anywhere along it."""
    magnets = list(magnets)
    if len(magnets) != 2:
        raise BadInputError("--trajectory pinch", "a design with two [[magnets]] (one per "
                            "fingertip)", f"{len(magnets)} magnet(s)")
    t = np.arange(0.0, pinch.duration_s + 0.5 * step_s, step_s)
    half = 0.5 * pinch.gap_m(t)
    paths = np.zeros((2, len(t), 3))
    paths[0, :, 0], paths[1, :, 0] = -half, half
    paths[:, :, 2] = pinch.finger_z_m
    lo, hi = (np.asarray(b, float) for b in bounds)
    outside = ~np.all((paths >= lo) & (paths <= hi), axis=-1)
    if outside.any():
        i, s = (int(a[0]) for a in np.nonzero(outside))
        box = f"{np.round(lo * 1e3, 1).tolist()}..{np.round(hi * 1e3, 1).tolist()} mm"
        raise BadInputError(f"--trajectory pinch ({magnets[i].name})",
                            f"positions inside the map box {box}",
                            f"{np.round(paths[i, s] * 1e3, 1).tolist()} mm")
    closest = int(np.argmin(half))
    a, b = (CylinderMagnet(paths[k, closest], m.moment_vector_a_m2, m.radius_m, m.length_m)
            for k, m in enumerate(magnets))
    if a.overlaps(b):
        raise BadInputError("--trajectory pinch", "magnets apart along the pinch (centres "
                            f"{2 * half[closest] * 1e3:.1f} mm apart at their closest)",
                            f"{magnets[0].name} and {magnets[1].name} (radii "
                            f"{magnets[0].radius_m * 1e3:g}, {magnets[1].radius_m * 1e3:g} mm)"
                            " overlap")
    return MagnetsTrajectory(t, paths)
