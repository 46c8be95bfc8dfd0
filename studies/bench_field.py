"""Question: how much run time per point does each way of computing the thesis winding's field
cost, at what accuracy -- and is designkit's quadrature faster than magpylib's constructions?

Winding: Ri = 12 mm, Ro = 19 mm, L = 100 mm, 1429 turns, 1 A (the thesis coil). Points: the
haptic workspace above the coil (rho <= 40 mm, 3..80 mm above the top face), local frame.
Error = max over points of |B - B_ref| / |B_ref| (and |G - G_ref| / |G_ref| for gradients), B_ref
the uniform-current-density model from designkit at rtol = 1e-13 (checked against mpmath).

Methods timed in the same process: designkit winding_field (B, and B + gradient) for rtol
1e-4 .. 1e-12; designkit's 1429 filament loops (a different physical model, ~1.7e-4 from the
uniform density); the on-axis closed form at on-axis points; magpylib's 1429 Circle loops and
its nested-shell construction (K CylinderSegment shells with M_z = J (Ro - r_mid) plus a bore
Cylinder) for several K, B only. Second part: randomized windings (Ri/Ro 1e-4..0.99, L/Ro
1e-3..1e3) and points in every region: designkit B+G time per point and error against the
30-digit mpmath table tests/data/winding_refs.json, per region and rtol.

Outputs (OUT_DIR): bench_field.txt (the tables and speed-up ratios), bench_field.json,
bench_field.png (time per point against error). Targets and measured ratios: docs/field_winding.md.

    python studies/bench_field.py [OUT_DIR]   (default out/bench_field)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from designkit.support.atomic import write_json_atomic, write_text_atomic
from designkit.design import MU0
from designkit.field import cylindrical_to_cartesian, loop_field, reference as ref, winding_field
from designkit.field.winding import winding_rz
from studies import winding_accuracy as wa

RI, RO, L, N, I = 0.012, 0.019, 0.100, 1429, 1.0
J = N * I / ((RO - RI) * L)


def workspace_points(n, seed=0):
    rng = np.random.default_rng(seed)
    rho = 0.04 * np.sqrt(rng.uniform(0, 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    z = L / 2 + rng.uniform(0.003, 0.08, n)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)


def _time(fn, repeat):
    best = np.inf
    out = None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def _err(x, ref):
    x = x.reshape(len(ref), -1)
    ref = ref.reshape(len(ref), -1)
    return float(np.max(np.linalg.norm(x - ref, axis=1) / np.linalg.norm(ref, axis=1)))


def discrete_turns():
    """(radius, z) of the 1429 turns: 10 layers x 143 turns per layer, the last one left out."""
    layers, per_layer = 10, 143
    a = RI + (np.arange(layers) + 0.5) * (RO - RI) / layers
    zc = -L / 2 + (np.arange(per_layer) + 0.5) * L / per_layer
    A, Z = np.meshgrid(a, zc, indexing="ij")
    return A.ravel()[:N], Z.ravel()[:N]


def designkit_loop_sum(pts):
    a, zc = discrete_turns()
    b = np.zeros((len(pts), 3))
    for aa in np.unique(a):
        sel = a == aa
        # all turns of one layer at once: points x turns
        p = (pts[:, None, :] - np.stack([0 * zc[sel], 0 * zc[sel], zc[sel]], 1)[None]).reshape(-1, 3)
        b += loop_field(p, aa, I).reshape(len(pts), -1, 3).sum(axis=1)
    return b


def magpylib_circles(pts):
    import magpylib as magpy

    a, zc = discrete_turns()
    obs = np.repeat(pts[None], N, axis=0).reshape(-1, 3)
    pos = np.repeat(np.stack([0 * zc, 0 * zc, zc], 1), len(pts), axis=0)
    b = magpy.func.circle_field("B", obs, np.repeat(2 * a, len(pts)), np.full(len(obs), I),
                                positions=pos)
    return b.reshape(N, len(pts), 3).sum(axis=0) * (MU0 / magpy.mu_0)


def magpylib_shells(pts, k, ri=RI, ro=RO, length=L, j=J):
    """B (designkit's mu0) of the nested-shell construction with k shells."""
    import magpylib as magpy

    edges = np.linspace(ri, ro, k + 1)
    mid = 0.5 * (edges[1:] + edges[:-1])
    dims = np.stack([edges[:-1], edges[1:], np.full(k, length), np.zeros(k),
                     np.full(k, 360.0)], 1)
    pol = np.zeros((k, 3))
    pol[:, 2] = magpy.mu_0 * j * (ro - mid)
    obs = np.repeat(pts[None], k, axis=0).reshape(-1, 3)
    b = magpy.func.cylinder_segment_field("B", obs, np.repeat(dims, len(pts), axis=0),
                                          np.repeat(pol, len(pts), axis=0))
    b = b.reshape(k, len(pts), 3).sum(axis=0)
    b += magpy.func.cylinder_field("B", pts, (2 * ri, length), (0, 0, magpy.mu_0 * j * (ro - ri)))
    return b * (MU0 / magpy.mu_0)  # B / mu0 = H + M is independent of mu0


def _kernel_reference(pts):
    """B, G of the raw kernel at rtol = 1e-13 (below the public 1e-12 floor: a reference for
    the thesis workspace only, checked against mpmath on a few points in the full run)."""
    rho = np.hypot(pts[:, 0], pts[:, 1])
    c = np.where(rho > 0, pts[:, 0] / np.where(rho > 0, rho, 1), 1.0)
    s = np.where(rho > 0, pts[:, 1] / np.where(rho > 0, rho, 1), 0.0)
    res = winding_rz(RI, RO, L / 2, rho, pts[:, 2], gradient=True, rtol=1e-13)
    return cylindrical_to_cartesian(c, s, MU0 * J, res, True)


def axis_closed_form(z):
    def F(u):
        return u * np.log((RO + np.hypot(RO, u)) / (RI + np.hypot(RI, u)))
    return MU0 * J / 2 * (F(z + L / 2) - F(z - L / 2))


REGION_RTOLS = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)


