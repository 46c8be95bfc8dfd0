"""Question: at matched achieved error, how much run time per point does designkit's thick-winding
field cost against its peers, cfsem (Rust filament sums) and magpylib (numpy shells)?

Winding: the thesis coil (Ri = 12 mm, Ro = 19 mm, L = 100 mm, 1429 turns, 1 A, uniform J).
Point sets (local frame): workspace (10^4 points, rho <= 40 mm, 20..80 mm above the top face),
near (2000, 1..10 mm outside the top face or the outer side), far (2000, 0.3..1 m, any way).
Error = max over points of |B - B_ref| / |B_ref| (B+G rows: the larger of that and the same for
G), B_ref from
designkit's exact path at rtol 1e-13 (checked against mpmath in tests/test_field_winding*.py).
Methods, same points, same process, one thread each (the thread-count variables of OpenMP,
BLAS and Rayon set to 1 before numpy loads), min of ``repeat`` wall-clock runs:
* designkit winding_field (Cartesian in and out), B and B + gradient, rtol 1e-4 .. 1e-12;
* dk-expansion: the same at rtol 1e-10 and 1e-12 with the exterior expansion allowed there
  (``winding.HARMONIC_RTOL_MIN`` lowered for the call: by default such requests take the exact
  path, batch-independent to ~1e-15); the expansion's bound still decides per point;
* cfsem.flux_density_circular_filament on Gauss-Legendre (na x nz) filament grids of the same
  section (par=False), plus the cylindrical -> Cartesian step; cfsem has no gradient of the
  circular-filament field: G by central differences of B in (rho, z), step 1 um (4 more calls);
* magpylib's nested shells (studies/bench_field.magpylib_shells, K shells), B only; G by
  central differences in x, y, z (6 more calls), on the first points of each set only.
Matched error E: each method's fastest configuration whose achieved error is <= E.
Output: bench_peers.txt (table, ratios), bench_peers.json, bench_peers.png (log-log time per
point against achieved error, one panel per point set). Run: ``python studies/bench_peers.py
OUT [--quick] [--repeat=K] [--sets=workspace,near,far] [--shells=8,32]``; the load average
and a same-process reference (2000 x 2000 matmul) are printed.
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "RAYON_NUM_THREADS"):
    os.environ[_v] = "1"

import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from designkit.support.atomic import atomic_path, write_json_atomic, write_text_atomic  # noqa: E402
from designkit.constants import MU0  # noqa: E402
from designkit.field import cylindrical_to_cartesian, winding_field  # noqa: E402
from designkit.field import harmonic, winding  # noqa: E402
from designkit.field.winding import winding_rz  # noqa: E402
from studies._common import load_average  # noqa: E402
from studies.bench_field import I, J, L, N, RI, RO, _err, _time, magpylib_shells  # noqa: E402

TARGETS = (1e-4, 1e-6, 1e-8)
CD_STEP = 1e-6
"""Central-difference step for the peers' gradients, m."""


def point_sets(n, seed=0, n_other=None):
    """{name: (n, 3) points, m} in the winding's local frame (near, far: ``n_other``)."""
    rng = np.random.default_rng(seed)
    phi = rng.uniform(0, 2 * np.pi, n)
    rho = 0.04 * np.sqrt(rng.uniform(0, 1, n))
    ws = np.stack([rho * np.cos(phi), rho * np.sin(phi), L / 2 + rng.uniform(0.02, 0.08, n)], 1)
    # near: offset 1..10 mm outward from a random spot of the top face or of the outer side
    n = n if n_other is None else n_other
    phi = phi[:n]
    d = rng.uniform(0.001, 0.01, n)
    top = rng.uniform(0, 1, n) < 0.5
    r_n = np.where(top, np.sqrt(rng.uniform(RI**2, RO**2, n)), RO + d)
    z_n = np.where(top, L / 2 + d, rng.uniform(-L / 2, L / 2, n))
    near = np.stack([r_n * np.cos(phi), r_n * np.sin(phi), z_n], 1)
    u = rng.normal(size=(n, 3))
    far = u / np.linalg.norm(u, axis=1)[:, None] * rng.uniform(0.3, 1.0, n)[:, None]
    return {"workspace": ws, "near": near, "far": far}


def reference(pts):
    """(B, G) of the exact path at rtol 1e-13, T and T/m."""
    rho = np.hypot(pts[:, 0], pts[:, 1])
    c = np.where(rho > 0, pts[:, 0] / np.where(rho > 0, rho, 1), 1.0)
    s = np.where(rho > 0, pts[:, 1] / np.where(rho > 0, rho, 1), 0.0)
    res = winding_rz(RI, RO, L / 2, rho, pts[:, 2], gradient=True, rtol=1e-13)
    return cylindrical_to_cartesian(c, s, MU0 * J, res, True)


