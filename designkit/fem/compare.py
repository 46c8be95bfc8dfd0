"""Set designkit's models beside a GetDP solution: tables and plots.

Everything is in the winding's local frame (centre at z = 0); heights are reported above the
winding's top face.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path

import numpy as np

from ..constants import MU0
from ..cores.saturation import SaturationWarning
from ..errors import BadInputError
from ..field.winding import winding_rz
from ..support.atomic import atomic_path
from .runner import FemResult


def model_field(coil, current: float, r: float, z_local: np.ndarray, core_model: str | None):
    """Bz, dBz/dz (T, T/m) of winding + core (``core_model``; None = winding only) on r = const."""
    z_local = np.asarray(z_local, dtype=float)
    n = len(z_local)
    j = coil.turns * current / ((coil.outer_radius - coil.inner_radius) * coil.length)
    w = winding_rz(coil.inner_radius, coil.outer_radius, coil.length / 2, np.full(n, r), z_local,
                   gradient=True, rtol=1e-11)
    bz = w[1] * MU0 * j
    dbz = w[5] * MU0 * j
    if core_model is not None and coil.core is not None:
        core = dataclasses.replace(coil.core, model=core_model)
        c2 = dataclasses.replace(coil, core=core)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SaturationWarning)
            b, g = core.field_local(np.column_stack([np.full(n, r), np.zeros(n), z_local]), c2,
                                    current, gradient=True)
        bz = bz + b[:, 2]
        dbz = dbz + g[:, 2, 2]
    return bz, dbz


def air_inductance(coil, nr: int = 16, nz: int = 48) -> float:
    """Air-core self-inductance by quadrature of the winding's own flux linkage, H.

    L = (N / S)^2 int_S Phi(r, z) dS / (N J / S ...) -- written per ampere: the flux through the
    disc of radius r at height z, averaged over the winding section, times N. Independent of
    the FEM: the reference the FEM's air-core inductance is checked against (docs/fem.md).
    """
    ri, ro, length, n_turns = coil.inner_radius, coil.outer_radius, coil.length, coil.turns
    j = n_turns / ((ro - ri) * length)

    def gl(a, b, n):
        x, w = np.polynomial.legendre.leggauss(n)
        return 0.5 * (a + b) + 0.5 * (b - a) * x, 0.5 * (b - a) * w

    rs, wr = gl(ri, ro, nr)
    zs, wz = [], []
    edge = min(0.05 * length, 0.005)
    for a, b in ((-length / 2, -length / 2 + edge), (-length / 2 + edge, length / 2 - edge),
                 (length / 2 - edge, length / 2)):
        x, w = gl(a, b, nz // 2)
        zs.append(x)
        wz.append(w)
    zs = np.concatenate(zs)
    wz = np.concatenate(wz)
    # flux through the disc (r, z): integrate Bz r' dr' on [0, ri] and [ri, r]
    xg, wg = np.polynomial.legendre.leggauss(24)
    total = 0.0
    for r, w1 in zip(rs, wr):
        pts_r, pts_w = [], []
        for a, b in ((0.0, ri), (ri, r)):
            pts_r.append(0.5 * (a + b) + 0.5 * (b - a) * xg)
            pts_w.append(0.5 * (b - a) * wg)
        pr = np.concatenate(pts_r)
        pw = np.concatenate(pts_w) * 2 * math.pi * pr
        rr = np.tile(pr, len(zs))
        zz = np.repeat(zs, len(pr))
        bz = winding_rz(ri, ro, length / 2, rr, zz, rtol=1e-11)[1] * MU0 * j
        phi = (bz.reshape(len(zs), len(pr)) * pw[None, :]).sum(axis=1)
        total += w1 * np.sum(wz * phi)
    return float(n_turns / ((ro - ri) * length) * total)


def comparison_table(coil, fem: FemResult, heights: np.ndarray) -> dict:
    """Relative errors of each model vs FEM along both lines at ``heights`` above the top (m)."""
    top = coil.length / 2
    z = top + np.asarray(heights, dtype=float)
    out = {"height_m": np.asarray(heights, dtype=float)}
    models = [None] if coil.core is None else ["surface-current", "thesis-uniform"]
    for name, line in (("axis", fem.axis), ("off_axis", fem.off_axis)):
        fit = line.fit(z)
        entry = {"fem_bz_t": fit["bz"], "fem_dbz_dz_t_per_m": fit["dbz_dz"]}
        for m in models:
            bz, dbz = model_field(coil, fem.current, line.r, z, m)
            key = m or "winding"
            entry[f"{key}_bz_t"] = bz
            entry[f"{key}_dbz_dz_t_per_m"] = dbz
            entry[f"{key}_bz_rel_err"] = bz / fit["bz"] - 1.0
            entry[f"{key}_dbz_dz_rel_err"] = dbz / fit["dbz_dz"] - 1.0
        out[name] = entry
    return out


def plot_comparison(coil, fem: FemResult, path: str | Path, title: str = "") -> Path:
    """PNG of :func:`comparison_figure`; returns the path."""
    import matplotlib.pyplot as plt

    fig = comparison_figure(coil, fem, title)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return path


def comparison_figure(coil, fem: FemResult, title: str = ""):
    """Bz and dBz/dz along the axis and the off-axis line, FEM vs designkit's models (rows 1-2),
    and their relative differences to the FEM in % (row 3, symmetric-log scale: the 0.1-1 %
    of the default model next to the tens of % of the thesis' model)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    top = coil.length / 2
    fig, axes = plt.subplots(3, 2, figsize=(11, 9.5), sharex=True)
    models = [None] if coil.core is None else ["surface-current", "thesis-uniform"]
    for col, line in enumerate((fem.axis, fem.off_axis)):
        sel = (line.z > top + 0.012) & (line.z < top + 0.102)
        zz = line.z[sel]
        hmm = (zz - top) * 1e3
        fit = line.fit(zz)
        axes[0, col].plot(hmm, fit["bz"] * 1e3, "k-", lw=3, alpha=0.4, label="GetDP FEM")
        axes[1, col].plot(hmm, fit["dbz_dz"], "k-", lw=3, alpha=0.4, label="GetDP FEM")
        for m, colour, style in zip(models, ("C0", "C3"), ("--", ":")):
            bz, dbz = model_field(coil, fem.current, line.r, zz, m)
            name = m or "designkit winding"
            axes[0, col].plot(hmm, bz * 1e3, colour + style, label=name)
            axes[1, col].plot(hmm, dbz, colour + style, label=name)
            axes[2, col].plot(hmm, _percent(bz, fit["bz"]), colour + "-", label=f"{name}: Bz")
            axes[2, col].plot(hmm, _percent(dbz, fit["dbz_dz"]), colour + "--",
                              label=f"{name}: dBz/dz")
        axes[0, col].set_title(f"r = {line.r * 1e3:.0f} mm")
        axes[2, col].set_xlabel("height above the winding top, mm")
        axes[2, col].set_yscale("symlog", linthresh=0.1)
        axes[2, col].axhline(0.0, color="k", lw=0.8)
    axes[0, 0].set_ylabel("Bz, mT")
    axes[1, 0].set_ylabel("dBz/dz, T/m")
    axes[2, 0].set_ylabel("(model - FEM) / |FEM|, %\n(symlog, linear within 0.1 %)")
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(title or f"FEM vs designkit at {fem.current:g} A")
    fig.tight_layout()
    return fig


def _percent(model, fem) -> np.ndarray:
    """(model - fem) / |fem| in %, 0 where the FEM value is 0."""
    fem = np.asarray(fem, float)
    out = np.zeros_like(fem)
    nz = fem != 0
    out[nz] = (np.asarray(model, float)[nz] - fem[nz]) / np.abs(fem[nz]) * 100
    return out


def model_rz(coil, current: float, r: np.ndarray, z_local: np.ndarray, *,
             core_model: str | None = "surface-current", rule: str = "auto") -> dict:
    """Winding + core field of designkit at local (r, z) points: dict of arrays br, bz (T),
    dbr_dz, dbz_dz, dbr_dr, br_over_r (T/m); ``core_model`` None = winding only."""
    r = np.asarray(r, dtype=float)
    z = np.asarray(z_local, dtype=float)
    j = coil.turns * current / ((coil.outer_radius - coil.inner_radius) * coil.length)
    w = winding_rz(coil.inner_radius, coil.outer_radius, coil.length / 2, r, z,
                   gradient=True, rtol=1e-11)
    # winding_rz gradient tuple: br, bz, dbr_drho, dbr_dz, dbz_drho, dbz_dz, br_over_rho
    out = {"br": w[0] * MU0 * j, "bz": w[1] * MU0 * j, "dbr_dr": w[2] * MU0 * j,
           "dbr_dz": w[3] * MU0 * j, "dbz_dz": w[5] * MU0 * j, "br_over_r": w[6] * MU0 * j}
    if core_model is not None and coil.core is not None:
        core = dataclasses.replace(coil.core, model=core_model)
        c2 = dataclasses.replace(coil, core=core)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SaturationWarning)
            sol = core.solution(c2, current)
        pts = np.column_stack([r, np.zeros_like(r), z])
        b, g = sol.field(pts, gradient=True, rule=rule)
        # on the y = 0 half-plane x = r: x is the radial, z the axial direction
        out["br"] = out["br"] + b[:, 0]
        out["bz"] = out["bz"] + b[:, 2]
        out["dbr_dr"] = out["dbr_dr"] + g[:, 0, 0]
        out["dbr_dz"] = out["dbr_dz"] + g[:, 0, 2]
        out["dbz_dz"] = out["dbz_dz"] + g[:, 2, 2]
        out["br_over_r"] = out["br_over_r"] + g[:, 1, 1]
    return out