def random_geometries(quick=False, have_magpylib=True, magpylib_random=False):
    """Run time per point and achieved error over randomized windings, per point region.

    Errors: the 30-digit mpmath table tests/data/winding_refs.json (12 windings incl. the
    domain's corners x 8 regions, studies/winding_accuracy.py) plus the issue-11 cases. Time:
    other windings from the same sampler with ``per`` points per (winding, region), one call
    each (so per-call overhead is amortized). magpylib: nested CylinderSegment shells (B only)
    on the same points."""
    data = Path(__file__).resolve().parents[1] / "tests" / "data"
    cases, refs = wa.load_or_compute(data, wa.TABLE_SEED, wa.TABLE_GEOMETRIES)
    per = 10 if quick else 100
    timing = ref.sample_cases(7, 4 if quick else 12, per_region=per)
    groups = {}
    for c in timing:
        groups.setdefault((c["region"], c["ri"], c["ro"], c["length"]), []).append(c["point"])
    out = {}
    for rtol in REGION_RTOLS:
        for (region, ri, ro, length), pts in groups.items():
            pts = np.array(pts)
            t = time.perf_counter()
            winding_field(pts, ri, ro, length, 1.0, 1.0, gradient=True, rtol=rtol)
            dt = time.perf_counter() - t
            o = out.setdefault((region, rtol), dict(time=0.0, n=0, err_b=0.0, err_g=0.0))
            o["time"] += dt
            o["n"] += len(pts)
        for case, (b_ref, g_ref) in zip(cases, refs):
            eb, eg = wa.errors(case, b_ref, g_ref, rtol)
            if case["corner_distance"] <= wa.CORNER_EXCLUSION * case["size"]:
                eg = 0.0
            o = out[(case["region"], rtol)]
            o["err_b"] = max(o["err_b"], eb)
            o["err_g"] = max(o["err_g"], eg)
    shells = {}
    # opt-in: magpylib 5.x's CylinderSegment (its cel iteration) did not return, within
    # minutes, for some points of the extreme windings (found with this bench); the thesis
    # section above keeps magpylib side by side in every run
    if have_magpylib and magpylib_random:
        # magpylib's CylinderSegment costs ~1 ms per shell and point on surfaces: time it on
        # 10 points per (winding, region)
        for k in ((16,) if quick else (16, 64)):
            for region in ref.REGIONS:
                tot, n, err = 0.0, 0, 0.0
                for (reg, ri, ro, length), pts in groups.items():
                    if reg != region:
                        continue
                    pts = np.array(pts)[:10]
                    t = time.perf_counter()
                    with np.errstate(all="ignore"):
                        magpylib_shells(pts, k, ri, ro, length, 1.0 / ((ro - ri) * length))
                    tot += time.perf_counter() - t
                    n += len(pts)
                for case, (b_ref, _g) in zip(cases, refs):
                    if case["region"] != region:
                        continue
                    j = 1.0 / ((case["ro"] - case["ri"]) * case["length"])
                    with np.errstate(all="ignore"):
                        b = magpylib_shells(case["point"][None], k, case["ri"], case["ro"],
                                            case["length"], j)[0]
                    e = float(np.linalg.norm(b - MU0 * j * b_ref) / np.linalg.norm(MU0 * j * b_ref))
                    # NaN: magpylib fails on some surface points
                    err = max(err, e) if np.isfinite(e) else np.inf
                shells[(region, k)] = dict(us_per_point=1e6 * tot / n, err_b=err)
    lines = ["Random windings (Ri/Ro 1e-4..0.99, L/Ro 1e-3..1e3): designkit B+G us/point "
             "[max err B / max err G vs mpmath]",
             f"{'region':8s} " + " ".join(f"{'rtol ' + format(r, '.0e'):>26s}"
                                          for r in REGION_RTOLS)]
    for region in ref.REGIONS:
        lines.append(f"{region:8s} " + " ".join(
            f"{1e6 * out[(region, r)]['time'] / out[(region, r)]['n']:8.1f} "
            f"[{out[(region, r)]['err_b']:7.1e}/{out[(region, r)]['err_g']:7.1e}]"
            for r in REGION_RTOLS))
    if shells:
        ks = sorted({k for _, k in shells})
        lines += ["", "magpylib nested shells (B only) us/point [max err B; inf: NaN returned], "
                  "same regions",
                  f"{'region':8s} " + " ".join(f"{str(k) + ' shells':>20s}" for k in ks)]
        for region in ref.REGIONS:
            lines.append(f"{region:8s} " + " ".join(
                f"{shells[(region, k)]['us_per_point']:8.1f} [{shells[(region, k)]['err_b']:7.1e}]"
                for k in ks))
    slow = sorted(ref.REGIONS, key=lambda r: -out[(r, 1e-10)]["time"] / out[(r, 1e-10)]["n"])
    lines += ["", "slowest regions at rtol 1e-10 (B+G): " + ", ".join(
        f"{r} {1e6 * out[(r, 1e-10)]['time'] / out[(r, 1e-10)]['n']:.0f} us" for r in slow[:3])]
    rows = [dict(region=r, rtol=t, us_per_point=1e6 * v["time"] / v["n"], err_b=v["err_b"],
                 err_g=v["err_g"]) for (r, t), v in out.items()]
    mrows = [dict(region=r, shells=k, **v) for (r, k), v in shells.items()]
    return rows, mrows, lines


