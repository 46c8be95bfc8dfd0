"""What a simulated run says: time to the safe state per fault, force error and its causes,
localization error, loop timing, and the run.csv table.

Inputs are a :class:`designkit.sim.loop.SimulationResult` (per-step SI columns); outputs are
plain dicts for summary.json (N, m, s). The force error is split into localization,
allocation, map interpolation, the saturation model and current lag
(:func:`force_error_causes`); the saturation model at the limit (:func:`saturation_summary`).
"""

from __future__ import annotations

import csv

import numpy as np

from ..model.array import force_matrix
from ..support.atomic import atomic_path
from .device import SimulatedDevice
from .samples import bias_force_any
from .faults import FAULT_CLEARS_S, FAULT_STATE
from .loop import SimulationResult

CURRENT_OFF_A = 0.01
"""A coil counts as off once its true current is below this, A."""


def time_to_safe(columns: dict, events, period_s: float) -> list[dict]:
    """The fault table, counted from the run.csv columns (t_s, state, i<k>_a).

    For each injected fault (time s, type): ``state_at_injection``; its own detection (the
    first step at or after the injection, and before the same type is injected again, whose
    state is this fault's: the coils are commanded off in that step) as ``detected_s`` and
    ``time_to_safe_s`` / ``periods`` after the injection; ``currents_off_s``: injection to the
    first step from the detection on, before the runner runs again, with every true coil
    current below :data:`CURRENT_OFF_A` (None: it ran again first); ``ended_s`` /
    ``ended_into``: injection to the first later step in another state, and that state;
    ``resumed_s``: injection to the first running step after the detection (None: not within
    the run); ``recovered_s``: from when the fault's cause is gone
    (:data:`designkit.sim.faults.FAULT_CLEARS_S` after the injection, or the detection if
    later) to the first running step from then on, also when another state masked the fault
    (None: not within the run, or a fault that does not clear, thermal). A fault another one
    masks is not detected.
    """
    t = np.asarray(columns["t_s"], float)
    st = np.asarray(columns["state"])
    amps = [np.asarray(v, float) for k, v in columns.items()
            if k.startswith("i") and k.endswith("_a")]
    off = np.max(np.abs(np.stack(amps, 1)), axis=1) < CURRENT_OFF_A if amps else \
        np.ones(len(t), bool)
    events = list(events)
    out = []
    for j, (te, name) in enumerate(events):
        te = float(te)
        again = [float(t2) for t2, n2 in events[j + 1:] if n2 == name]
        window = (t >= te - 1e-12) & (t < (again[0] - 1e-12 if again else np.inf))
        at = np.flatnonzero(t >= te - 1e-12)
        state = FAULT_STATE.get(name, name)
        own = np.flatnonzero(window & (st == state))
        row = {"fault": name, "injected_s": te,
               "state_at_injection": str(st[at[0]]) if len(at) else None,
               "state": None, "detected_s": None, "time_to_safe_s": None, "periods": None,
               "currents_off_s": None, "ended_s": None, "ended_into": None, "resumed_s": None,
               "recovered_s": None}
        if len(own):
            k = int(own[0])
            row.update(state=state, detected_s=float(t[k]), time_to_safe_s=float(t[k] - te),
                       periods=float((t[k] - te) / period_s))
            back = np.flatnonzero(st[k:] == "running")
            stop = k + back[0] if len(back) else len(t)
            quiet = np.flatnonzero(off[k:stop])
            if len(quiet):
                row["currents_off_s"] = float(t[k + quiet[0]] - te)
            other = np.flatnonzero(st[k:] != state)
            if len(other):
                row.update(ended_s=float(t[k + other[0]] - te), ended_into=str(st[k + other[0]]))
            if len(back):
                row["resumed_s"] = float(t[k + back[0]] - te)
        clears = FAULT_CLEARS_S.get(name)
        if clears is not None:      # also when another state (e.g. gated) masked the fault's
            tc = max(te + clears, float(t[own[0]]) if len(own) else -np.inf)
            again = np.flatnonzero((t >= tc - 1e-12) & (st == "running"))
            if len(again):
                row["recovered_s"] = max(float(t[again[0]] - tc), 0.0)
        out.append(row)
    return out