def _grid(na, nz):
    xa, wa = np.polynomial.legendre.leggauss(na)
    xz, wz = np.polynomial.legendre.leggauss(nz)
    a = 0.5 * (RO + RI) + 0.5 * (RO - RI) * xa
    A, Z = np.meshgrid(a, L / 2 * xz, indexing="ij")
    W = np.outer(0.5 * (RO - RI) * wa, L / 2 * wz) * J  # A per filament
    return W.ravel(), A.ravel(), Z.ravel()


def _cfsem_mu0():
    """cfsem's mu0 (CODATA; designkit's is 4e-7 pi): B at the centre of a unit loop x 2."""
    import cfsem

    one = np.ones(1)
    return 2.0 * float(cfsem.flux_density_circular_filament(one, one, 0 * one, 0 * one,
                                                            0 * one, par=False)[1][0])


def cfsem_field(pts, grid, gradient):
    """B (and G by central differences in rho, z) from cfsem's filament sum, Cartesian."""
    import cfsem

    cur, a, zf = grid
    rho = np.hypot(pts[:, 0], pts[:, 1])
    safe = np.where(rho > 0, rho, 1.0)
    c = np.where(rho > 0, pts[:, 0] / safe, 1.0)
    s = np.where(rho > 0, pts[:, 1] / safe, 0.0)
    z = pts[:, 2]

    def f(r, zz):
        return cfsem.flux_density_circular_filament(cur, a, zf, r, zz, par=False)

    br, bz = f(rho, z)
    scale = MU0 / _cfsem_mu0()
    if not gradient:
        return cylindrical_to_cartesian(c, s, scale, (br, bz), False)
    h = CD_STEP
    brp, bzp = f(rho + h, z)
    brm, bzm = f(np.abs(rho - h), z)  # Br is odd in rho: |rho - h| with its sign below
    sg = np.where(rho - h < 0, -1.0, 1.0)
    brm = brm * sg
    bru, bzu = f(rho, z + h)
    brd, bzd = f(rho, z - h)
    dbr_dr = (brp - brm) / (2 * h)
    dbz_dr = (bzp - bzm) / (2 * h)
    dbr_dz = (bru - brd) / (2 * h)
    dbz_dz = (bzu - bzd) / (2 * h)
    br_r = np.where(rho > 0, br / safe, dbr_dr)
    res = (br, bz, dbr_dr, dbr_dz, dbz_dr, dbz_dz, br_r)
    return cylindrical_to_cartesian(c, s, scale, res, True)


def magpylib_field(pts, k, gradient):
    b = magpylib_shells(pts, k)
    if not gradient:
        return b
    g = np.empty((len(pts), 3, 3))
    for j in range(3):
        e = np.zeros(3)
        e[j] = CD_STEP
        g[:, :, j] = (magpylib_shells(pts + e, k) - magpylib_shells(pts - e, k)) / (2 * CD_STEP)
    return b, g


def _matmul_seconds():
    a = np.random.default_rng(0).standard_normal((2000, 2000))
    return _time(lambda: a @ a, 3)[0]


def matched(rows, method, target, gradient):
    """Fastest row of ``method`` whose achieved error is <= target (None if none)."""
    ok = [r for r in rows if r["method"] == method and r["gradient"] == gradient
          and r["err"] <= target]
    return min(ok, key=lambda r: r["us_per_point"]) if ok else None


CONFIG = {
    False: dict(n=10000, n_mp=20, repeat=3, rtols=[1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-10, 1e-12],
                grids=[(2, 3), (2, 4), (3, 5), (3, 6), (3, 7), (4, 7), (4, 8), (4, 9), (5, 9),
                       (5, 10), (5, 12), (6, 12), (6, 14), (7, 16), (8, 20)],
                shells=[8, 32, 128, 512]),
    True: dict(n=300, n_mp=20, repeat=1, rtols=[1e-4, 1e-6, 1e-8], grids=[(3, 5), (4, 7), (6, 12)],
               shells=[4, 16]),
}
"""Full and quick (smoke test) runs."""