def _reference_check(pts, b_ref, g_ref):
    """Largest relative error of the rtol = 1e-13 reference against mpmath on 4 points."""
    worst = 0.0
    for p in pts[:4]:
        r = ref.winding_textbook(RI, RO, L, float(np.hypot(p[0], p[1])), p[2], gradient=True)
        b, g = ref.rz_to_cartesian(p, r[0], r[1], r[2:])
        i = int(np.nonzero((pts == p).all(axis=1))[0][0])
        worst = max(worst, np.linalg.norm(b_ref[i] - MU0 * J * b) / np.linalg.norm(b_ref[i]),
                    np.linalg.norm(g_ref[i] - MU0 * J * g) / np.linalg.norm(g_ref[i]))
    return worst


def _have_magpylib():
    try:
        import magpylib  # noqa: F401
        return True
    except ImportError:  # pragma: no cover
        return False


def _time_methods(pts, n_mp, b_ref, g_ref, rtols, shells, repeat, have_magpylib):
    """One row per method (and rtol): run time per point and error against the reference."""
    n_dk = len(pts)
    pts_mp = pts[:n_mp]
    rows = []

    def add(method, rtol, t, npts, err_b, err_g=None):
        rows.append(dict(method=method, rtol=rtol, us_per_point=1e6 * t / npts, err_b=err_b,
                         err_g=err_g))

    for rtol in rtols:
        t, b = _time(lambda: winding_field(pts, RI, RO, L, N, I, rtol=rtol), repeat)
        add("designkit B", rtol, t, n_dk, _err(b, b_ref))
        t, (b, g) = _time(lambda: winding_field(pts, RI, RO, L, N, I, gradient=True, rtol=rtol),
                          repeat)
        add("designkit B+G", rtol, t, n_dk, _err(b, b_ref), _err(g, g_ref))
    t, b = _time(lambda: designkit_loop_sum(pts_mp), 1)
    add("designkit 1429 loops (discrete)", None, t, n_mp, _err(b, b_ref[:n_mp]))
    z_ax = np.linspace(L / 2 + 0.003, L / 2 + 0.08, n_dk)
    t, bz = _time(lambda: axis_closed_form(z_ax), repeat)
    bz_dk = _kernel_reference(np.stack([0 * z_ax, 0 * z_ax, z_ax], 1))[0]
    add("axis closed form (float64, on-axis points)", None, t, n_dk,
        float(np.max(np.abs(bz / bz_dk[:, 2] - 1))))
    if have_magpylib:
        t, b = _time(lambda: magpylib_circles(pts_mp), 1)
        add("magpylib 1429 Circle (discrete)", None, t, n_mp, _err(b, b_ref[:n_mp]))
        for k in shells:
            t, b = _time(lambda: magpylib_shells(pts_mp, k), 1)
            add(f"magpylib {k} shells", None, t, n_mp, _err(b, b_ref[:n_mp]))
    return rows


