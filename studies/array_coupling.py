"""The array as one magnetic system: how much do coupled cores, the magnet's pull on
the iron and saturation change what the controller must know?

Question: over the workspace of the default 3x3 array (linear mu_r 1000 cores), how different
is the coupled actuation matrix (all cores solved together, designkit.cores.coupled) from the
thesis' uncoupled one (each core magnetized by its own winding), and from the 3-D GetDP FEM
(designkit.fem.fem3d, with ``--fem``: level 0, within 0.6 / 1.3 % (B / grad B) of its level-1 solution; level -2
with ``--quick``)? What is the magnet's pull on the iron F0(p) with every
coil off (vertical slice, PNG)? What error does the core field the magnet induces leave in
the thesis' upper-minus-lower sensor subtraction? How large is the 1010-steel saturation
correction, against the nonlinear axisymmetric GetDP FEM (``--saturation-fem``)? What do the
solve and a point cost, and how converged are the modes (m_max) and panels (refine)?

Writes ``array_coupling.json`` and ``array_coupling_f0.png`` under the output folder (default
out/array_coupling/) and returns the summary dict. Timings are on whatever machine runs it
(say whether it was loaded).
Usage: ``PYTHONPATH=$PWD python studies/array_coupling.py [out_dir] [--quick] [--fem]
[--saturation-fem]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from designkit import default_design
from designkit.support.atomic import write_json_atomic
from designkit.support.progress import tqdm
from designkit.model.array import CoilArray, gradient_from_g5
from designkit.model.coil import Coil
from designkit.cores import ArraySystem, M_MAX, saturation_table
from designkit.fem import fem3d
from designkit.fem.runner import solve
from designkit.field import dipole_field

DEFAULT_OUT = Path(__file__).resolve().parents[1] / "out" / "array_coupling"
"""Default output folder (git-ignored), whatever the working directory."""


FEM_NOT_RUN = "fem: not run"


def _gzz(a):
    """dBz/dz from rows dBx/dx, dBy/dy of A (..., 8, k)."""
    return -(a[..., 3, :] + a[..., 6, :])


def _table_points(quick):
    xs = (0.0, 0.025, 0.05) if quick else (0.0, 0.025, 0.05, 0.075)
    hs = (0.012, 0.03) if quick else (0.012, 0.03, 0.05, 0.08)
    return np.array([[x, y, h] for h in hs for x in xs for y in (0.0, 0.025) if y <= x])


def coupling_table(arr, pts, fem=None, coil=4):
    """Rows per point for ``coil``'s column: |B| and dBz/dz uncoupled, coupled, FEM (with the
    FEM: |dB| / |B|, ||dG||_F / ||G||_F and the relative dBz/dz difference, FEM reference)."""
    a = arr.actuation_matrix(pts)
    au = arr.uncoupled_actuation_matrix(pts)
    rows = []
    for i, p in enumerate(pts):
        b_c, b_u = np.linalg.norm(a[i, :3, coil]), np.linalg.norm(au[i, :3, coil])
        g_c, g_u = _gzz(a[i])[coil], _gzz(au[i])[coil]
        row = {"x_mm": p[0] * 1e3, "y_mm": p[1] * 1e3, "z_mm": p[2] * 1e3,
               "bz_uncoupled_t": au[i, 2, coil], "bz_coupled_t": a[i, 2, coil],
               "b_uncoupled_t": b_u, "b_coupled_t": b_c, "b_change": b_c / b_u - 1.0,
               "dbz_dz_uncoupled_t_per_m": g_u, "dbz_dz_coupled_t_per_m": g_c,
               "dbz_dz_change": g_c / g_u - 1.0}
        if fem is None:
            row["fem"] = FEM_NOT_RUN
        else:
            bf, gf = fem
            row["b_fem_t"] = float(np.linalg.norm(bf[i]))
            row["dbz_dz_fem_t_per_m"] = float(gf[i, 2, 2])
            row["b_coupled_vs_fem"] = float(np.linalg.norm(a[i, :3, coil] - bf[i])
                                            / np.linalg.norm(bf[i]))
            row["b_uncoupled_vs_fem"] = float(np.linalg.norm(au[i, :3, coil] - bf[i])
                                              / np.linalg.norm(bf[i]))
            row["dbz_dz_coupled_vs_fem"] = float(g_c / gf[i, 2, 2] - 1.0)
            g_full = gradient_from_g5(a[i, 3:, coil])
            row["grad_b_coupled_vs_fem"] = float(np.linalg.norm(g_full - gf[i])
                                                 / np.linalg.norm(gf[i]))
        rows.append(row)
    return rows


def workspace_change(arr, n=6, heights=(0.012, 0.03, 0.05, 0.08)):
    """Range of |B| and dBz/dz change (coupled / uncoupled - 1) over a workspace grid for
    every coil's column, where the column is not negligible (>= 5 % of its max on the plane)."""
    xs = np.linspace(-0.075, 0.075, n)
    X, Y = np.meshgrid(xs, xs)
    out = {}
    bch, gch = [], []
    for h in heights:
        pts = np.c_[X.ravel(), Y.ravel(), np.full(X.size, h)]
        a = arr.actuation_matrix(pts)
        au = arr.uncoupled_actuation_matrix(pts)
        b, bu = np.linalg.norm(a[:, :3], axis=1), np.linalg.norm(au[:, :3], axis=1)
        g, gu = _gzz(a), _gzz(au)
        keep_b = bu > 0.05 * bu.max(axis=0)
        keep_g = np.abs(gu) > 0.05 * np.abs(gu).max(axis=0)
        bch.append(np.abs(b / bu - 1)[keep_b])
        gch.append(np.abs(g / gu - 1)[keep_g])
    bch, gch = np.concatenate(bch), np.concatenate(gch)
    out["b_change_percentiles_5_50_95"] = np.percentile(bch, [5, 50, 95]).tolist()
    out["dbz_dz_change_percentiles_5_50_95"] = np.percentile(gch, [5, 50, 95]).tolist()
    return out


