"""Figures of a simulated run: the finger's path against the object, desired vs rendered force
and the coil currents (thesis Fig. 4.5-like), and a histogram of the loop's compute time.
matplotlib is imported on first use.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .loop import SimulationResult

def plot_run(result: SimulationResult, out_dir, *, surface_height=None, title: str = "") -> list:
    """Fig. 4.5-like figure (path vs object, desired vs rendered force, currents) and a
    loop-timing histogram; returns the PNG paths."""
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    fig = run_figure(result, surface_height=surface_height, title=title)
    p1 = out_dir / "run.png"
    fig.savefig(p1, dpi=130)
    plt.close(fig)
    return [p1, _loop_timing(result, out_dir, plt)]


def run_figure(result: SimulationResult, *, surface_height=None, title: str = ""):
    """The matplotlib figure of run.png: the path against the object, then force and currents
    against time with the runner's off spans shaded and the injected faults marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = result.columns
    fig, ax = plt.subplots(3, 1, figsize=(11.0, 9.5), constrained_layout=True)
    ax[0].plot(c["x_m"] * 1e3, c["z_m"] * 1e3, color="tab:blue", lw=1.5, label="finger (true)")
    est = np.isfinite(c["xe_m"])
    ax[0].plot(c["xe_m"][est] * 1e3, c["ze_m"][est] * 1e3, ".", ms=1.5, color="tab:orange",
               label="finger (estimated)")
    if surface_height is not None:
        xs = np.linspace(-60e-3, 60e-3, 400)
        h = np.asarray(surface_height(xs, np.zeros_like(xs)), float)
        ax[0].fill_between(xs * 1e3, 0, np.where(np.isfinite(h), h, 0) * 1e3, color="0.85",
                           label="object")
    ax[0].set_xlabel("x (mm)")
    ax[0].set_ylabel("z above the coil tops (mm)")
    ax[0].legend(**OUTSIDE, fontsize=8)
    ax[0].set_title(title or "finger path against the object")
    _time_panels(ax, result)
    return fig


def _time_panels(ax, result) -> None:
    """Force and current against time, the runner's off spans shaded and the injected faults
    marked, each named in the legend."""
    c = result.columns
    t = c["t_s"]
    running = c["state"] == "running"
    ax[1].plot(t, c["fz_obj_n"] * 1e3, color="k", lw=1.2, label="object force at the true position")
    ax[1].plot(t, c["fz_n"] * 1e3, color="tab:red", lw=1.0, label="rendered (true force on magnet)")
    ax[1].plot(t, c["fz_ref_n"] * 1e3, color="tab:green", lw=0.8, ls="--",
               label="object force at the estimate")
    _current_lines(ax[2], t, [c[f"i{k + 1}_a"] for k in range(
        sum(1 for key in c if key.startswith("cmd")))])
    for a in ax[1:]:
        _shade_faults(a, t, running)
        _mark_injections(a, result.faults)
        a.set_xlabel("time (s)")
    ax[1].set_ylabel("Fz (mN)")
    ax[1].legend(**OUTSIDE, fontsize=8)
    ax[2].set_ylabel("coil current (A)")
    ax[2].legend(**OUTSIDE, fontsize=7, ncol=2)


IDLE_FRACTION = 0.02
"""A coil whose |current| stays below this fraction of the largest coil current of the run is
drawn as one grey line group ("idle")."""


def coil_colours(n: int) -> list:
    """n distinct RGBA colours for coil lines: tab10 up to 10 coils, tab20 up to 20, else n
    hues evenly spaced around the HSV circle (full saturation, value alternating 0.9 / 0.6)."""
    from matplotlib import colormaps
    from matplotlib.colors import hsv_to_rgb

    if n <= 10:
        return [colormaps["tab10"](k) for k in range(n)]
    if n <= 20:
        return [colormaps["tab20"](k) for k in range(n)]
    return [(*hsv_to_rgb((k / n, 1.0, 0.9 if k % 2 == 0 else 0.6)), 1.0) for k in range(n)]


def _current_lines(ax, t, currents) -> None:
    """One coloured line a coil that carries current (:func:`coil_colours`, labelled with its
    number), the idle ones (:data:`IDLE_FRACTION`) thin and grey under one legend entry."""
    peaks = np.array([np.max(np.abs(i)) if len(i) else 0.0 for i in currents])
    top = float(peaks.max()) if len(peaks) else 0.0
    active = [k for k in range(len(currents)) if peaks[k] > IDLE_FRACTION * top]
    idle = [k for k in range(len(currents)) if k not in active]
    for k in idle:
        ax.plot(t, currents[k], lw=0.6, color="0.7",
                label=f"idle: coils {_numbers(idle)}" if k == idle[0] else None)
    for k, colour in zip(active, coil_colours(len(active))):
        ax.plot(t, currents[k], lw=1.0, color=colour, label=f"coil {k + 1}")


def _numbers(indices) -> str:
    """'1-3, 7, 9-12' for 0-based indices [0, 1, 2, 6, 8, 9, 10, 11] (coils count from 1)."""
    out = []
    group = [indices[0]] if indices else []
    for k in indices[1:]:
        if k == group[-1] + 1:
            group.append(k)
        else:
            out.append(group)
            group = [k]
    if group:
        out.append(group)
    return ", ".join(f"{g[0] + 1}" if len(g) == 1 else f"{g[0] + 1}-{g[-1] + 1}" for g in out)


def _loop_timing(result, out_dir: Path, plt) -> Path:
    """loop_timing.png: the compute time of the running steps, p50, p99 and the period."""
    c = result.columns
    running = c["state"] == "running"
    fig, ax = plt.subplots(figsize=(6.5, 4), constrained_layout=True)
    loop_us = c["loop_s"][running] * 1e6
    if len(loop_us):
        ax.hist(loop_us, bins=60, color="tab:blue")
        for q, ls in ((50, "--"), (99, ":")):
            v = np.percentile(loop_us, q)
            ax.axvline(v, color="k", ls=ls, label=f"p{q} = {v:.0f} us")
        ax.axvline(result.period_s * 1e6, color="tab:red", label="control period")
        ax.legend()
    else:
        ax.text(0.5, 0.5, "no running step", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("compute time per control step (us)")
    ax.set_ylabel("steps")
    ax.set_title("runner loop timing (running steps)")
    path = out_dir / "loop_timing.png"
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


OFF_LABEL = "runner not running (coils off: fault or no fix yet)"
OUTSIDE = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "borderaxespad": 0.0}
"""Legends right of their panel: inside, they covered the curves and the fault labels."""
INJECTED_LABEL = "fault injected"


def _shade_faults(ax, t, running) -> None:
    """Shade the steps the runner was not running; one legend entry for them all."""
    off = ~running
    if not off.any():
        return
    edges = np.flatnonzero(np.diff(np.r_[0, off.astype(int), 0]))
    for k, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
        ax.axvspan(t[a], t[min(b, len(t) - 1)], color="tab:red", alpha=0.08, lw=0,
                   label=OFF_LABEL if k == 0 else None)


def _mark_injections(ax, faults) -> None:
    """A dotted line at each injected fault, its type written at the top of the axes."""
    for k, (te, name) in enumerate(faults):
        ax.axvline(te, color="tab:purple", ls=":", lw=1.0,
                   label=INJECTED_LABEL if k == 0 else None)
        ax.text(te, 1.0, f" {name}", transform=ax.get_xaxis_transform(), rotation=90,
                va="top", ha="left", fontsize=6, color="tab:purple")