def _ratios(rows, rtols, have_magpylib):
    """Gradient cost and designkit's speed-ups over magpylib at equal error."""
    def row(method, rtol=None):
        for r in rows:
            if r["method"] == method and (rtol is None or r["rtol"] == rtol):
                return r
        return None

    ratios = {}
    # gradient cost: B+G over B at each rtol
    ratios["gradient_cost_max"] = max(row("designkit B+G", r)["us_per_point"]
                                      / row("designkit B", r)["us_per_point"] for r in rtols)
    if have_magpylib:
        mp_rows = [r for r in rows if r["method"].endswith("shells")]
        reach = [r for r in mp_rows if r["err_b"] <= 1e-6]
        dk = min((r for r in rows if r["method"] == "designkit B+G"
                  and max(r["err_b"], r["err_g"]) <= 1e-6), key=lambda r: r["us_per_point"])
        if reach:
            best = min(reach, key=lambda r: r["us_per_point"])
            ratios["speedup_at_1e-6"] = best["us_per_point"] / dk["us_per_point"]
            ratios["magpylib_at_1e-6"] = best["method"]
        else:
            # no shell count tried reaches 1e-6: extrapolate the trapezoid rule's K^-2 law
            # from the largest K (a lower bound on magpylib's cost there)
            big = mp_rows[-1]
            k = int(big["method"].split()[1])
            k_need = int(np.ceil(k * np.sqrt(big["err_b"] / 1e-6)))
            ratios["speedup_at_1e-6"] = (big["us_per_point"] * k_need / k) / dk["us_per_point"]
            ratios["magpylib_at_1e-6"] = f"{k_need} shells (extrapolated from {k})"
        ratios["designkit_at_1e-6"] = f"B+G rtol={dk['rtol']:g}"
        r16 = row("magpylib 16 shells")
        ratios["magpylib16_error"] = r16["err_b"]
        ratios["speedup_vs_16_shells_at_rtol_1e-10"] = (
            r16["us_per_point"] / row("designkit B+G", 1e-10)["us_per_point"])
    return ratios


