"""Scripted finger trajectories for the simulated device: the magnet's centre (m) and its tilt
over time (s).

``slide`` sweeps across an object at a fixed depth below its surface, there and back (thesis
Fig. 4.5); ``poke`` presses down into it and back out, twice; ``tilt`` slides while the finger
splint tilts the magnet up to 45 degrees, its azimuth turning once; a CSV file with columns
``t_s, x_m, y_m, z_m`` (and optionally ``tilt_deg, azimuth_deg``) gives any other path.

Tilt convention: ``tilt_deg`` is the angle between the magnet's moment and the design's moment
direction, ``azimuth_deg`` the direction in the array's x-y plane it tilts towards (0: +x, 90:
+y); between samples both are interpolated linearly (write the azimuth unwrapped).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import BadInputError

TRAJECTORY_COLUMNS = ("t_s", "x_m", "y_m", "z_m")
"""The columns every trajectory file has (SI)."""

TILT_COLUMNS = ("tilt_deg", "azimuth_deg")
"""Optional columns of a trajectory file: the magnet's tilt and its azimuth, degrees."""

TILT_RANGE_DEG = (0.0, 180.0)
"""Valid tilts, degrees (180: the magnet upside down)."""

AZIMUTH_RANGE_DEG = (-3600.0, 3600.0)
"""Valid azimuths, degrees (unwrapped: ten turns either way)."""

SCRIPTED_TILT_DEG = 45.0
"""Largest tilt of the scripted ``tilt`` trajectory, degrees."""


def tilted_direction(reference, tilt_rad, azimuth_rad) -> np.ndarray:
    """Unit vectors (k, 3): ``reference`` (3,) turned by ``tilt_rad`` (k,) towards the array
    direction (cos azimuth, sin azimuth, 0) (Rodrigues' rotation about reference x that
    direction; for a reference along that direction, about the array's z axis)."""
    d = np.asarray(reference, float)
    d = d / np.linalg.norm(d)
    tilt = np.atleast_1d(np.asarray(tilt_rad, float))
    az = np.atleast_1d(np.asarray(azimuth_rad, float))
    e = np.stack([np.cos(az), np.sin(az), np.zeros_like(az)], -1)
    k = np.cross(d, e)
    norm = np.linalg.norm(k, axis=-1, keepdims=True)
    k = np.where(norm > 1e-12, k / np.where(norm > 1e-12, norm, 1.0), [0.0, 0.0, 1.0])
    c, s = np.cos(tilt)[:, None], np.sin(tilt)[:, None]
    return d * c + np.cross(k, d) * s + k * (k @ d)[:, None] * (1 - c)


@dataclass(frozen=True)
class Trajectory:
    """Finger (magnet centre) positions and tilts over time.

    Attributes
    ----------
    t_s : ndarray, shape (k,), s, strictly increasing
    position_m : ndarray, shape (k, 3), m
    tilt_deg, azimuth_deg : ndarray, shape (k,), degrees (default zeros: the design's moment
        direction); see the module docstring for the convention
    """

    t_s: np.ndarray
    position_m: np.ndarray
    tilt_deg: np.ndarray | None = field(default=None)
    azimuth_deg: np.ndarray | None = field(default=None)

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
        for name, valid in (("tilt_deg", TILT_RANGE_DEG), ("azimuth_deg", AZIMUTH_RANGE_DEG)):
            a = np.zeros(len(t)) if getattr(self, name) is None else np.asarray(
                getattr(self, name), float)
            if a.shape != t.shape:
                raise BadInputError(f"trajectory {name}", f"{len(t)} values (one per time)",
                                    f"shape {a.shape}")
            _check_range(name, a, valid)
            object.__setattr__(self, name, a)

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1] - self.t_s[0])

    @property
    def tilted(self) -> bool:
        """True when the magnet ever leaves the design's moment direction."""
        return bool(np.any(self.tilt_deg != 0.0))

    def at(self, t_s: float) -> np.ndarray:
        """Position at time t (linear interpolation, held constant outside), m, shape (3,)."""
        return np.array([np.interp(t_s, self.t_s, self.position_m[:, k]) for k in range(3)])

    def moment_direction(self, t_s, reference) -> np.ndarray:
        """Unit moment directions (k, 3) at the times ``t_s`` (k,) s: ``reference`` (3,) (the
        design's moment direction) tilted as the trajectory says (linear interpolation of
        tilt and azimuth, held constant outside)."""
        t = np.atleast_1d(np.asarray(t_s, float))
        tilt = np.radians(np.interp(t, self.t_s, self.tilt_deg))
        az = np.radians(np.interp(t, self.t_s, self.azimuth_deg))
        return tilted_direction(reference, tilt, az)

    @classmethod
    def from_csv(cls, path, workspace=None) -> "Trajectory":
        """Read ``t_s, x_m, y_m, z_m`` columns (SI, a header line naming them) and, if present,
        ``tilt_deg`` (in [0, 180]) and ``azimuth_deg``. With ``workspace``
        (:class:`designkit.design.workspace.Workspace`, the design's region) every position must
        lie in it: a path in millimetres or below the floor is refused in one line naming the
        column, the file line, the value and the valid range (the map covers only the
        workspace; outside it nothing is rendered)."""
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
            cols = TRAJECTORY_COLUMNS + tuple(c for c in TILT_COLUMNS if c in header)
            idx = [header.index(c) for c in cols]
            rows, line_numbers = [], []
            for line_no, row in enumerate(reader, start=2):
                if not row:
                    continue
                line_numbers.append(line_no)
                try:
                    rows.append([float(row[i]) for i in idx])
                except (ValueError, IndexError):
                    raise BadInputError(f"trajectory line {line_no}", f"{len(cols)} numbers "
                                        f"({', '.join(cols)})", row) from None
        a = np.asarray(rows, float).reshape(-1, len(cols))
        extra = {c: a[:, 4 + j] for j, c in enumerate(cols[4:])}
        for name, valid in (("tilt_deg", TILT_RANGE_DEG), ("azimuth_deg", AZIMUTH_RANGE_DEG)):
            if name in extra:
                _check_range(name, extra[name], valid, lines=True)
        if workspace is not None and len(a):
            _check_workspace(a[:, 1:4], workspace, line_numbers)
        return cls(a[:, 0], a[:, 1:4], **extra)


