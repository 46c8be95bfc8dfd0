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
    for k in range(sum(1 for key in c if key.startswith("cmd"))):
        ax[2].plot(t, c[f"i{k + 1}_a"], lw=1.0, label=f"coil {k + 1}")
    for a in ax[1:]:
        _shade_faults(a, t, running)
        _mark_injections(a, result.faults)
        a.set_xlabel("time (s)")
    ax[1].set_ylabel("Fz (mN)")
    ax[1].legend(**OUTSIDE, fontsize=8)
    ax[2].set_ylabel("coil current (A)")
    ax[2].legend(**OUTSIDE, fontsize=7, ncol=2)


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