def _table_lines(rows, ratios, ref_check):
    lines = [f"{'method':45s} {'rtol':>8s} {'us/point':>10s} {'err B':>10s} {'err G':>10s}"]
    for r in rows:
        lines.append(f"{r['method']:45s} {'' if r['rtol'] is None else format(r['rtol'], '.0e'):>8s}"
                     f" {r['us_per_point']:10.3f} {r['err_b']:10.2e}"
                     f" {'' if r['err_g'] is None else format(r['err_g'], '.2e'):>10s}")
    lines.append("")
    for k, val in ratios.items():
        lines.append(f"{k}: {val:.3g}" if isinstance(val, float) else f"{k}: {val}")
    if ref_check is not None:
        lines.append(f"reference (rtol=1e-13) vs mpmath on 4 points: {ref_check:.2e}")
    return lines


def _plot(rows, out_dir):
    """Time per point against error, written to out_dir/bench_field.png; returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    for method, marker in [("designkit B", "o-"), ("designkit B+G", "s-")]:
        rr = [r for r in rows if r["method"] == method]
        err = [max(r["err_b"], r["err_g"] or 0.0) for r in rr]
        ax.loglog([max(e, 1e-17) for e in err], [r["us_per_point"] for r in rr], marker,
                  label=method + " (rtol sweep)")
    mp_rows = [r for r in rows if "shells" in r["method"]]
    if mp_rows:
        ax.loglog([r["err_b"] for r in mp_rows], [r["us_per_point"] for r in mp_rows], "^--",
                  label="magpylib K shells (B only)")
        for r in mp_rows:
            ax.annotate(r["method"].split()[1], (r["err_b"], r["us_per_point"]), fontsize=8)
    for r in rows:
        if "Circle" in r["method"] or "loops" in r["method"] or "closed" in r["method"]:
            ax.loglog([max(r["err_b"], 1e-17)], [r["us_per_point"]], "x", ms=9, label=r["method"])
    ax.set_xlabel("achieved relative error vs uniform-density model")
    ax.set_ylabel("run time per point, us")
    ax.set_title("Thesis winding: time per point vs error")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    png = out_dir / "bench_field.png"
    tmp = out_dir / "bench_field.tmp.png"
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(png)
    return png


def run(out_dir, quick=False):
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    n_dk = 400 if quick else 4000
    n_mp = 40 if quick else 300
    repeat = 1 if quick else 3
    rtols = [1e-4, 1e-6, 1e-10] if quick else [1e-4, 1e-5, 1e-6, 1e-8, 1e-10, 1e-12]
    shells = [4, 16, 64] if quick else [4, 16, 64, 128, 256, 512]

    pts = workspace_points(n_dk)
    b_ref, g_ref = _kernel_reference(pts)
    # the reference itself against mpmath on a few points
    ref_check = None if quick else _reference_check(pts, b_ref, g_ref)
    have_magpylib = _have_magpylib()
    rows = _time_methods(pts, n_mp, b_ref, g_ref, rtols, shells, repeat, have_magpylib)
    ratios = _ratios(rows, rtols, have_magpylib)
    lines = _table_lines(rows, ratios, ref_check)
    rand_rows, mag_rows, rand_lines = random_geometries(quick, have_magpylib)
    lines += ["", *rand_lines]
    table = "\n".join(lines)
    write_text_atomic(out_dir / "bench_field.txt", table + "\n")
    png = _plot(rows, out_dir)
    result = dict(rows=rows, ratios=ratios, reference_vs_mpmath=ref_check, table=table,
                  png=str(png), random_rows=rand_rows, random_magpylib_rows=mag_rows)
    write_json_atomic(out_dir / "bench_field.json", {k: v for k, v in result.items()})
    return result


if __name__ == "__main__":
    from studies._common import study_parser

    a = study_parser(__doc__, Path(__file__).resolve().parents[1] / "out" / "bench_field",
                     quick="a smoke test: fewer points and cases").parse_args()
    res = run(a.out, quick=a.quick)
    print(res["table"])