def _check_range(name: str, values: np.ndarray, valid: tuple, lines: bool = False) -> None:
    """BadInputError naming the column, the first bad value (and its file line) and the range."""
    bad = np.flatnonzero(~((values >= valid[0]) & (values <= valid[1])))
    if len(bad):
        k = int(bad[0])
        where = f" (line {k + 2})" if lines else f" (sample {k})"
        raise BadInputError(f"trajectory column {name}",
                            f"in [{valid[0]:g}, {valid[1]:g}] degrees",
                            f"{values[k]!r}{where}")


def _check_workspace(positions_m, workspace, line_numbers) -> None:
    """BadInputError for the first position (k, 3) m outside ``workspace``: the column, its
    file line and value, the column's valid range (m) and, when the value is in range read as
    millimetres, the hint; a position in the range of every column but outside the outline
    names the outline."""
    lo, hi = workspace.bounds_m()
    tol = 1e-9
    bad = (positions_m < lo - tol) | (positions_m > hi + tol)
    rows = np.flatnonzero(bad.any(axis=1))
    if len(rows):
        k = int(rows[0])
        j = int(np.argmax(bad[k]))
        v = float(positions_m[k, j])
        # a length of a metre or more that lies in the range as millimetres: the unit
        mm = abs(v) >= 1.0 and lo[j] - tol <= v * 1e-3 <= hi[j] + tol
        raise BadInputError(f"trajectory column {('x_m', 'y_m', 'z_m')[j]}",
                            f"in [{lo[j]:.4g}, {hi[j]:.4g}] m (the design's workspace)",
                            f"{v:g} (line {line_numbers[k]})",
                            hint=(f"Millimetres where metres are expected? Write {v * 1e-3:g}."
                                  if mm else ""))
    out = np.flatnonzero(~workspace.contains(positions_m))
    if len(out):
        k = int(out[0])
        raise BadInputError("trajectory x_m, y_m", "inside the design's workspace outline "
                            f"{np.round(workspace.outline * 1e3, 1).tolist()} mm",
                            f"{positions_m[k, :2].tolist()} m (line {line_numbers[k]})")


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


def tilt_trajectory(surface_height, *, duration_s: float = 4.0,
                    max_tilt_deg: float = SCRIPTED_TILT_DEG, **slide) -> Trajectory:
    """:func:`slide_trajectory` while the splint tilts the magnet from 0 up to ``max_tilt_deg``
    and back (raised cosine), its azimuth turning once (0 -> 360 degrees); ``slide``: the
    slide's keywords."""
    s = slide_trajectory(surface_height, duration_s=duration_s, **slide)
    phase = s.t_s / duration_s
    tilt = max_tilt_deg * (0.5 - 0.5 * np.cos(2 * np.pi * phase))
    return Trajectory(s.t_s, s.position_m, tilt, 360.0 * phase)


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