def force_lag_s(reference, rendered, period_s: float, max_lag_s: float = 0.2) -> float:
    """Delay of ``rendered`` behind ``reference`` (s) maximizing their cross-correlation."""
    a = np.asarray(reference, float) - np.mean(reference)
    b = np.asarray(rendered, float) - np.mean(rendered)
    if not (np.any(a) and np.any(b)):
        return 0.0
    kmax = min(int(max_lag_s / period_s), len(a) - 1)
    scores = [np.dot(a[: len(a) - k], b[k:]) for k in range(kmax + 1)]
    return float(np.argmax(scores) * period_s)


def _p50_p99(x) -> dict:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if not len(x):
        return {"n": 0, "p50_s": None, "p99_s": None}
    return {"n": int(len(x)), "p50_s": float(np.percentile(x, 50)),
            "p99_s": float(np.percentile(x, 99))}


def loop_by_kind(result: SimulationResult) -> dict:
    """Compute time of the running steps without and with a new sensor result (p50, p99, s),
    per stage when the runner profiled, and of the fit on the sensor side."""
    c = result.columns
    running = c["state"] == "running"
    fresh = np.asarray(c.get("new_frame", np.zeros(len(running), bool)), bool)
    out = {"without_frame": _p50_p99(c["loop_s"][running & ~fresh]),
           "with_frame": _p50_p99(c["loop_s"][running & fresh]),
           "sensor_side_fit": _p50_p99(result.fit_s)}
    stages = [k for k in c if k.startswith("stage_")]
    if stages:
        out["stages"] = {k[6:-2]: {"without_frame": _p50_p99(c[k][running & ~fresh]),
                                   "with_frame": _p50_p99(c[k][running & fresh])}
                         for k in stages}
    return out


def loop_by_state(result: SimulationResult) -> dict:
    """Compute time of the control step per runner state (running, gated, lost, ...): n, p50,
    p99 and max, s (the fit on the sensor side is not in it: :func:`loop_by_kind`)."""
    c = result.columns
    st = np.asarray(c["state"])
    out = {}
    for name in dict.fromkeys(st.tolist()):
        x = np.asarray(c["loop_s"], float)[st == name]
        out[name] = {**_p50_p99(x), "max_s": float(np.max(x))}
    return out


def summarize(result: SimulationResult, causes: dict | None = None) -> dict:
    """summary.json: force error RMS/p95, localization MAE, loop p50/p99, faults, time to safe."""
    c = result.columns
    running = c["state"] == "running"
    f_true = np.stack([c["fx_n"], c["fy_n"], c["fz_n"]], 1)
    f_obj = np.stack([c["fx_obj_n"], c["fy_obj_n"], c["fz_obj_n"]], 1)
    err = np.linalg.norm(f_true - f_obj, axis=1)[running]
    p_true = np.stack([c["x_m"], c["y_m"], c["z_m"]], 1)
    p_est = np.stack([c["xe_m"], c["ye_m"], c["ze_m"]], 1)
    fix = np.all(np.isfinite(p_est), axis=1)
    loc = np.linalg.norm(p_est - p_true, axis=1)[fix]
    loop = c["loop_s"][running]
    currents = np.stack([v for k, v in c.items() if k.startswith("cmd")], 1)

    def stats(x):
        return (float(np.sqrt(np.mean(x ** 2))) if len(x) else None,
                float(np.percentile(x, 95)) if len(x) else None)

    rms, p95 = stats(err)
    out = {
        "steps": int(len(c["t_s"])), "period_s": result.period_s,
        "running_fraction": float(np.mean(running)),
        "force_error_rms_n": rms, "force_error_p95_n": p95,
        "object_force_rms_n": stats(np.linalg.norm(f_obj, axis=1)[running])[0],
        "force_lag_s": force_lag_s(c["fz_obj_n"], c["fz_n"], result.period_s),
        "localization_mae_m": float(np.mean(loc)) if len(loc) else None,
        "localization_p95_m": float(np.percentile(loc, 95)) if len(loc) else None,
        "loop_p50_s": float(np.percentile(loop, 50)) if len(loop) else None,
        "loop_p99_s": float(np.percentile(loop, 99)) if len(loop) else None,
        "loop_by_kind": loop_by_kind(result),
        "loop_by_state": loop_by_state(result),
        "max_command_a": float(np.abs(currents).max()),
        "max_total_command_a": float(np.abs(currents).sum(axis=1).max()),
        "faults": time_to_safe(c, result.faults, result.period_s),
        "fault_log": [{"t_s": float(t), "state": s, "detail": d} for t, s, d in result.fault_log],
    }
    out.update(pose_summary(c))
    out.update(fix_summary(result.fixes))
    if causes is not None:
        out["force_error_causes"] = causes
    return out