def probe_errors(coil, fem: FemResult, *, core_model: str | None = "surface-current",
                 rule: str = "auto") -> dict:
    """designkit vs GetDP at the probe points of ``fem`` (``solve(probes=...)``).

    Error measures (dimensionless), chosen so that sign changes of a component do not blow up:

    * ``b_err``: |B_model - B_fem| / |B_fem| (vector, r and z components);
    * ``dbz_err``: |dBz/dz_model - dBz/dz_fem| / max(|dBz/dz_fem|, ||G_fem||_F / 2), with
      ||G||_F the Frobenius norm of the FEM's gradient tensor at the point (from dBr/dz = dBz/dr,
      dBz/dz, Br/r and dBr/dr = -dBz/dz - Br/r): the plain relative error wherever dBz/dz is
      at least half the gradient's size, a local scale where dBz/dz passes through zero.
    * ``dbz_rel``: the plain relative error (for the table).
    """
    pr = fem.probes
    if pr is None:
        raise BadInputError("fem.probes", "a FemResult solved with probes=...", None)
    m = model_rz(coil, fem.current, pr["r"], pr["z"], core_model=core_model, rule=rule)
    b_fem = np.hypot(pr["br"], pr["bz"])
    b_err = np.hypot(m["br"] - pr["br"], m["bz"] - pr["bz"]) / b_fem
    with np.errstate(divide="ignore", invalid="ignore"):
        br_over_r = np.where(pr["r"] > 1e-6, pr["br"] / np.maximum(pr["r"], 1e-30),
                             -0.5 * pr["dbz_dz"])
    dbr_dr = -pr["dbz_dz"] - br_over_r
    g_norm = np.sqrt(pr["dbz_dz"] ** 2 + 2 * pr["dbr_dz"] ** 2 + br_over_r ** 2 + dbr_dr ** 2)
    scale = np.maximum(np.abs(pr["dbz_dz"]), 0.5 * g_norm)
    dbz_err = np.abs(m["dbz_dz"] - pr["dbz_dz"]) / scale
    return {"r": pr["r"], "z": pr["z"], "model": m, "fem": pr, "b_err": b_err,
            "dbz_err": dbz_err, "dbz_rel": m["dbz_dz"] / pr["dbz_dz"] - 1.0,
            "g_norm_fem": g_norm}