def f0_slice(arr, moment, nx, nz):
    """F0 (n_z, n_x, 3) N on the slice y = 0, x in +-75 mm, z in 10..80 mm."""
    xs = np.linspace(-0.075, 0.075, nx)
    zs = np.linspace(0.010, 0.080, nz)
    X, Z = np.meshgrid(xs, zs)
    pts = np.c_[X.ravel(), np.zeros(X.size), Z.ravel()]
    f = arr.bias_force(pts, moment).reshape(nz, nx, 3)
    return xs, zs, f


def plot_f0(xs, zs, f, threshold_n, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mag = np.linalg.norm(f, axis=-1) * 1e3
    fig, ax = plt.subplots(figsize=(8, 5.2))
    ext = [xs[0] * 1e3, xs[-1] * 1e3, zs[0] * 1e3, zs[-1] * 1e3]
    levels = np.arange(-1.0, 4.5, 0.5)
    cs = ax.contourf(xs * 1e3, zs * 1e3, np.log10(np.maximum(mag, 1e-3)), levels=levels,
                     cmap="viridis", extend="both")
    ct = ax.contour(xs * 1e3, zs * 1e3, mag, levels=[threshold_n * 1e3], colors="w",
                    linewidths=1.5)
    ax.clabel(ct, fmt={threshold_n * 1e3: f"{threshold_n * 1e3:g} mN threshold"}, fontsize=8)
    step = max(1, len(xs) // 12)
    u, w = f[::step, ::step, 0], f[::step, ::step, 2]
    nrm = np.hypot(u, w)
    nrm[nrm == 0] = 1.0
    Xq, Zq = np.meshgrid(xs[::step] * 1e3, zs[::step] * 1e3)
    ax.quiver(Xq, Zq, u / nrm, w / nrm, color="w", alpha=0.7, scale=30, width=0.003)
    for xc in (-50, 0, 50):
        ax.axvspan(xc - 12, xc + 12, ymin=0, ymax=0.02, color="0.3")
    ax.text(-25, zs[0] * 1e3 + 1.0, "grey: cores\n(tops at z = 5 mm)", ha="center",
            fontsize=7, color="w")
    cb = fig.colorbar(cs, ax=ax, pad=0.02)
    cb.set_label("|F0| (mN), log10 scale")
    cb.set_ticks(levels[::2])
    cb.set_ticklabels([f"{10 ** t:g}" for t in levels[::2]])
    ax.set_xlabel("x (mm), slice y = 0 through a row of coils")
    ax.set_ylabel("magnet centre height above coil tops z (mm)")
    ax.set_title("Magnet's pull on the iron with every coil off, F0(p)\n"
                 "(arrows: direction in the x-z plane; moment +z, |m| of the design)",
                 fontsize=10)
    ax.set_xlim(ext[0], ext[1])
    ax.set_ylim(ext[2], ext[3])
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def sensor_subtraction(arr, moment, magnet_points):
    """Upper-minus-lower at the sensors with the magnet at each point (no current).

    The thesis subtracts the lower array's reading from the upper's to cancel the coils'
    fields; the core field the magnet induces (upper and lower differ) is left as an error.
    Returns per magnet point: the magnet's own field difference (the signal), the induced
    field difference (the error), at the sensor with the largest error.
    """
    s = arr.sensor_positions_m().reshape(-1, 3)
    n = arr.n_coils
    rows = []
    for p in magnet_points:
        ind = arr.magnet_core_field(s, p, moment).reshape(2, n, 3)
        own = dipole_field(s - p, moment).reshape(2, n, 3)
        err = ind[0] - ind[1]
        sig = own[0] - own[1]
        k = int(np.argmax(np.linalg.norm(err, axis=1)))
        rows.append({"magnet_mm": (np.asarray(p) * 1e3).tolist(), "sensor": k,
                     "signal_t": float(np.linalg.norm(sig[k])),
                     "induced_upper_t": float(np.linalg.norm(ind[0, k])),
                     "induced_lower_t": float(np.linalg.norm(ind[1, k])),
                     "subtraction_error_t": float(np.linalg.norm(err[k])),
                     "error_over_signal": float(np.linalg.norm(err[k])
                                                / max(np.linalg.norm(sig[k]), 1e-30))})
    return rows


def saturation(design, fem_run=False, currents=(1.0, 2.0, 3.0, 4.0, 5.0, 6.0), level=1):
    """designkit's per-coil factor vs the nonlinear axisymmetric GetDP FEM (ratio of dBz/dz at
    the design point, nonlinear at I over I x linear mu_r at 1 A)."""
    coil = Coil.from_design(design)
    tab = saturation_table(coil, design.optimize.height_m, np.r_[0.0, currents])
    out = {"current_a": tab["current_a"].tolist(), "factor_designkit": tab["factor"].tolist()}
    if not fem_run:
        out["fem"] = FEM_NOT_RUN
        return out


    z = coil.length / 2 + design.optimize.height_m
    lin = solve(dataclasses.replace(coil, core=dataclasses.replace(coil.core, bh="linear")),
                1.0, level=level).axis.fit([z])["dbz_dz"][0]
    fem = [1.0]
    for i in currents:
        r = solve(coil, float(i), bh="steel1010", level=level)
        fem.append(float(r.axis.fit([z])["dbz_dz"][0] / (i * lin)))
    out["factor_fem"] = fem
    out["designkit_minus_fem"] = (np.array(out["factor_designkit"]) - np.array(fem)).tolist()
    out["max_abs_error"] = float(np.max(np.abs(out["designkit_minus_fem"])))
    return out


def cross_terms(arr, moment):
    """Axial flux density inside the centre core (on its axis, at its mid-plane and 5 mm below
    its top face) from its own coil at 6 A, from a side neighbour at 6 A, and from the magnet
    (12 and 30 mm above the centre): the fields a per-coil saturation factor does not see.
    On the axis Bz of the cores is that of their m = 0 currents, exact inside the iron too."""
    s = arr.coupled()
    kc = arr.n_coils // 2
    kn = kc + 1 if kc + 1 < arr.n_coils else kc - 1
    c = arr.coils[kc]
    z_top = c.pose.position[2] + c.core.offset + c.core.length / 2
    x0, y0 = c.pose.position[0], c.pose.position[1]
    pts = np.array([[x0, y0, c.pose.position[2] + c.core.offset], [x0, y0, z_top - 5e-3]])
    b = s.core_field(pts, s.coil_solution())[:, 2]
    bw = np.stack([cc.field(pts, 1.0, include="winding")[:, 2] for cc in arr.coils], -1)
    tot = b + bw
    out = {"points_mm": (pts * 1e3).tolist(),
           "own_coil_6a_bz_t": (6 * tot[:, kc]).tolist(),
           "neighbour_coil_6a_bz_t": (6 * tot[:, kn]).tolist()}
    for h in (0.012, 0.03):
        out[f"magnet_{int(round(h * 1e3))}mm_bz_t"] = arr.magnet_core_field(
            pts, [x0, y0, h], moment)[:, 2].tolist()
    return out


def _costs(arr, moment, quick: bool):
    """(costs, the coupled system): seconds to build the coupled system and its coil columns,
    microseconds per point of the coupled and uncoupled actuation matrix and of the bias force
    (random workspace points)."""
    t0 = time.perf_counter()
    system = arr.coupled()
    t_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    system.coil_solution()
    t_coils = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    npts = 200 if quick else 2000
    pts = np.c_[rng.uniform(-0.075, 0.075, (npts, 2)), rng.uniform(0.01, 0.08, npts)]
    t0 = time.perf_counter()
    arr.actuation_matrix(pts)
    t_c = time.perf_counter() - t0
    t0 = time.perf_counter()
    arr.uncoupled_actuation_matrix(pts)
    t_u = time.perf_counter() - t0
    nb = 50 if quick else 500
    t0 = time.perf_counter()
    arr.bias_force(pts[:nb], moment)
    t_f0 = time.perf_counter() - t0
    return {"n_unknowns": system.n_unknowns, "cross_blocks": system.n_blocks,
            "build_s": t_build, "coil_columns_s": t_coils,
            "actuation_per_point_coupled_us": t_c / npts * 1e6,
            "actuation_per_point_uncoupled_us": t_u / npts * 1e6,
            "coupled_over_uncoupled": t_c / t_u,
            "bias_force_per_point_us": t_f0 / nb * 1e6}, system


def _convergence(arr, system, quick: bool) -> dict:
    """dBz/dz at the design point and Bz above a neighbour (centre coil at 1 A) for a few
    (m_max, refine) of the core model: how converged the modes and panels are."""
    p = np.array([[0.0, 0.0, 0.03], [0.05, 0.0, 0.03]])
    conv = {}
    variants = [(M_MAX, 1)] if quick else [(1, 1), (2, 1), (M_MAX, 1), (M_MAX + 1, 1),
                                          (M_MAX, 2)]
    for m_max, refine in variants:
        s = system if (m_max, refine) == (M_MAX, 1) else ArraySystem(arr, m_max=m_max,
                                                                     refine=refine)
        b, g = s.core_field(p, s.coil_solution(), gradient=True)
        bw = np.stack([c.field(p, 1.0, include="winding") for c in arr.coils], -1)
        gw = np.stack([c.field(p, 1.0, gradient=True, include="winding")[1] for c in arr.coils],
                      -1)
        kc = arr.n_coils // 2
        conv[f"m_max={m_max},refine={refine}"] = {
            "dbz_dz_design_point_t_per_m": float(g[0, 2, 2, kc] + gw[0, 2, 2, kc]),
            "bz_above_neighbour_t": float(b[1, 2, kc] + bw[1, 2, kc])}
    return conv


def run(out_dir=DEFAULT_OUT, quick: bool = False, fem: bool = False,
        saturation_fem: bool = False, design=None) -> dict:
    """The study (module docs); ``design`` defaults to the default 3x3 design (the FEM table
    models the default array, so ``fem`` needs it)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    design = default_design() if design is None else design
    moment = np.array([0.0, 0.0, design.magnet.moment_a_m2])
    res: dict = {"machine_note": "timings on the machine that ran this (state if loaded)"}
    steps = ["solve", "table", "workspace", "f0", "sensors", "saturation", "convergence"]
    bar = tqdm(steps, desc="array_coupling", mininterval=1.0)

    bar.set_postfix_str("solve")
    arr = CoilArray.from_design(design)
    res["cost"], system = _costs(arr, moment, quick)
    bar.update()

    bar.set_postfix_str("table")
    tp = _table_points(quick)
    fem_res = None
    if fem:
        t0 = time.perf_counter()
        bf, gf, _ = fem3d.array_case(tp, energized="centre", level=-2 if quick else 0)
        fem_res = (bf, gf)
        res["fem_level"] = -2 if quick else 0
        res["fem_seconds"] = time.perf_counter() - t0
    res["table_centre_coil"] = coupling_table(arr, tp, fem_res, coil=arr.n_coils // 2)
    bar.update()

    bar.set_postfix_str("workspace")
    res["workspace_change"] = workspace_change(arr, n=4 if quick else 7,
                                               heights=(0.012, 0.05) if quick else
                                               (0.012, 0.03, 0.05, 0.08))
    bar.update()

    bar.set_postfix_str("F0 slice")
    xs, zs, f = f0_slice(arr, moment, 9 if quick else 31, 6 if quick else 29)
    png = out / "array_coupling_f0.png"
    plot_f0(xs, zs, f, design.render.threshold_n, png)
    i30 = int(np.argmin(np.abs(zs - 0.03)))
    res["f0"] = {"png": str(png), "x_mm": (xs * 1e3).tolist(), "z_mm": (zs * 1e3).tolist(),
                 "fz_centre_column_n": f[:, len(xs) // 2, 2].tolist(),
                 "fz_at_30mm_centre_n": float(arr.bias_force(
                     [0, 0, 0.03], moment, magnet_size_m=(design.magnet.radius_m,
                                                          design.magnet.length_m))[2]),
                 "fz_at_30mm_centre_dipole_n": float(arr.bias_force([0, 0, 0.03], moment)[2]),
                 "max_abs_f0_at_30mm_n": float(np.abs(f[i30]).max()),
                 "threshold_n": design.render.threshold_n}
    bar.update()

    bar.set_postfix_str("sensors")
    mp = [(0.0, 0.0, 0.03), (0.025, 0.0, 0.03), (0.05, 0.0, 0.03), (0.0, 0.0, 0.025),
          (0.025, 0.025, 0.05), (0.0, 0.0, 0.08)]
    rows = sensor_subtraction(arr, moment, mp[:3] if quick else mp)
    res["sensor_subtraction"] = rows
    res["sensor_centre_magnet_30mm"] = {
        "induced_upper_t": float(np.linalg.norm(arr.magnet_core_field(
            arr.sensor_positions_m()[0, arr.n_coils // 2], [0, 0, 0.03], moment))),
        "induced_lower_t": float(np.linalg.norm(arr.magnet_core_field(
            arr.sensor_positions_m()[1, arr.n_coils // 2], [0, 0, 0.03], moment)))}
    bar.update()

    bar.set_postfix_str("saturation")
    if quick:  # the nonlinear solves are the slow part; the smoke test skips them
        res["saturation"] = {"skipped": "quick mode", "fem": FEM_NOT_RUN}
    else:
        res["saturation"] = saturation(design, saturation_fem)
    res["saturation_cross_terms"] = cross_terms(arr, moment)
    bar.update()

    bar.set_postfix_str("convergence")
    res["convergence"] = _convergence(arr, system, quick)
    bar.update()
    bar.close()
    write_json_atomic(out / "array_coupling.json", res)
    return res


def _print(res):
    c = res["cost"]
    print(f"solve: {c['n_unknowns']} unknowns, {c['cross_blocks']} cross blocks, build "
          f"{c['build_s']:.1f} s + coil columns {c['coil_columns_s']:.1f} s; A per point "
          f"{c['actuation_per_point_coupled_us']:.0f} us coupled vs "
          f"{c['actuation_per_point_uncoupled_us']:.0f} us uncoupled "
          f"(x{c['coupled_over_uncoupled']:.1f}); F0 {c['bias_force_per_point_us']:.0f} us/pt")
    print("\ncentre coil energized, 1 A:  x,y,z (mm) | Bz unc / cpl (mT) | |B| change | "
          "dBz/dz unc / cpl (T/m) | change | fem")
    for r in res["table_centre_coil"]:
        fem = r.get("fem", f"|dB|/|B| cpl {r.get('b_coupled_vs_fem', 0):.1%} "
                           f"unc {r.get('b_uncoupled_vs_fem', 0):.1%}, |dG|/|G| cpl "
                           f"{r.get('grad_b_coupled_vs_fem', 0):.1%}, dBz/dz cpl "
                           f"{r.get('dbz_dz_coupled_vs_fem', 0):+.1%}")
        print(f"{r['x_mm']:5.0f}{r['y_mm']:5.0f}{r['z_mm']:5.0f} | {r['bz_uncoupled_t'] * 1e3:7.3f}"
              f" {r['bz_coupled_t'] * 1e3:7.3f} | {r['b_change']:+7.1%} | "
              f"{r['dbz_dz_uncoupled_t_per_m']:8.4f} {r['dbz_dz_coupled_t_per_m']:8.4f} | "
              f"{r['dbz_dz_change']:+7.1%} | {fem}")
    w = res["workspace_change"]
    print("\nworkspace, all columns: |B| change 5/50/95 %:",
          [f"{v:.1%}" for v in w["b_change_percentiles_5_50_95"]], " dBz/dz change:",
          [f"{v:.1%}" for v in w["dbz_dz_change_percentiles_5_50_95"]])
    f = res["f0"]
    dip = f["fz_at_30mm_centre_dipole_n"]
    print(f"\nF0 at 30 mm above the centre coil: {f['fz_at_30mm_centre_n'] * 1e3:.1f} mN "
          f"(the 10 x 10 mm cylinder; point dipole {dip * 1e3:.1f} mN) "
          f"(threshold {f['threshold_n'] * 1e3} mN); PNG {f['png']}")
    s = res["sensor_centre_magnet_30mm"]
    print(f"induced core field at the centre sensors, magnet 30 mm above the centre: upper "
          f"{s['induced_upper_t'] * 1e3:.2f} mT, lower {s['induced_lower_t'] * 1e3:.2f} mT")
    print("upper-minus-lower subtraction: magnet (mm) | sensor | signal (mT) | error (mT) | "
          "error/signal")
    for r in res["sensor_subtraction"]:
        print(f"{r['magnet_mm']} | {r['sensor']} | {r['signal_t'] * 1e3:.3f} | "
              f"{r['subtraction_error_t'] * 1e3:.3f} | {r['error_over_signal']:.1f}")
    s = res["saturation"]
    if "skipped" in s:
        s = {"current_a": [], "factor_designkit": [], "fem": "skipped (quick)"}
    print("\nsaturation factor s(|I|):", ", ".join(
        f"{i:g} A: {f:.4f}" for i, f in zip(s["current_a"], s["factor_designkit"])))
    if "factor_fem" in s:
        print("               FEM:", ", ".join(f"{i:g} A: {f:.4f}" for i, f in
                                               zip(s["current_a"], s["factor_fem"])),
              f"(max |designkit - FEM| {s['max_abs_error']:.4f})")
    else:
        print("               ", s["fem"])
    print("cross terms at the centre core top:", res["saturation_cross_terms"])
    print("\nconvergence:", res["convergence"])


def main(argv=None) -> int:

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", nargs="?", default=str(DEFAULT_OUT),
                    help="output folder (default out/array_coupling)")
    ap.add_argument("--quick", action="store_true", help="coarse grids (the smoke test's run)")
    ap.add_argument("--fem", action="store_true", help="the 3-D GetDP reference too")
    ap.add_argument("--saturation-fem", action="store_true",
                    help="the nonlinear GetDP reference of the saturation factor too")
    a = ap.parse_args(argv)
    _print(run(a.out, quick=a.quick, fem=a.fem, saturation_fem=a.saturation_fem))
    return 0


if __name__ == "__main__":
    sys.exit(main())
