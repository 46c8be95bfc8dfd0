"""The bound maps of sensor layouts: each layout's Cramer-Rao bound over a set of scenarios, and
the tables that summarize it by height (and, for two magnets, by separation).

:func:`layout_bounds` evaluates several layouts against one set of scenarios with one response
(the cores' solve is per magnet pose, shared by every sensor); :func:`summary` gives, per group
of scenarios, the worst and median position rms bound, the worst mean absolute error and the
share of magnets whose mean absolute error bound is within an accuracy target, and the worst
direction bound. Lengths in m, angles in rad; :func:`summary_text` prints mm and degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.array import array_for_design
from .crb import Bound, BoundSettings, pose_bound
from .region import Scenarios
from .response import MagnetShape, magnet_response

ACCURACY_TARGET_M = 1.5e-3
"""The position accuracy two fingers need (mean absolute error per magnet), m."""


@dataclass(frozen=True)
class Layout:
    """A sensor layout: ``name``, ``positions_m`` (n, 3), chip ``frames`` (n, 3, 3)."""

    name: str
    positions_m: np.ndarray
    frames: np.ndarray


def layout_bounds(design, layouts, scenarios: Scenarios, settings: BoundSettings,
                  array=None) -> dict[str, Bound]:
    """{layout name: :class:`Bound` over the scenarios}; ``array`` the design's
    :class:`CoilArray` (its cores; used when ``settings.cores`` is 'coupled')."""
    sites = np.concatenate([lay.positions_m for lay in layouts])
    response = scenario_response(design, sites, scenarios, settings, array)
    out, start = {}, 0
    for lay in layouts:
        idx = np.arange(start, start + len(lay.positions_m))
        out[lay.name] = pose_bound(response, scenarios.index, idx, lay.frames, settings)
        start += len(idx)
    return out


def scenario_response(design, sites, scenarios: Scenarios, settings: BoundSettings,
                      array=None):
    """:func:`designkit.sensing.response.magnet_response` of the scenarios' poses at the sites
    (the design's first magnet's shape; its cores when ``settings.cores`` is 'coupled': those
    of ``array``, default the design's)."""
    use = None
    if settings.cores == "coupled":
        use = array_for_design(design) if array is None else array
    return magnet_response(sites, scenarios.positions_m, scenarios.directions,
                           MagnetShape.of(design.magnet), array=use)


def groups(scenarios: Scenarios) -> list[tuple[str, np.ndarray]]:
    """(label, scenario indices): one magnet by height; two by heights and separation."""
    h = np.round(scenarios.heights_m() * 1e3, 1)
    out = []
    if scenarios.n_magnets == 1:
        for z in np.unique(h[:, 0]):
            out.append((f"z {z:g} mm", np.flatnonzero(h[:, 0] == z)))
        return out
    lo, hi = h.min(axis=1), h.max(axis=1)
    sep = np.round(scenarios.separation_m * 1e3, 1)
    for a, b in sorted(set(zip(lo.tolist(), hi.tolist()))):
        for s in np.unique(sep):
            idx = np.flatnonzero((lo == a) & (hi == b) & (sep == s))
            if len(idx):
                heights = f"z {a:g} mm" if a == b else f"z {a:g} / {b:g} mm"
                out.append((f"{heights}, {s:g} mm apart", idx))
    return out


def summary(bound: Bound, scenarios: Scenarios, target_m: float = ACCURACY_TARGET_M) -> dict:
    """Per group of :func:`groups` and over all: ``worst_rms_m``, ``median_rms_m``,
    ``worst_mae_m``, ``within_target`` (share of magnets whose MAE bound <= target_m),
    ``worst_orientation_rad``, ``scenarios``."""
    rows = []
    for label, idx in groups(scenarios) + [("all", np.arange(len(scenarios.index)))]:
        rms, mae = bound.position_rms_m[idx], bound.position_mae_m[idx]
        rows.append({"group": label, "scenarios": int(len(idx)),
                     "worst_rms_m": float(rms.max()), "median_rms_m": float(np.median(rms)),
                     "worst_mae_m": float(mae.max()),
                     "within_target": float(np.mean(mae <= target_m)),
                     "worst_orientation_rad": float(bound.orientation_rms_rad[idx].max()),
                     "unobservable": int((~bound.observable[idx]).sum())})
    return {"target_m": target_m, "rows": rows}


def summary_text(summaries: dict[str, dict]) -> str:
    """{layout name: :func:`summary`} side by side, mm and degrees."""
    names = list(summaries)
    first = summaries[names[0]]
    width = max(len(row["group"]) for row in first["rows"])
    head = ["group".ljust(width)] + [f"{n[:30]:>30}" for n in names]
    lines = [f"per layout: position CRB rms worst / median mm, MAE worst mm, share of magnets "
             f"with MAE <= {first['target_m'] * 1e3:g} mm, direction rms worst deg",
             "  ".join(head)]
    for k, row in enumerate(first["rows"]):
        cells = [row["group"].ljust(width)]
        for n in names:
            r = summaries[n]["rows"][k]
            cells.append(f"{r['worst_rms_m'] * 1e3:6.2f} /{r['median_rms_m'] * 1e3:6.2f} "
                         f"{r['worst_mae_m'] * 1e3:6.2f} {r['within_target']:4.0%} "
                         f"{direction_text(r['worst_orientation_rad']):>5}".rjust(30))
        lines.append("  ".join(cells))
    return "\n".join(lines)


def direction_text(angle_rad: float) -> str:
    """A direction bound in degrees; beyond 90 degrees the linear bound means nothing but
    'unknown', shown as '>90'."""
    deg = math.degrees(angle_rad)
    return ">90" if deg > 90 else f"{deg:.1f}"
