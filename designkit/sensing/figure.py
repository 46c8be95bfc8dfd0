"""The figure of bound maps: for each layout (rows) and height (columns), the position
Cramer-Rao bound (rms, mm, one logarithmic colour scale for the whole figure) over the x-y plane,
with the layout's sensors and the coils' outlines on top. For two magnets the map is over the
pair's centre at equal heights, each point the worst of the pairs centred there. matplotlib,
off-screen (Agg), imported on first use.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from .maps import ACCURACY_TARGET_M

MAX_COLUMNS = 4
"""Heights shown (evenly chosen among the scenarios' heights)."""
MARKERS = {"upper": ("^", "k"), "lower": ("v", "none"), "plane": ("D", "k")}
"""Sensor marker and fill by board: the upper board filled, the lower hollow."""


def panel_values(bound, scenarios, height_m: float):
    """(x (n,), y (n,), value (n,)) m, m, m: the worst position rms over the magnets of the
    scenarios at ``height_m`` (both magnets there), by the lattice point nearest the
    scenario's x-y centre."""
    h = scenarios.heights_m()
    at = np.all(np.abs(h - height_m) < 1e-9, axis=1)
    centre = scenarios.centres_m()[at, :2]
    # a pair's centre falls between lattice points: each goes to the nearest one
    lattice = scenarios.positions_m[:, :2]
    step = np.diff(np.unique(np.round(lattice[:, 0], 9)))
    if len(step):
        origin = lattice.min(axis=0)
        centre = origin + np.round((centre - origin) / step.min()) * step.min()
    centre = np.round(centre, 9)
    val = bound.position_rms_m[at].max(axis=1)
    keys, inv = np.unique(centre, axis=0, return_inverse=True)
    worst = np.full(len(keys), -np.inf)
    np.maximum.at(worst, inv.ravel(), val)
    return keys[:, 0], keys[:, 1], worst


def shown_heights(scenarios) -> np.ndarray:
    """Up to :data:`MAX_COLUMNS` heights at which every magnet of a scenario sits."""
    h = scenarios.heights_m()
    same = np.unique(h[np.all(np.abs(h - h[:, :1]) < 1e-9, axis=1), 0])
    if len(same) <= MAX_COLUMNS:
        return same
    return same[np.round(np.linspace(0, len(same) - 1, MAX_COLUMNS)).astype(int)]


def bound_figure(blocks, design, path, *, title: str = "") -> Path:
    """Write the bound maps to ``path`` (PNG).

    ``blocks``: a list of (scenarios, [(layout, bound, boards), ...]), one block of rows per
    scenario set (one magnet, two magnets); ``boards`` (n_sensors,) the board name of each
    sensor ('upper', 'lower', 'plane').
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    rows = [(scen, lay, bound, boards) for scen, items in blocks
            for lay, bound, boards in items]
    ncol = max(len(shown_heights(scen)) for scen, _ in blocks)
    vals = np.concatenate([b.position_rms_m.ravel() for _, _, b, _ in rows]) * 1e3
    norm = LogNorm(vmin=max(vals.min(), 1e-3), vmax=max(vals.max(), 2 * vals.min(), 1e-2))
    fig, axes = plt.subplots(len(rows), ncol, figsize=(3.6 * ncol + 1.4, 3.5 * len(rows) + 0.8),
                             squeeze=False, constrained_layout=True)
    tops = design.array.top_centres_m()
    radii = [design.coil_spec(k).outer_radius_m for k in range(design.n_coils)]
    image = None
    for r, (scen, lay, bound, boards) in enumerate(rows):
        heights = shown_heights(scen)
        for c in range(ncol):
            ax = axes[r, c]
            if c >= len(heights):
                ax.axis("off")
                continue
            x, y, v = panel_values(bound, scen, heights[c])
            image = _map(ax, x, y, v, norm)
            for (cx, cy, _), rad in zip(tops, radii):
                ax.add_patch(plt.Circle((cx * 1e3, cy * 1e3), rad * 1e3, fill=False,
                                        color="0.6", lw=0.8))
            _sensors(ax, lay, boards)
            kind = "two magnets" if scen.n_magnets == 2 else "one magnet"
            ax.set_title(f"{lay.name} ({len(lay.positions_m)} sensors), {kind}, z = "
                         f"{heights[c] * 1e3:g} mm\nworst {v.max() * 1e3:.3g}, median "
                         f"{np.median(v) * 1e3:.3g} mm", fontsize=8.5)
            ax.set_aspect("equal")
            ax.set_xlabel("x (mm)", fontsize=8)
            ax.set_ylabel("y (mm)", fontsize=8)
            ax.tick_params(labelsize=7)
    bar = fig.colorbar(image, ax=axes, shrink=0.8)
    bar.set_label("position Cramer-Rao bound, rms (mm)", labelpad=22)  # clear of the mark
    bar.ax.axhline(ACCURACY_TARGET_M * 1e3, color="w", lw=1.5)
    bar.ax.text(1.05, ACCURACY_TARGET_M * 1e3, f" {ACCURACY_TARGET_M * 1e3:g} mm",
                transform=bar.ax.get_yaxis_transform(), va="center", fontsize=7)
    text = title or ("Cramer-Rao bound of the magnet position (two magnets: at the pair's "
                     "centre, the worst pair there; sensors: upper board filled, lower hollow)")
    # wrapped to the figure's width: a 10 pt character is about 0.6 x 10 pt wide
    chars = max(40, int(fig.get_size_inches()[0] * 72 / (0.6 * 10)))
    fig.suptitle("\n".join(textwrap.wrap(text, chars)), fontsize=10)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _map(ax, x, y, v, norm):
    """The values on their lattice as cells (mm); cells without a value stay blank."""
    xs, ix = np.unique(np.round(x, 9), return_inverse=True)
    ys, iy = np.unique(np.round(y, 9), return_inverse=True)
    grid = np.full((len(ys), len(xs)), np.nan)
    grid[iy.ravel(), ix.ravel()] = v
    return ax.pcolormesh(_edges(xs) * 1e3, _edges(ys) * 1e3,
                         np.ma.masked_invalid(grid * 1e3), norm=norm, cmap="viridis",
                         shading="flat")


def _edges(c: np.ndarray) -> np.ndarray:
    """Cell edges around sorted centres (half a step beyond the ends)."""
    if len(c) == 1:
        return np.r_[c - 0.005, c + 0.005]
    mid = 0.5 * (c[1:] + c[:-1])
    return np.r_[2 * c[0] - mid[0], mid, 2 * c[-1] - mid[-1]]


def _sensors(ax, lay, boards) -> None:
    for name, (marker, fill) in MARKERS.items():
        sel = np.asarray(boards) == name
        if sel.any():
            p = lay.positions_m[sel] * 1e3
            ax.scatter(p[:, 0], p[:, 1], marker=marker, s=22, facecolors=fill,
                       edgecolors="r" if name != "upper" else "w", linewidths=0.8,
                       label=f"{name} board")
    if len(boards):
        ax.legend(fontsize=6, loc="lower left", framealpha=0.6)