STALE_LIMIT_M = 5e-3
"""A rendered position farther than this from where the finger was is counted, m."""


def fix_summary(fixes) -> dict:
    """summary.json's sensor-side rows: the fixes published, the share trusted, and the
    trusted ones more than :data:`STALE_LIMIT_M` from the truth at their frame's field time
    (``fixes``: (field time s, trusted, distance m) per fix)."""
    if not fixes:
        return {"fixes": 0, "fixes_trusted_fraction": None, "trusted_fixes_beyond_5mm": 0}
    ok = np.array([f[1] for f in fixes], bool)
    far = np.array([f[2] for f in fixes], float) > STALE_LIMIT_M
    return {"fixes": int(len(ok)), "fixes_trusted_fraction": float(ok.mean()),
            "trusted_fixes_beyond_5mm": int(np.sum(ok & far))}


def pose_summary(columns: dict) -> dict:
    """summary.json's pose and torque rows, from the run.csv columns (SI): the tilt, the moment
    direction error, the torque of the coils' field on the true magnet and as the runner
    reported it, the sensors fault detection excluded and those dropped for saturation, and
    how far the rendered position was from the finger -- at the frame time of the newest fix
    the runner had (what the runner could know: ``rendered_off_frame_steps``) and now (the
    sensing latency included)."""
    c = columns
    running = c["state"] == "running"
    m = np.stack([c["mx_a_m2"], c["my_a_m2"], c["mz_a_m2"]], 1)
    me = np.stack([c["mxe_a_m2"], c["mye_a_m2"], c["mze_a_m2"]], 1)
    ref = m[0] / np.linalg.norm(m[0])
    unit = m / np.linalg.norm(m, axis=1, keepdims=True)
    tilt = np.degrees(np.arccos(np.clip(unit @ ref, -1.0, 1.0)))
    cos_e = np.sum(unit * me, axis=1) / np.maximum(np.linalg.norm(me, axis=1), 1e-300)
    err = np.degrees(np.arccos(np.clip(cos_e, -1.0, 1.0)))[running]
    tau = np.linalg.norm(np.stack([c["tx_n_m"], c["ty_n_m"], c["tz_n_m"]], 1), axis=1)[running]
    tau_e = np.linalg.norm(np.stack([c["txe_n_m"], c["tye_n_m"], c["tze_n_m"]], 1),
                           axis=1)[running]
    t = np.asarray(c["t_s"], float)
    p = np.stack([c["x_m"], c["y_m"], c["z_m"]], 1)
    pe = np.stack([c["xe_m"], c["ye_m"], c["ze_m"]], 1)
    t_fix = np.asarray(c["fix_t_s"], float)
    at_fix = np.stack([np.interp(t_fix, t, p[:, k]) for k in range(3)], 1)
    off_frame = np.linalg.norm(pe - at_fix, axis=1)[running]
    off_now = np.linalg.norm(pe - p, axis=1)[running]
    changes = [str(x) for k, x in enumerate(c["fault_excluded"])
               if k == 0 or x != c["fault_excluded"][k - 1]]

    def top(x):
        return float(np.max(x)) if len(x) else None

    return {"max_tilt_deg": float(np.max(tilt)),
            "moment_error_median_deg": float(np.median(err)) if len(err) else None,
            "moment_error_max_deg": top(err),
            "torque_rms_n_m": float(np.sqrt(np.mean(tau ** 2))) if len(tau) else None,
            "torque_max_n_m": top(tau),
            "reported_torque_rms_n_m": float(np.sqrt(np.mean(tau_e ** 2))) if len(tau_e)
            else None,
            "fault_excluded_sensors": sorted({int(k) for x in changes for k in x.split()}),
            "max_saturating_sensors": int(np.max(c["n_saturating"])),
            "fix_age_max_s": top((t - t_fix)[running]),
            "rendered_off_frame_steps": int(np.sum(off_frame > STALE_LIMIT_M)),
            "rendered_off_frame_max_m": top(off_frame),
            "rendered_off_now_steps": int(np.sum(off_now > STALE_LIMIT_M)),
            "rendered_off_now_max_m": top(off_now)}


