"""Can designkit's iron-core model be trusted? Core models vs GetDP FEM on the thesis coil.

Question: how far from a converged axisymmetric FEM solution (GetDP, second-order elements,
shell transformation to infinity) are designkit's core models -- the default surface-current
model (linear and with the 1010 steel B-H curve) and the thesis' uniform-magnetization model --
in Bz and dBz/dz above the coil, in inductance, and in the force on the finger magnet at the
design point; what time constant does the thesis coil have with its core; and what do the
models cost?

Table sections: air core (FEM vs quadrature); mesh refinement (the FEM digits are converged);
linear cores mu_r 200/1000/5000 at 6 A (max error on the axis 14-100 mm above the winding and on
r = 10 mm); nonlinear core 1-6 A at the design point; inductance, tau and 5 tau against
``SETTLING_S``; force at 6 A vs the thesis' 780 mN; all around the coil (above, below, beside,
in the bore beyond the core's ends, at the neighbours' positions) for three core geometries and
mu_r 200/1000/5000/1010 steel, with the FEM's mesh convergence at those points; costs.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from pathlib import Path

import numpy as np

import designkit.cores.panel as core_mod
from designkit.support.atomic import write_json_atomic
from designkit.support.progress import tqdm
from designkit.model.coil import Coil
from designkit.cores import Core, SaturationWarning
from designkit.design import OptimizeSpec, default_design
from designkit.model.electrical import resistance
from designkit.fem import solve
from designkit.fem.compare import (air_inductance, model_field, plot_comparison, probe_errors,
                                   probe_set)
from designkit.field.winding import winding_rz

THESIS_FORCE_N = 0.780
SETTLING_S = OptimizeSpec().max_settling_time_s
"""The bound on 5 L/R of the coil-design problem, s."""


def _coil(core=None):
    d = default_design()
    c = d.coil
    return Coil(c.inner_radius_m, c.outer_radius_m, c.length_m, c.turns, core)


def _max_errors(coil, res, heights, model):
    z = coil.length / 2 + heights
    out = {}
    for name, line in (("axis", res.axis), ("off_axis", res.off_axis)):
        fit = line.fit(z)
        bz, dbz = model_field(coil, res.current, line.r, z, model)
        out[name] = (float(np.max(np.abs(bz / fit["bz"] - 1))),
                     float(np.max(np.abs(dbz / fit["dbz_dz"] - 1))))
    return out


def _timings(repeats: int = 20) -> dict:
    coil = _coil(Core(0.012, 0.110, 1000.0))
    # solve per design: new designs (cache cleared each time)
    ts = []
    for i in range(5):
        core_mod._solve_linear.cache_clear()
        t = time.perf_counter()
        coil.core.solution(coil, 1.0)
        ts.append(time.perf_counter() - t)
    solve_ms = 1e3 * float(np.median(ts))
    ti = []
    for i in range(5):
        core_mod._solve_linear.cache_clear()
        t = time.perf_counter()
        coil.core.extra_inductance(coil)
        ti.append(time.perf_counter() - t)
    induct_ms = 1e3 * float(np.median(ti))
    rng = np.random.default_rng(1)
    n = 1000
    pts = np.column_stack([rng.uniform(-0.04, 0.04, n), rng.uniform(-0.04, 0.04, n),
                           rng.uniform(0.06, 0.13, n)])
    sol = coil.core.solution(coil, 1.0)
    rho = np.hypot(pts[:, 0], pts[:, 1])

    def best(fn):
        fn()
        t = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            t.append(time.perf_counter() - t0)
        return float(np.min(t))

    t_core = best(lambda: sol.field(pts, gradient=True))
    t_wind = best(lambda: winding_rz(0.012, 0.019, 0.05, rho, pts[:, 2], gradient=True))
    return {"core_solve_ms": solve_ms, "core_solve_plus_inductance_ms": induct_ms,
            "core_field_1000pts_ms": 1e3 * t_core, "winding_field_1000pts_ms": 1e3 * t_wind,
            "core_over_winding": t_core / t_wind}


CORE_GEOMETRIES = {
    "thesis 24x110": dict(radius=0.012, length=0.110),
    "short-thin 16x70": dict(radius=0.008, length=0.070),
    "offset 20x90 +15": dict(radius=0.010, length=0.090, offset=0.015),
}
MATERIALS = (200.0, 1000.0, 5000.0, "steel1010")
CLASSES = ("above", "below", "beside", "bore", "between")


def _around_one(geometry, material, level):
    kw = CORE_GEOMETRIES[geometry]
    core = Core(**kw, bh="steel1010") if material == "steel1010" else \
        Core(**kw, relative_permeability=float(material))
    coil = _coil(core)
    pts, labels = probe_set(coil)
    res = solve(coil, 6.0, level=level, probes=pts)
    e = probe_errors(coil, res)
    labels = np.array(labels)
    row = {"getdp_s": res.solve_seconds, "n_points": len(labels)}
    for c in CLASSES:
        sel = labels == c
        if sel.any():
            row[c] = (float(e["b_err"][sel].max()), float(e["dbz_err"][sel].max()))
    row["worst_b"] = float(e["b_err"].max())
    row["worst_dbz"] = float(e["dbz_err"].max())
    return row, e, labels


def _around(level, quick):
    cases = [(g, m) for g in CORE_GEOMETRIES for m in MATERIALS]
    if quick:
        cases = [("thesis 24x110", 1000.0), ("short-thin 16x70", 1000.0)]
    out = {}
    for g, m in tqdm(cases, desc="core vs FEM all around", mininterval=2):
        out[f"{g} | {m}"] = _around_one(g, m, level)[0]
    return out


def _around_convergence():
    """FEM mesh convergence at the probes: thesis core, mu_r 1000, levels 0..2."""
    vals = {}
    for lv in (0, 1, 2):
        _, e, _ = _around_one("thesis 24x110", 1000.0, lv)
        vals[lv] = e
    ref = vals[2]["fem"]
    conv = {}
    for lv in (0, 1):
        f = vals[lv]["fem"]
        db = np.hypot(f["br"] - ref["br"], f["bz"] - ref["bz"]) / np.hypot(ref["br"], ref["bz"])
        dg = np.abs(f["dbz_dz"] - ref["dbz_dz"]) / np.maximum(np.abs(ref["dbz_dz"]),
                                                              0.5 * vals[2]["g_norm_fem"])
        conv[lv] = (float(db.max()), float(dg.max()))
    conv["model_vs_level2"] = (float(vals[2]["b_err"].max()), float(vals[2]["dbz_err"].max()))
    return conv


def _linear_cores(level, quick, l_air, heights, h_design, m_z, out) -> dict:
    """Linear cores (mu_r 200 / 1000 / 5000) at 6 A: each model's worst error against the FEM,
    the inductances and the force at the design height; the mu_r 1000 comparison figure."""
    lin = {}
    for mu in ((1000.0,) if quick else (200.0, 1000.0, 5000.0)):
        coil = _coil(Core(0.012, 0.110, mu))
        r = solve(coil, 6.0, level=level)
        entry = {m: _max_errors(coil, r, heights, m) for m in ("surface-current",
                                                               "thesis-uniform")}
        l_model = l_air + coil.core.extra_inductance(coil)
        l_uniform = l_air + dataclasses.replace(coil.core, model="thesis-uniform") \
            .extra_inductance(coil)
        entry["l_fem_h"] = r.inductance_energy
        entry["l_model_h"] = l_model
        entry["l_uniform_h"] = l_uniform
        f = r.axis.fit(np.array([coil.length / 2 + h_design]))
        entry["fz_fem_n"] = float(m_z * f["dbz_dz"][0])
        lin[mu] = entry
        if mu == 1000.0:
            plot_comparison(coil, r, out / "linear_mu1000_6A.png",
                            "thesis coil + 24 x 110 mm core, mu_r 1000, 6 A")
    return lin


def _nonlinear_core(coil_nl, level, quick, l_air, zd, out) -> list:
    """The 1010 steel core at 1..6 A: dBz/dz at the design point (FEM, model, linear mu_r 1000),
    peak B, the inductances; the 6 A comparison figure."""
    nl = []
    for current in ((6.0,) if quick else (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)):
        r = solve(coil_nl, current, level=level)
        f = r.axis.fit(zd)
        _, d_model = model_field(coil_nl, current, 0.0, zd, "surface-current")
        lin_coil = _coil(Core(0.012, 0.110, 1000.0))
        _, d_lin = model_field(lin_coil, current, 0.0, zd, "surface-current")
        nl.append({"current_a": current, "dbz_fem": float(f["dbz_dz"][0]),
                   "dbz_model": float(d_model[0]), "dbz_linear1000": float(d_lin[0]),
                   "peak_b_t": coil_nl.core.peak_flux_density(coil_nl, current),
                   "l_fem_h": r.inductance_linkage,
                   "l_model_h": l_air + coil_nl.core.extra_inductance(coil_nl, current),
                   "getdp_s": r.solve_seconds})
        if current == 6.0:
            plot_comparison(coil_nl, r, out / "steel1010_6A.png",
                            "thesis coil + 1010 steel core (B-H curve), 6 A")
    return nl


def run(out_dir, quick: bool = False) -> dict:
    """The study (module docs) at FEM level 1 (0 with ``quick``); writes core_vs_fem.json and
    the two comparison figures under ``out_dir``; returns the results dict."""
    warnings.simplefilter("ignore", SaturationWarning)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    design = default_design()
    m_z = design.magnet.moment_a_m2
    h_design = design.optimize.height_m
    level = 0 if quick else 1
    heights = np.linspace(0.014, 0.100, 44)
    results: dict = {"level": level}

    # ---- air core
    air = _coil()
    r_air = solve(air, 1.0, level=level)
    z30 = np.array([air.length / 2 + 0.030])
    fit = r_air.axis.fit(z30)
    bz, dbz = model_field(air, 1.0, 0.0, z30, None)
    l_air = air_inductance(air)
    results["air"] = {"bz_rel": float(fit["bz"][0] / bz[0] - 1),
                      "dbz_rel": float(fit["dbz_dz"][0] / dbz[0] - 1),
                      "l_quadrature_h": l_air, "l_fem_h": r_air.inductance_energy,
                      "l_rel": r_air.inductance_energy / l_air - 1,
                      "getdp_s": r_air.solve_seconds, "nodes": r_air.mesh_stats["nodes"]}

    # ---- mesh refinement (mu_r 1000, 6 A)
    core1000 = _coil(Core(0.012, 0.110, 1000.0))
    refine = []
    for lv in ((0,) if quick else (0, 1, 2, 3)):
        r = solve(core1000, 6.0, level=lv)
        f = r.axis.fit(z30)
        refine.append({"level": lv, "nodes": r.mesh_stats["nodes"], "bz": float(f["bz"][0]),
                       "dbz": float(f["dbz_dz"][0]), "l_h": r.inductance_energy,
                       "getdp_s": r.solve_seconds})
    results["refinement"] = refine

    results["linear"] = _linear_cores(level, quick, l_air, heights, h_design, m_z, out)

    coil_nl = _coil(Core(0.012, 0.110, bh="steel1010"))
    zd = np.array([coil_nl.length / 2 + h_design])
    nl = _nonlinear_core(coil_nl, level, quick, l_air, zd, out)
    results["nonlinear"] = nl

    # ---- inductance, time constant, force
    rr = resistance(air, design.wire)
    l_small = l_air + coil_nl.core.extra_inductance(coil_nl, 0.01)
    l_6 = nl[-1]["l_model_h"]
    results["electrical"] = {
        "resistance_ohm": rr, "l_air_h": l_air, "l_core_small_signal_h": l_small,
        "l_core_6a_secant_h": l_6, "tau_air_s": l_air / rr, "tau_core_s": l_small / rr,
        "five_tau_core_s": 5 * l_small / rr, "meets_100ms": bool(5 * l_small / rr < SETTLING_S)}
    _, d_air = model_field(air, 6.0, 0.0, zd, None)
    results["force"] = {
        "moment_a_m2": m_z, "height_m": h_design,
        "fz_air_n": float(m_z * d_air[0]),
        "fz_core_linear1000_n": float(m_z * nl[-1]["dbz_linear1000"]),
        "fz_core_steel1010_model_n": float(m_z * nl[-1]["dbz_model"]),
        "fz_core_steel1010_fem_n": float(m_z * nl[-1]["dbz_fem"]),
        "thesis_n": THESIS_FORCE_N}
    # ---- all around the coil: 3 core geometries x 4 materials
    results["around"] = _around(level, quick)
    if not quick:
        results["around_convergence"] = _around_convergence()
    results["cost"] = _timings(5 if quick else 20)
    results["cost"]["getdp_coarse_s"] = r_air.solve_seconds if level == 0 else refine[0]["getdp_s"]

    write_json_atomic(out / "core_vs_fem.json", results)
    return results


def print_table(res: dict) -> None:
    a = res["air"]
    print(f"== air core (level {res['level']}, {a['nodes']} nodes, GetDP {a['getdp_s']:.1f} s)")
    print(f"   30 mm above: Bz {a['bz_rel']:+.2e}  dBz/dz {a['dbz_rel']:+.2e} (limit 2e-4);"
          f"  L {a['l_fem_h'] * 1e3:.5f} mH vs quadrature {a['l_quadrature_h'] * 1e3:.5f} mH"
          f" ({a['l_rel']:+.1e}, limit 1e-4)")
    print("== mesh refinement, mu_r 1000, 6 A, axis 30 mm above")
    last = res["refinement"][-1]
    for r in res["refinement"]:
        print(f"   level {r['level']}: {r['nodes']:7d} nodes  Bz {r['bz'] * 1e3:.5f} mT"
              f" ({r['bz'] / last['bz'] - 1:+.1e})  dBz/dz {r['dbz']:.5f} T/m"
              f" ({r['dbz'] / last['dbz'] - 1:+.1e})  L {r['l_h'] * 1e3:.4f} mH"
              f" ({r['l_h'] / last['l_h'] - 1:+.1e})  GetDP {r['getdp_s']:.1f} s")
    print("== linear core 24 x 110 mm, 6 A: max |rel err| vs FEM, 14-100 mm above the winding")
    print("   mu_r   line      default Bz  dBz/dz  | thesis-uniform Bz  dBz/dz |"
          "  L_FEM mH  default  uniform")
    for mu, e in res["linear"].items():
        for line in ("axis", "off_axis"):
            d = e["surface-current"][line]
            u = e["thesis-uniform"][line]
            lt = (f"  {e['l_fem_h'] * 1e3:8.2f} {100 * (e['l_model_h'] / e['l_fem_h'] - 1):+6.2f}%"
                  f" {100 * (e['l_uniform_h'] / e['l_fem_h'] - 1):+6.1f}%") if line == "axis" \
                else ""
            print(f"   {mu:5.0f}  {line:8s}  {100 * d[0]:6.2f}% {100 * d[1]:6.2f}%  |"
                  f"  {100 * u[0]:6.1f}%  {100 * u[1]:6.1f}%  |{lt}")
    print("== 1010 steel core (B-H curve), design point 30 mm above the coil top")
    print("   I A   peak B T   dBz/dz FEM   default err   linear-1000 err   L FEM mH  model err")
    for e in res["nonlinear"]:
        print(f"   {e['current_a']:.0f}     {e['peak_b_t']:.2f}     {e['dbz_fem']:8.4f}"
              f"     {100 * (e['dbz_model'] / e['dbz_fem'] - 1):+6.2f}%"
              f"        {100 * (e['dbz_linear1000'] / e['dbz_fem'] - 1):+6.2f}%"
              f"        {e['l_fem_h'] * 1e3:7.2f}  {100 * (e['l_model_h'] / e['l_fem_h'] - 1):+6.2f}%")
    el = res["electrical"]
    print(f"== R = {el['resistance_ohm']:.3f} ohm; L air {el['l_air_h'] * 1e3:.2f} mH,"
          f" with core {el['l_core_small_signal_h'] * 1e3:.1f} mH (small signal),"
          f" {el['l_core_6a_secant_h'] * 1e3:.1f} mH (secant at 6 A)")
    print(f"   tau air {el['tau_air_s'] * 1e3:.2f} ms; tau with core {el['tau_core_s'] * 1e3:.1f} ms;"
          f" 5 tau = {el['five_tau_core_s'] * 1e3:.0f} ms -> "
          f"{'meets' if el['meets_100ms'] else 'FAILS'} 5 tau < {SETTLING_S * 1e3:.0f} ms")
    f = res["force"]
    print(f"== Fz on m = {f['moment_a_m2']:.3f} A m^2 at {f['height_m'] * 1e3:.0f} mm, 6 A:"
          f" air {1e3 * abs(f['fz_air_n']):.0f} mN; core mu_r 1000 (linear)"
          f" {1e3 * abs(f['fz_core_linear1000_n']):.0f} mN; 1010 steel model"
          f" {1e3 * abs(f['fz_core_steel1010_model_n']):.0f} mN, FEM"
          f" {1e3 * abs(f['fz_core_steel1010_fem_n']):.0f} mN; thesis {1e3 * f['thesis_n']:.0f} mN")
    print("== all around the coil, 6 A: max error per point class, B | dBz/dz (%)")
    print("   B: |dB|/|B| (vector); dBz/dz: |d dBz/dz| / max(|dBz/dz|, ||grad B||_F / 2) (FEM)")
    print("   core / material                " + "".join(f"{c:>15s}" for c in CLASSES)
          + "   GetDP s")
    for key, row in res["around"].items():
        cells = "".join(f"{100 * row[c][0]:6.2f} |{100 * row[c][1]:5.2f} " if c in row
                        else f"{'-':>15s}" for c in CLASSES)
        print(f"   {key:31s}{cells}  {row['getdp_s']:6.1f}")
    if "around_convergence" in res:
        cv = res["around_convergence"]
        print("   FEM mesh convergence (thesis core, mu_r 1000) vs level 2, max over the probes:"
              f" level 0 B {100 * cv[0][0]:.2f} % dBz/dz {100 * cv[0][1]:.2f} %;"
              f" level 1 B {100 * cv[1][0]:.2f} % dBz/dz {100 * cv[1][1]:.2f} %;"
              f" model vs level 2: B {100 * cv['model_vs_level2'][0]:.2f} %,"
              f" dBz/dz {100 * cv['model_vs_level2'][1]:.2f} %")
    c = res["cost"]
    print(f"== cost: core solve {c['core_solve_ms']:.1f} ms/design (limit 50),"
          f" + inductance {c['core_solve_plus_inductance_ms']:.1f} ms;"
          f" core field {c['core_field_1000pts_ms']:.2f} ms vs winding"
          f" {c['winding_field_1000pts_ms']:.2f} ms per 1000 points with gradient"
          f" (x{c['core_over_winding']:.2f}, limit 2); coarse GetDP {c['getdp_coarse_s']:.1f} s"
          " (limit 15)")


if __name__ == "__main__":  # pragma: no cover
    from studies._common import study_parser

    a = study_parser(__doc__, Path(__file__).resolve().parents[1] / "out" / "core_vs_fem",
                     quick="FEM level 0, mu_r 1000 and 6 A only").parse_args()
    res = run(a.out, quick=a.quick)
    print_table(res)
