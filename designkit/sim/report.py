"""What a simulated run says: time to the safe state per fault, force error and its causes,
localization error, loop timing, and the run.csv table.

Inputs are a :class:`designkit.sim.loop.SimulationResult` (per-step SI columns); outputs are
plain dicts for summary.json (N, m, s). The force error is split into localization,
allocation, map interpolation and current lag (:func:`force_error_causes`).
"""

from __future__ import annotations

import csv

import numpy as np

from ..model.array import force_matrix
from ..support.atomic import atomic_path
from .device import SimulatedDevice
from .faults import FAULT_CLEARS_S
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
        own = np.flatnonzero(window & (st == name))
        row = {"fault": name, "injected_s": te,
               "state_at_injection": str(st[at[0]]) if len(at) else None,
               "state": None, "detected_s": None, "time_to_safe_s": None, "periods": None,
               "currents_off_s": None, "ended_s": None, "ended_into": None, "resumed_s": None,
               "recovered_s": None}
        if len(own):
            k = int(own[0])
            row.update(state=name, detected_s=float(t[k]), time_to_safe_s=float(t[k] - te),
                       periods=float((t[k] - te) / period_s))
            back = np.flatnonzero(st[k:] == "running")
            stop = k + back[0] if len(back) else len(t)
            quiet = np.flatnonzero(off[k:stop])
            if len(quiet):
                row["currents_off_s"] = float(t[k + quiet[0]] - te)
            other = np.flatnonzero(st[k:] != name)
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
    if causes is not None:
        out["force_error_causes"] = causes
    return out


def write_run_csv(path, columns: dict) -> None:
    """run.csv: one row per control step, SI columns (see :func:`simulate`)."""
    order = ["t_s", "x_m", "y_m", "z_m", "xe_m", "ye_m", "ze_m", "fx_ref_n", "fy_ref_n",
             "fz_ref_n", "fx_n", "fy_n", "fz_n"]
    order += [k for k in columns if k.startswith("i") and k.endswith("_a")]
    order += [k for k in columns if k.startswith("cmd")]
    order += ["loop_s", "state"]
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

    With p the true and q the estimated position, I* the command and I the true currents,
    F(.) / F0(.) the exact force per ampere and bias force and Fm / F0m the map's::

        F(p) I + F0(p) - f(p) =   [f(q) - f(p)] + [F(p) I* + F0(p) - F(q) I* - F0(q)]  localization
                                + [Fm(q) I* + F0m(q) - f(q)]                           allocation
                                + [F(q) I* + F0(q) - Fm(q) I* - F0m(q)]                map
                                + F(p) (I - I*)                                        current lag

    Returns RMS and p95 (N) of each term's Fz and of its magnitude, and of the total.
    """
    c = result.columns
    run = np.flatnonzero(c["state"] == "running")
    if len(run) == 0:
        return {}
    n_running = len(run)
    if n_running > max_steps:
        run = run[np.unique(np.linspace(0, n_running - 1, max_steps).round().astype(int))]
    m = device.moment
    n = device.array.n_coils
    q = np.stack([c["xe_m"], c["ye_m"], c["ze_m"]], 1)[run]
    i_cmd = np.stack([c[f"cmd{k + 1}_a"] for k in range(n)], 1)[run]
    i_true = np.stack([c[f"i{k + 1}_a"] for k in range(n)], 1)[run]
    f_ref = np.stack([c["fx_ref_n"], c["fy_ref_n"], c["fz_ref_n"]], 1)[run]
    f_obj = np.stack([c["fx_obj_n"], c["fy_obj_n"], c["fz_obj_n"]], 1)[run]
    fm = force_matrix(m)
    f_exact_q = np.einsum("ij,kjl->kil", fm, device.array.actuation_matrix(q)[:, 3:, :])
    f0_exact_q = np.asarray(device.array.bias_force(q, m), float).reshape(-1, 3)
    inside = _inside(fieldmap, q)
    f_map_q = np.zeros_like(f_exact_q)
    f_map_q[inside] = np.einsum("ij,kjl->kil", fm, fieldmap.actuation(q[inside])[:, 3:, :])
    f0_map_q = np.zeros_like(q)
    if inside.any():
        f0_map_q[inside] = np.asarray(fieldmap.bias_force(q[inside]), float).reshape(-1, 3)
    f_p = device.force_per_amp[run]
    f0_p = device.bias_n[run]

    def mv(a, i):
        return np.einsum("kil,kl->ki", a, i)

    terms = {
        "localization": (f_ref - f_obj) + (mv(f_p, i_cmd) + f0_p - mv(f_exact_q, i_cmd)
                                           - f0_exact_q),
        "allocation": mv(f_map_q, i_cmd) + f0_map_q - f_ref,
        "map_interpolation": mv(f_exact_q, i_cmd) + f0_exact_q - mv(f_map_q, i_cmd) - f0_map_q,
        "current_lag": mv(f_p, i_true - i_cmd),
    }
    terms["total"] = mv(f_p, i_true) + f0_p - f_obj
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

