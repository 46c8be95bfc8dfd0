"""Scripted finger trajectories for the simulated device: positions (m) of the magnet's centre
over time (s).

``slide`` sweeps across an object at a fixed depth below its surface, there and back (thesis
Fig. 4.5); ``poke`` presses down into it and back out, twice; a CSV file with columns
``t_s, x_m, y_m, z_m`` gives any other path.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import BadInputError

TRAJECTORY_COLUMNS = ("t_s", "x_m", "y_m", "z_m")


@dataclass(frozen=True)
class Trajectory:
    """Finger (magnet centre) positions over time.

    Attributes
    ----------
    t_s : ndarray, shape (k,), s, strictly increasing
    position_m : ndarray, shape (k, 3), m
    """

    t_s: np.ndarray
    position_m: np.ndarray

    def __post_init__(self):
        t = np.asarray(self.t_s, float)
        p = np.asarray(self.position_m, float)
        if t.ndim != 1 or len(t) < 2 or p.shape != (len(t), 3):
            raise BadInputError("trajectory", "k >= 2 times and a (k, 3) array of positions",
                                f"{t.shape} and {p.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
            raise BadInputError("trajectory", "finite times and positions", "NaN or Inf")
        if np.any(np.diff(t) <= 0):
            raise BadInputError("trajectory t_s", "strictly increasing", t[:5].tolist())
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "position_m", p)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])

    def at(self, t_s: float) -> np.ndarray:
        """Position at time t (linear interpolation, held constant outside), m, shape (3,)."""
        return np.array([np.interp(t_s, self.t_s, self.position_m[:, k]) for k in range(3)])

    @classmethod
    def from_csv(cls, path) -> "Trajectory":
        """Read ``t_s, x_m, y_m, z_m`` columns (SI, a header line naming them)."""
        p = Path(path)
        if not p.is_file():
            raise BadInputError("trajectory", "a CSV file with columns t_s,x_m,y_m,z_m", str(p))
        with p.open(newline="") as fh:
            reader = csv.reader(fh)
            try:
                header = [h.strip() for h in next(reader)]
            except StopIteration:
                raise BadInputError("trajectory", "a header line t_s,x_m,y_m,z_m", "an empty file") \
                    from None
            missing = [c for c in TRAJECTORY_COLUMNS if c not in header]
            if missing:
                raise BadInputError("trajectory columns", "t_s, x_m, y_m, z_m (SI units)",
                                    header, hint=f"missing {missing} in {p}")
            idx = [header.index(c) for c in TRAJECTORY_COLUMNS]
            rows = []
            for line_no, row in enumerate(reader, start=2):
                if not row:
                    continue
                try:
                    rows.append([float(row[i]) for i in idx])
                except (ValueError, IndexError):
                    raise BadInputError(f"trajectory line {line_no}", "four numbers", row) from None
        a = np.asarray(rows, float).reshape(-1, 4)
        return cls(a[:, 0], a[:, 1:])


def slide_trajectory(surface_height, *, duration_s: float = 4.0, half_span_m: float = 0.04,
                     depth_m: float = 0.004, y_m: float = 0.0, z_limits_m=(0.012, 0.078),
                     samples: int = 2001) -> Trajectory:
    """Slide across an object at ``depth_m`` below its surface, there and back (thesis Fig. 4.5).

    Parameters
    ----------
    surface_height : callable
        ``surface_height(x_m, y_m) -> z_m`` of the object's top (arrays); NaN where there is no
        object (the finger then stays at the lowest allowed height).
    duration_s, half_span_m, depth_m, y_m : float
        One sweep x: -half_span -> +half_span -> -half_span (cosine speed profile).
    z_limits_m : (float, float)
        Heights the trajectory is kept within (inside the map box), m.
    """
    t = np.linspace(0.0, duration_s, samples)
    x = -half_span_m * np.cos(2 * np.pi * t / duration_s)
    y = np.full_like(t, y_m)
    h = np.asarray(surface_height(x, y), float)
    z = np.where(np.isfinite(h), h - depth_m, z_limits_m[0])
    z = np.clip(z, *z_limits_m)
    return Trajectory(t, np.stack([x, y, z], 1))


def poke_trajectory(surface_height, *, duration_s: float = 3.0, x_m: float = 0.0,
                    y_m: float = 0.0, above_m: float = 0.015, depth_m: float = 0.010,
                    z_limits_m=(0.012, 0.078), samples: int = 1501) -> Trajectory:
    """Poke down into the object and back out, twice (raised-cosine depth profile)."""
    t = np.linspace(0.0, duration_s, samples)
    h = float(np.asarray(surface_height(np.array([x_m]), np.array([y_m])), float)[0])
    if not math.isfinite(h):
        h = z_limits_m[0] + above_m
    phase = 0.5 - 0.5 * np.cos(4 * np.pi * t / duration_s)   # 0 -> 1 -> 0, twice
    z = np.clip(h + above_m - phase * (above_m + depth_m), *z_limits_m)
    return Trajectory(t, np.stack([np.full_like(t, x_m), np.full_like(t, y_m), z], 1))