PITCH_M = 0.05
"""Array pitch of the thesis layout, m: 'between' probes sit at neighbours' positions."""


def probe_set(coil, pitch: float = PITCH_M) -> tuple[np.ndarray, list[str]]:
    """Probe points all around ``coil`` (local frame, m) and their class labels.

    Classes: ``above`` / ``below`` the coil and core, ``beside`` the winding (level with it,
    including (r, z) = (20, -6), (25, 20), (30, 0) mm, docs/fem.md), ``bore`` (inside the bore beyond the core's ends
    or between a thin core and the winding, when there is room), ``between`` (half-way to and
    at the neighbours' axes at ``pitch``, side and diagonal). Every vertical probe segment
    (+-2.5 mm) lies in air.

    Returns
    -------
    points : ndarray (n, 2), (r, z) m
    labels : list of str (n)
    """
    ri, ro, hl = coil.inner_radius, coil.outer_radius, coil.length / 2
    core = coil.core
    ct = core.offset + core.length / 2 if core else -np.inf
    cb = core.offset - core.length / 2 if core else np.inf
    mt, mb = max(hl, ct), min(-hl, cb)
    pts: list[tuple[float, float, str]] = []
    for sgn, m0, lab in ((1.0, mt, "above"), (-1.0, mb, "below")):
        for r, dz in ((0.0, 0.008), (0.0, 0.030), (0.6 * ro, 0.005), (ro, 0.004),
                      (ro, 0.020), (1.5 * ro, 0.010)):
            pts.append((r, m0 + sgn * dz, lab))
    for r, z in ((0.020, -0.006), (0.025, 0.020), (0.030, 0.0), (ro + 0.002, 0.8 * hl),
                 (ro + 0.002, -0.7 * hl), (ro + 0.006, 0.3 * hl)):
        pts.append((r, z, "beside"))
    if core is not None:
        if ct < hl - 0.008:
            pts.append((0.0, ct + 0.004, "bore"))
            pts.append((0.5 * ri, 0.5 * (ct + hl), "bore"))
        if cb > -hl + 0.008:
            pts.append((0.0, cb - 0.004, "bore"))
            pts.append((0.5 * ri, 0.5 * (cb - hl), "bore"))
        if ri - core.radius >= 0.003:
            pts.append((0.5 * (ri + core.radius), core.offset, "bore"))
    for r, z in ((0.5 * pitch, 0.0), (0.5 * pitch, mt + 0.010), (pitch, 0.0),
                 (pitch, hl + 0.020), (pitch, -hl - 0.010), (math.sqrt(2) * pitch, 0.030),
                 (math.sqrt(0.5) * pitch, -0.030)):
        pts.append((r, z, "between"))
    arr = np.array([(r, z) for r, z, _ in pts])
    return arr, [lab for _, _, lab in pts]
