"""Workspace metrics of an array: the largest vertical force under the drive limits, where it
passes the human threshold, and the conditioning of A (thesis chapter 2, eq. 2.13).

Forces in N, currents in A, lengths in m; A (n, 8, n_coils) as :data:`designkit.model.array.ROWS`.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy.optimize import linprog

from ..errors import BadInputError
from ..support import validate as v
from ..support.atomic import atomic_path
from .array import CoilArray, force_matrix


def fz_per_amp(actuation: np.ndarray, moment) -> np.ndarray:
    """Vertical force per ampere of each coil, (n, n_coils), N/A, from A (n, 8, n_coils)."""
    return np.einsum("k,nkc->nc", force_matrix(moment)[2], actuation[:, 3:, :])


def max_vertical_force(fz_coeff: np.ndarray, max_current: float, total_current: float, *,
                       lateral: Literal["free", "zero"] = "free") -> np.ndarray:
    """Largest upward force reachable at each point under the drive limits, N.

    Maximize ``Fz = a . I`` subject to ``|I_k| <= max_current`` and ``sum |I_k| <= total_current``.

    ``lateral='free'``: closed form (a fractional knapsack with equal weights): give
    ``max_current`` with sign(a_k) to the coils with the largest |a_k| until the budget is spent.
    ``lateral='zero'``: also require Fx = Fy = 0 (a pure push); one linear program per point
    (scipy.optimize.linprog, HiGHS) -- then ``fz_coeff`` must be (n, 3, n_coils) force per amp.

    Parameters
    ----------
    fz_coeff : ndarray, shape (n, n_coils) N/A ('free') or (n, 3, n_coils) N/A ('zero')
    max_current, total_current : float, A

    Returns
    -------
    ndarray, shape (n,), N (>= 0).
    """
    imax = v.positive("max_current", max_current, "A")
    itot = v.positive("total_current", total_current, "A")
    if lateral == "free":
        a = np.sort(np.abs(np.asarray(fz_coeff, dtype=float)), axis=1)[:, ::-1]
        n_full = int(min(a.shape[1], itot // imax))
        out = imax * a[:, :n_full].sum(axis=1)
        if n_full < a.shape[1]:
            out += (itot - n_full * imax) * a[:, n_full]
        return out
    if lateral != "zero":
        raise BadInputError("lateral", "'free' or 'zero'", lateral)
    f = np.asarray(fz_coeff, dtype=float)
    nc = f.shape[2]
    # I = Ip - In with Ip, In >= 0: the L1 budget becomes linear
    a_ub = np.ones((1, 2 * nc))
    out = np.empty(len(f))
    for k in range(len(f)):
        c = -np.r_[f[k, 2], -f[k, 2]]
        a_eq = np.c_[f[k, :2], -f[k, :2]]
        res = linprog(c, A_ub=a_ub, b_ub=[itot], A_eq=a_eq, b_eq=[0.0, 0.0],
                      bounds=[(0, imax)] * (2 * nc), method="highs")
        out[k] = -res.fun if res.status == 0 else 0.0
    return out


def condition_number(actuation: np.ndarray, length_scale: float = 0.03) -> np.ndarray:
    """2-norm condition number of A(p) with the gradient rows times ``length_scale`` (m).

    The rows of A have different units (T/A and T/(m A)); scaling the gradient rows by a length
    (default 30 mm, the design height) makes the singular values comparable.
    Returns shape (n,); inf where A is rank deficient.
    """
    a = np.array(actuation, dtype=float, copy=True)
    a[:, 3:, :] *= v.positive("length_scale", length_scale)
    s = np.linalg.svd(a, compute_uv=False)
    with np.errstate(divide="ignore"):
        return np.where(s[:, -1] > 0, s[:, 0] / np.where(s[:, -1] > 0, s[:, -1], 1.0), np.inf)


def workspace_metrics(design, *, spacing: float = 0.005, heights=None, out_png=None,
                      array: CoilArray | None = None) -> dict:
    """Largest vertical force, where it passes the human threshold, and conditioning.

    Evaluated on horizontal planes (``heights``, m above the coil tops; default 10, 30, 50 mm)
    over the bounding box of the workspace's outline (the layout's footprint,
    :meth:`designkit.design.Design.workspace_region`) with the design's drive limits (per
    coil and total) and a magnet of the design (its moment vector, MagnetSpec.direction);
    ``fraction_above_threshold`` counts the points inside the outline.

    Returns a dict of arrays and summary numbers; writes a PNG map to ``out_png`` if given.
    """
    arr = array or CoilArray.from_design(design)
    region = design.workspace_region()
    lo, hi = region.bounds_m()
    heights = (0.010, 0.030, 0.050) if heights is None else tuple(heights)
    xs = np.arange(lo[0], hi[0] + 1e-12, spacing)
    ys = np.arange(lo[1], hi[1] + 1e-12, spacing)
    m = np.array(design.magnet.moment_vector_a_m2)
    thr = design.render.threshold_n
    X, Y = np.meshgrid(xs, ys, indexing="xy")
    inside = region.contains_xy(np.c_[X.ravel(), Y.ravel()]).reshape(X.shape)
    fmax, cond = [], []
    for h in heights:
        pts = np.c_[X.ravel(), Y.ravel(), np.full(X.size, h)]
        # the array's own exact matrix: designkit.model.skipping (tables, faster) imports this module
        a = arr.actuation_matrix(pts)
        fz = fz_per_amp(a, m)
        fmax.append(max_vertical_force(fz, design.drive.max_current_a,
                                       design.drive.total_current_a).reshape(X.shape))
        cond.append(condition_number(a).reshape(X.shape))
    fmax, cond = np.array(fmax), np.array(cond)
    out = {"heights_m": np.array(heights), "x_m": xs, "y_m": ys, "max_fz_n": fmax,
           "condition": cond, "inside": inside,
           "fraction_above_threshold": [(f[inside] > thr).mean() for f in fmax],
           "threshold_n": thr}
    if out_png is not None:
        _plot_metrics(out, out_png)
    return out


def _plot_metrics(res: dict, out_png) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hs = res["heights_m"]
    ext = np.array([res["x_m"][0], res["x_m"][-1], res["y_m"][0], res["y_m"][-1]]) * 1e3
    fig, axes = plt.subplots(2, len(hs), figsize=(4 * len(hs), 7), squeeze=False)
    for k, h in enumerate(hs):
        ax = axes[0, k]
        im = ax.imshow(res["max_fz_n"][k] * 1e3, origin="lower", extent=ext, cmap="viridis")
        ax.contour(res["max_fz_n"][k] * 1e3, levels=[res["threshold_n"] * 1e3], colors="w",
                   extent=ext, origin="lower")
        ax.set_title(f"max Fz (mN), z = {h * 1e3:.0f} mm\nwhite: {res['threshold_n'] * 1e3} mN")
        fig.colorbar(im, ax=ax)
        ax = axes[1, k]
        im = ax.imshow(np.log10(res["condition"][k]), origin="lower", extent=ext, cmap="magma")
        ax.set_title("log10 cond A (grad rows x 30 mm)")
        fig.colorbar(im, ax=ax)
        for a in axes[:, k]:
            a.set_xlabel("x (mm)")
            a.set_ylabel("y (mm)")
    fig.tight_layout()
    with atomic_path(out_png, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)