def write_run_csv(path, columns: dict) -> None:
    """run.csv: one row per control step, SI columns (see :func:`simulate`)."""
    order = ["t_s", "x_m", "y_m", "z_m", "xe_m", "ye_m", "ze_m", "mx_a_m2", "my_a_m2",
             "mz_a_m2", "mxe_a_m2", "mye_a_m2", "mze_a_m2", "fx_ref_n", "fy_ref_n", "fz_ref_n",
             "fx_n", "fy_n", "fz_n", "tx_n_m", "ty_n_m", "tz_n_m", "txe_n_m", "tye_n_m",
             "tze_n_m"]
    order += [k for k in columns if k.startswith("i") and k.endswith("_a")]
    order += [k for k in columns if k.startswith("cmd")]
    order += ["n_saturating", "fault_excluded", "fix_t_s", "loop_s", "state"]
    order = [k for k in order if k in columns]
    with atomic_path(path) as tmp, tmp.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(order)
        cols = [columns[k] for k in order]
        for row in zip(*cols):
            w.writerow([v if isinstance(v, str) else f"{float(v):.9g}" for v in row])



def force_error_causes(device: SimulatedDevice, fieldmap, result: SimulationResult, *,
                       max_steps: int = 500) -> dict:
    """Split the rendered-force error into its causes, over the running steps (at most
    ``max_steps`` of them, evenly spaced: the exact coupled model at each estimate is the
    costly part; RMS and p95 of an evenly spaced subsample of a 4000-step run).

    With (p, m) the true and (q, n) the estimated pose (position, moment), I* the command and I
    the true currents, F(., m, I) / F0(., m) the exact force per ampere (the saturating cores'
    columns at the currents I) and bias force on a moment m, Fm / F0m the map's (Fm(q, n, I*):
    its linear A with the map's saturation factor at I*; the map's F0 is for its own moment) and
    Fl(q, n) S(I*) the exact linear force per ampere scaled by that factor::

        F(p,m,I) I + F0(p,m) - f(p) = [f(q) - f(p)]
                      + [F(p,m,I*) I* + F0(p,m) - F(q,n,I*) I* - F0(q,n)]   localization
                      + [Fm(q,n,I*) I* + F0m(q) - f(q)]                     allocation
                      + [Fl(q,n) S(I*) I* + F0(q,n) - Fm(q,n,I*) I* - F0m(q)] map
                      + [F(q,n,I*) I* - Fl(q,n) S(I*) I*]                    saturation
                      + [F(p,m,I) I - F(p,m,I*) I*]                         current lag

    ('localization' holds the pose's error, position and orientation; 'saturation' the error of
    the map's per-coil factor against the plant's saturating cores, zero for linear cores.)
    Returns RMS and p95 (N) of each term's Fz and of its magnitude, and of the total.
    """
    c = result.columns
    run = np.flatnonzero(c["state"] == "running")
    if len(run) == 0:
        return {}
    n_running = len(run)
    if n_running > max_steps:
        run = run[np.unique(np.linspace(0, n_running - 1, max_steps).round().astype(int))]
    n = device.array.n_coils

    def col3(names):
        return np.stack([c[k] for k in names.split()], 1)[run]

    q = col3("xe_m ye_m ze_m")
    m_est = col3("mxe_a_m2 mye_a_m2 mze_a_m2")
    i_cmd = np.stack([c[f"cmd{k + 1}_a"] for k in range(n)], 1)[run]
    i_true = np.stack([c[f"i{k + 1}_a"] for k in range(n)], 1)[run]
    f_ref = col3("fx_ref_n fy_ref_n fz_ref_n")
    f_obj = col3("fx_obj_n fy_obj_n fz_obj_n")
    fm = np.stack([force_matrix(m) for m in m_est])
    a_lin = device.array.actuation_matrix(q)
    f_lin_q = np.einsum("kij,kjl->kil", fm, a_lin[:, 3:, :])
    f_exact_q = np.einsum("kij,kjl->kil", fm, device.saturated(q, a_lin, i_cmd)[:, 3:, :])
    # F0 at the estimate: the point dipole's there, plus the magnet's finite-size part at the
    # true position (a few % of F0, smooth: its change over the localization error is small)
    f0_exact_q = (bias_force_any(device.array, q, m_est)
                  + np.stack([device.bias.at(k) for k in run])
                  - bias_force_any(device.array, device.path_m[run], device.moment_steps[run]))
    s_map = fieldmap.saturation_table().factor_at(i_cmd)          # (k, n)
    inside = _inside(fieldmap, q)
    f_map_q = np.zeros_like(f_exact_q)
    f_map_q[inside] = np.einsum("kij,kjl->kil", fm[inside],
                                fieldmap.actuation(q[inside])[:, 3:, :]) * s_map[inside, None]
    f0_map_q = np.zeros_like(q)
    if inside.any():
        f0_map_q[inside] = np.asarray(fieldmap.bias_force(q[inside]), float).reshape(-1, 3)
    f_cmd = np.stack([device.force_per_amp(k, i) for k, i in zip(run, i_cmd)])
    f_true = np.stack([device.force_per_amp(k, i) for k, i in zip(run, i_true)])
    f0_p = np.stack([device.bias.at(k) for k in run])

    def mv(a, i):
        return np.einsum("kil,kl->ki", a, i)

    terms = {
        "localization": (f_ref - f_obj) + (mv(f_cmd, i_cmd) + f0_p - mv(f_exact_q, i_cmd)
                                           - f0_exact_q),
        "allocation": mv(f_map_q, i_cmd) + f0_map_q - f_ref,
        "map_interpolation": mv(f_lin_q * s_map[:, None], i_cmd) + f0_exact_q
        - mv(f_map_q, i_cmd) - f0_map_q,
        "saturation": mv(f_exact_q - f_lin_q * s_map[:, None], i_cmd),
        "current_lag": mv(f_true, i_true) - mv(f_cmd, i_cmd),
    }
    terms["total"] = mv(f_true, i_true) + f0_p - f_obj
    out = {}
    for name, v in terms.items():
        v = v[inside] if name != "total" else v
        mag = np.linalg.norm(v, axis=1)
        out[name] = {"fz_rms_n": float(np.sqrt(np.mean(v[:, 2] ** 2))),
                     "fz_p95_n": float(np.percentile(np.abs(v[:, 2]), 95)),
                     "norm_rms_n": float(np.sqrt(np.mean(mag ** 2))),
                     "norm_p95_n": float(np.percentile(mag, 95))}
    out["steps"] = int(n_running)
    out["steps_evaluated"] = int(len(run))
    return out