def run(out_dir, quick=False, repeat=None, sets=("workspace", "near", "far"), shells=None):
    """Run the benchmark into ``out_dir``; ``repeat`` overrides the min-of count, ``sets``
    chooses the point sets, ``shells`` magpylib's shell counts."""
    cfg = dict(CONFIG[bool(quick)])
    if shells is not None:
        cfg["shells"] = list(shells)
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    out_dir = Path(out_dir)
    n, n_mp, rtols, grids, shells = (cfg[k] for k in ("n", "n_mp", "rtols", "grids", "shells"))
    repeat = cfg["repeat"] if repeat is None else int(repeat)
    try:
        import cfsem  # noqa: F401
        have_cfsem = True
    except ImportError:  # pragma: no cover
        have_cfsem = False
    try:
        import magpylib  # noqa: F401
        have_mp = True
    except ImportError:  # pragma: no cover
        have_mp = False
    t0 = time.perf_counter()
    harmonic.coefficients(RI, RO, L / 2)  # cached: every later call reuses them
    coef_ms = 1e3 * (time.perf_counter() - t0)
    rows = []
    for name, pts in point_sets(n, n_other=n if quick else 2000).items():
        if name not in sets:
            continue
        b_ref, g_ref = reference(pts)
        npt = len(pts)

        def add(method, config, gradient, npts, t, out):
            if gradient:
                b, g = out
                eb, eg = _err(b, b_ref[:npts]), _err(g, g_ref[:npts])
            else:
                eb, eg = _err(out, b_ref[:npts]), None
            rows.append(dict(set=name, method=method, config=config, gradient=gradient,
                             us_per_point=1e6 * t / npts, err_b=eb, err_g=eg,
                             err=max(eb, eg or 0.0)))

        jobs = []  # (method, config, gradient, points, function)
        for gradient in (False, True):
            winding_field(pts, RI, RO, L, N, I, gradient=gradient, rtol=1e-6)  # warm caches
            for rtol in rtols:
                jobs.append(("designkit", f"rtol {rtol:.0e}", gradient, npt,
                             lambda rtol=rtol, gradient=gradient: winding_field(
                                 pts, RI, RO, L, N, I, gradient=gradient, rtol=rtol)))
            for rtol in [r for r in rtols if r < winding.HARMONIC_RTOL_MIN]:
                jobs.append(("dk-expansion", f"rtol {rtol:.0e}", gradient, npt,
                             lambda rtol=rtol, gradient=gradient: _expansion_allowed(
                                 pts, gradient, rtol)))
            for g in grids if have_cfsem else []:
                jobs.append(("cfsem", f"{g[0]}x{g[1]}", gradient, npt,
                             lambda grid=_grid(*g), gradient=gradient: cfsem_field(
                                 pts, grid, gradient)))
        # interleaved: every repeat runs every job once, so load changes hit all alike
        best = [np.inf] * len(jobs)
        outs = [None] * len(jobs)
        for _ in range(repeat):
            for k, job in enumerate(jobs):
                t, outs[k] = _time(job[4], 1)
                best[k] = min(best[k], t)
        for k, job in enumerate(jobs):
            add(*job[:4], best[k], outs[k])
        for gradient in (False, True):
            for kk in shells if have_mp else []:
                t, out = _time(lambda: magpylib_field(pts[:n_mp], kk, gradient), 1)
                add("magpylib", f"{kk} shells", gradient, n_mp, t, out)
    ratios = _ratios(rows, have_cfsem, have_mp)
    mm = _matmul_seconds()
    table = _table(rows, ratios, coef_ms, mm, n, n if quick else 2000, n_mp, repeat)
    write_text_atomic(out_dir / "bench_peers.txt", table + "\n")
    png = _figure(rows, out_dir)
    result = dict(rows=rows, ratios=ratios, coefficients_ms=coef_ms, matmul_2000_s=mm,
                  load_average=load_average(), table=table, png=str(png))
    write_json_atomic(out_dir / "bench_peers.json", result)
    return result


def _expansion_allowed(pts, gradient, rtol):
    """winding_field at ``rtol`` with the exterior expansion allowed below HARMONIC_RTOL_MIN."""
    keep = winding.HARMONIC_RTOL_MIN
    winding.HARMONIC_RTOL_MIN = rtol
    try:
        return winding_field(pts, RI, RO, L, N, I, gradient=gradient, rtol=rtol)
    finally:
        winding.HARMONIC_RTOL_MIN = keep


