"""The colour ranges of the figures: fixed by the design, not by the currents drawn, so that two
figures of one design (other currents, another kind) read on the same scale.

Each range is set by the coil the design point sits above
(:attr:`designkit.design.Design.design_coil`), alone, at the design's per-coil limit ``drive.max_current_a``:

* |B| (mT): up to its largest |B| :data:`POLE_GAP_M` from its pole (its highest solid's top
  face: the core's, or the winding's bore), on the axis and at the rim (the slices and the field
  lines come that close; nearer the rim's edge the field grows without bound);
* |F| (mN): up to the force on the magnet on its axis at the workspace floor
  ``workspace.z_min_m`` above its top face (the largest force where the magnet's centre can be);
* the coil currents (A): -limit..+limit.

The tops are rounded up to 1, 2 or 5 x 10^k and the log ranges span :data:`DECADES` decades
below them. Values outside a range take its end colour and the figure's title says so.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import math
import warnings

import numpy as np

from ..model.array import force_matrix, g5_from_gradient
from ..model.coil import Coil

if TYPE_CHECKING:  # pragma: no cover
    from ..design import Design

DECADES = 4
"""Decades of a logarithmic colour range below its top."""
POLE_GAP_M = 0.002
"""Height above the reference coil's highest solid where the |B| range's top is taken, m."""


@dataclass(frozen=True)
class ColourRanges:
    """Colour ranges of a design's figures: ``b_mt`` (mT, log), ``f_mn`` (mN, log),
    ``current_a`` (A, linear, symmetric)."""

    b_mt: tuple[float, float]
    f_mn: tuple[float, float]
    current_a: tuple[float, float]


def colour_ranges(design: "Design") -> ColourRanges:
    """The fixed colour ranges of the design's figures (see the module docstring)."""
    k = design.design_coil
    coil = Coil.of_design(design, k)
    frame = design.coil_poses()[k].matrix
    side, axis = frame[:, 0], frame[:, 2]
    top = np.asarray(design.array.top_centres_m()[k], dtype=float)
    c, core = design.coil_spec(k), design.core_spec(k)
    # the pole: the core's top face when it stands above the winding, else the bore's mouth
    above = 0.0 if core is None else max(0.0, core.offset_m + core.length_m / 2 - c.length_m / 2)
    rim = c.inner_radius_m if core is None else core.radius_m
    gap = POLE_GAP_M
    points = top + np.array([(above + gap) * axis, rim * side + (above + gap) * axis,
                             (rim + gap) * side + above * axis,
                             design.workspace.z_min_m * axis])
    u = design.drive.max_current_a
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a scale, not a result: the report states saturation
        b, g = coil.field(points, u, gradient=True)
    f = g5_from_gradient(g[-1:]) @ force_matrix(np.array(design.magnet.moment_vector_a_m2)).T
    return ColourRanges(_log_range(float(np.linalg.norm(b[:-1], axis=1).max()) * 1e3),
                        _log_range(float(np.linalg.norm(f[0])) * 1e3), (-u, u))


def _log_range(top: float) -> tuple[float, float]:
    """(hi / 10^DECADES, hi), hi = top rounded up to 1, 2, 5 x 10^k; (1e-4, 1) for no field."""
    if not top > 0:
        return 1e-4, 1.0
    e = math.floor(math.log10(top))
    hi = min(m * 10.0 ** k for k in (e, e + 1) for m in (1, 2, 5)
             if m * 10.0 ** k >= top * (1 - 1e-9))
    return hi * 10.0 ** -DECADES, hi


def clip_note(values, lo: float, hi: float, unit: str) -> str:
    """'; colours above 500 mT clipped (largest 812)' (and/or below): what the fixed range
    leaves out of the data; '' when nothing is."""
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    notes = []
    if x.size and x.max() > hi * (1 + 1e-9):
        notes.append(f"above {hi:g} {unit} clipped (largest {_number(x.max())})")
    if x.size and x.min() < lo * (1 - 1e-9):
        notes.append(f"below {lo:g} {unit} clipped")
    return ("; colours " + " and ".join(notes)) if notes else ""


def _number(x: float) -> str:
    """3 significant digits without an exponent for the values a figure shows (20300, 0.00412)."""
    return f"{x:.0f}" if abs(x) >= 1000 else f"{x:.3g}"