def _inside(fieldmap, q) -> np.ndarray:
    lo, hi = (np.asarray(b, float) for b in fieldmap.bounds)
    return np.all((q >= lo) & (q <= hi), axis=1)



SATURATION_NEAR = 0.9
"""A running step counts as near the current limit when its largest commanded |I| is at least
this fraction of the limit (:func:`saturation_summary`)."""


def saturation_summary(device: SimulatedDevice, fieldmap, result: SimulationResult,
                       limit_a: float) -> dict:
    """The runner's saturation model against the plant's saturating cores, at the commanded
    currents I* and the finger's true pose (p, m): the coils' force as the runner's model has
    it, F(m) Am(p) S(I*) I* (the map's A and its saturation factor S), against the plant's
    exact F(m) A(p, I*) I*. Over the running steps inside the map's box whose largest |I*| is
    at least :data:`SATURATION_NEAR` x ``limit_a`` (A): the relative error's RMS and maximum
    (|difference| / |exact|), and the same without the factor (S = 1: the linear cores' map).
    At those of the steps where no coil is at its bound (``below_bound_steps``: the allocation
    is exact there), ``commands_vs_rendered_mean_rel``: the commands through that model at the
    runner's estimate, F(n) Am(q) S(I*) I* + F0m(q), against the force the runner rendered there
    (f_ref), the mean difference along f_ref over its mean magnitude: ~0 when the runner applies
    the factor, ~ -6 % when it ignores it, ~ +6 % when it applies it twice. Empty when no core
    saturates."""
    if device.saturation is None:
        return {}
    c = result.columns
    n = device.array.n_coils
    i_cmd = np.stack([c[f"cmd{k + 1}_a"] for k in range(n)], 1)
    p = np.stack([c["x_m"], c["y_m"], c["z_m"]], 1)
    near = ((c["state"] == "running") & _inside(fieldmap, p)
            & (np.abs(i_cmd).max(axis=1) >= SATURATION_NEAR * limit_a))
    steps = np.flatnonzero(near)
    out = {"near_limit_a": SATURATION_NEAR * limit_a, "steps": int(len(steps))}
    if not len(steps):
        return out
    fm = np.stack([force_matrix(device.moment_steps[k]) for k in steps])
    a_map = np.einsum("kij,kjl->kil", fm, fieldmap.actuation(p[steps])[:, 3:, :])
    s_map = fieldmap.saturation_table().factor_at(i_cmd[steps])
    exact = np.stack([device.force_per_amp(k, i_cmd[k]) @ i_cmd[k] for k in steps])
    norm = np.maximum(np.linalg.norm(exact, axis=1), 1e-300)
    for name, s in (("with_factor", s_map), ("without_factor", np.ones_like(s_map))):
        rel = np.linalg.norm(np.einsum("kil,kl->ki", a_map * s[:, None], i_cmd[steps]) - exact,
                             axis=1) / norm
        out[name] = {"rel_rms": float(np.sqrt(np.mean(rel ** 2))), "rel_max": float(rel.max())}
    # the runner's commands through the map's model with the factor, at its own estimate, against
    # the force it rendered there (its target f_ref - F0m), where no coil is at its bound (the
    # allocation is then exact): ~0 when the runner applies the factor, ~ -6 % when it ignores it
    free = steps[np.abs(i_cmd[steps]).max(axis=1) < limit_a - 1e-3]
    out["below_bound_steps"] = int(len(free))
    if len(free):
        q = np.stack([c["xe_m"], c["ye_m"], c["ze_m"]], 1)[free]
        n_est = np.stack([c["mxe_a_m2"], c["mye_a_m2"], c["mze_a_m2"]], 1)[free]
        am = np.einsum("kij,kjl->kil", np.stack([force_matrix(m) for m in n_est]),
                       fieldmap.actuation(q)[:, 3:, :])
        i = i_cmd[free]
        model = np.einsum("kil,kl->ki", am * fieldmap.saturation_table().factor_at(i)[:, None],
                          i) + np.asarray(fieldmap.bias_force(q), float).reshape(-1, 3)
        f_ref = np.stack([c["fx_ref_n"], c["fy_ref_n"], c["fz_ref_n"]], 1)[free]
        along = np.sum((model - f_ref) * f_ref, axis=1) / np.linalg.norm(f_ref, axis=1)
        out["commands_vs_rendered_mean_rel"] = float(np.mean(along)
                                                     / np.mean(np.linalg.norm(f_ref, axis=1)))
    out["max_command_a"] = float(np.abs(i_cmd[steps]).max())
    out["factor_at_max"] = float(s_map.min())
    return out