def _ratios(rows, have_cfsem, have_mp):
    out = {}
    for name in ("workspace", "near", "far"):
        sub = [r for r in rows if r["set"] == name]
        for gradient in (False, True):
            tag = "B+G" if gradient else "B"
            for e in TARGETS:
                dk = matched(sub, "designkit", e, gradient)
                cf = matched(sub, "cfsem", e, gradient) if have_cfsem else None
                if dk and cf:
                    out[f"{name} {tag} designkit/cfsem at {e:.0e}"] = dict(
                        ratio=dk["us_per_point"] / cf["us_per_point"], designkit=dk["config"],
                        cfsem=cf["config"])
            if have_mp:
                dk = matched(sub, "designkit", 1e-6, gradient)
                mp = [r for r in sub if r["method"] == "magpylib" and r["gradient"] == gradient]
                reach = [r for r in mp if r["err"] <= 1e-6]
                if dk and mp:
                    if reach:
                        best = min(reach, key=lambda r: r["us_per_point"])
                        t_mp, what = best["us_per_point"], best["config"]
                    else:
                        # the shells' trapezoid rule converges like K^-2: extrapolate from
                        # the largest K (a lower bound on magpylib's cost at 1e-6)
                        big = max(mp, key=lambda r: int(r["config"].split()[0]))
                        k = int(big["config"].split()[0])
                        k_need = int(np.ceil(k * np.sqrt(big["err"] / 1e-6)))
                        t_mp = big["us_per_point"] * k_need / k
                        what = f"{k_need} shells (extrapolated from {k})"
                    out[f"{name} {tag} magpylib/designkit at 1e-06"] = dict(
                        ratio=t_mp / dk["us_per_point"], designkit=dk["config"], magpylib=what)
    return out


def _table(rows, ratios, coef_ms, mm, n, n_other, n_mp, repeat):
    lines = [f"thesis winding, {n} workspace points (near, far: {n_other}; magpylib: the first "
             f"{n_mp} of each set), one thread each, "
             f"min of {repeat}; load average {load_average()}; 2000x2000 matmul {mm:.3f} s "
             f"(same process); designkit's expansion coefficients (once per winding) "
             f"{coef_ms:.1f} ms",
             "cfsem G and magpylib G: central differences of B (step 1 um)", "",
             f"{'set':10s} {'method':12s} {'config':14s} {'grad':>5s} {'us/point':>10s} "
             f"{'err B':>10s} {'err G':>10s}"]
    for r in rows:
        eg = "" if r["err_g"] is None else f"{r['err_g']:.2e}"
        lines.append(f"{r['set']:10s} {r['method']:12s} {r['config']:14s} "
                     f"{'B+G' if r['gradient'] else 'B':>5s} {r['us_per_point']:10.3f} "
                     f"{r['err_b']:10.2e} {eg:>10s}")
    lines += ["", "matched achieved error (each method's fastest configuration within it):"]
    for k, v in ratios.items():
        rest = ", ".join(f"{a}: {b}" for a, b in v.items() if a != "ratio")
        lines.append(f"  {k:48s} {v['ratio']:8.3f}   ({rest})")
    return "\n".join(lines)


def _figure(rows, out_dir):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sets = ("workspace", "near", "far")
    fig, axes = plt.subplots(1, 3, figsize=(15, 5), sharey=True)
    styles = {"designkit": "o-", "dk-expansion": "D-.", "cfsem": "s--", "magpylib": "^:"}
    for ax, name in zip(axes, sets):
        for method, st in styles.items():
            for gradient in (False, True):
                rr = [r for r in rows if r["set"] == name and r["method"] == method
                      and r["gradient"] == gradient]
                if not rr:
                    continue
                rr.sort(key=lambda r: r["err"])
                ax.loglog([max(r["err"], 1e-17) for r in rr], [r["us_per_point"] for r in rr],
                          st, alpha=1.0 if gradient else 0.6,
                          label=f"{method} {'B+G' if gradient else 'B'}")
        ax.set_title(name)
        ax.set_xlabel("achieved relative error")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("time per point, us (one thread)")
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    png = out_dir / "bench_peers.png"
    with atomic_path(png) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return png


if __name__ == "__main__":
    from studies._common import study_parser

    ap = study_parser(__doc__, Path(__file__).resolve().parents[1] / "out" / "bench_peers",
                      quick="a smoke test: fewer points and tolerances")
    ap.add_argument("--repeat", type=int, default=None, help="timing repeats (default 3)")
    ap.add_argument("--sets", default="workspace,near,far",
                    help="point sets, comma-separated (default workspace,near,far)")
    ap.add_argument("--shells", default=None,
                    help="shell counts of the thick winding, comma-separated")
    a = ap.parse_args()
    kw = {"repeat": a.repeat, "sets": tuple(a.sets.split(","))}
    if a.shells is not None:
        kw["shells"] = [int(k) for k in a.shells.split(",")]
    res = run(a.out, quick=a.quick, **kw)
    print(res["table"])
