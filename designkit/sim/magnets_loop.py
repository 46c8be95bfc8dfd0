"""The closed loop with N magnets: firmware_io's :class:`~firmware_io.runner.MagnetsRunner`
stepped against :class:`~designkit.sim.magnets.MagnetsDevice`, what a run says, and its
figures.

Per control period T (s), as :func:`designkit.sim.loop.simulate`: the sensor source ticks
(beside the loop, as the sensor thread), the runner steps (its compute clock stands still:
modelled compute time), the true force on every magnet is taken at its true position with the
true coil currents (the coupled model, the cores' pull of every magnet, the pair force), and
the coils advance one R-L step under the voltages the PWM registers hold. Faults are not
injected in an N-magnet run. SI units throughout.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..support.progress import tqdm
from .loop import LoopTiming
from .report import STALE_LIMIT_M
from .sensors import SimSensorSource


class MagnetsSensorSource(SimSensorSource):
    """:class:`SimSensorSource` for N magnets: ``position_at(t_s)`` gives (N, 3) m, and each
    published fix is logged as (field time s, trusted per magnet, distance m per magnet)."""

    @staticmethod
    def diagnose(fix, truth_m) -> tuple:
        truth = np.asarray(truth_m, float)
        return (tuple(bool(f.ok) for f in fix.fixes),
                tuple(float(np.linalg.norm(np.asarray(f.position_m, float) - q))
                      for f, q in zip(fix.fixes, truth)))


@dataclass
class MagnetsResult:
    """Per step (k steps, N magnets, n coils; SI): ``t_s`` (k,), true and rendered-on
    (predicted; NaN without a track) positions (k, N, 3), the runner's object force at its
    estimate ``force_ref_n``, the true force on each magnet ``force_n``, the object's force
    at the true position ``object_n``, the true pair force ``pair_n`` and the one the runner
    compensated ``pair_compensated_n`` (k, N, 3), the condition number of the stacked rows
    (k,), the runner's state (k,), true and commanded currents (k, n); the sensor side's fixes
    and the runner's fault log."""

    names: list
    period_s: float
    t_s: np.ndarray
    true_m: np.ndarray
    estimate_m: np.ndarray
    force_ref_n: np.ndarray
    force_n: np.ndarray
    object_n: np.ndarray
    pair_n: np.ndarray
    pair_compensated_n: np.ndarray
    condition: np.ndarray
    state: np.ndarray
    loop_s: np.ndarray
    new_frame: np.ndarray
    current_a: np.ndarray
    command_a: np.ndarray
    fixes: list = field(default_factory=list)
    fault_log: list = field(default_factory=list)


def _still() -> float:
    """The modelled compute clock: a step takes no simulated time."""
    return 0.0


def simulate_magnets(device, runner_factory, trajectory, *, duration_s: float,
                     timing: LoopTiming = LoopTiming(), scene_force=None,
                     progress: bool = True) -> MagnetsResult:
    """Close the loop for N magnets: ``runner_factory(sensor_source, clock)`` -> a started
    :class:`firmware_io.runner.MagnetsRunner` on ``device.coils``; ``trajectory`` a
    :class:`~designkit.sim.pinch.MagnetsTrajectory`; ``scene_force(p, v) -> (3,)`` N the
    object's force at a true position (the reference)."""
    period = timing.period_s
    n_steps = int(round(duration_s / period))
    t = np.arange(n_steps) * period
    true_p = np.array([trajectory.at(ts) for ts in t])            # (k, N, 3)
    vel = np.gradient(true_p, period, axis=0)
    device.prepare(true_p.transpose(1, 0, 2))
    source = MagnetsSensorSource(device, trajectory.at, period, timing.fit_time_s)
    runner = runner_factory(source, _still)
    n, nc = device.n_magnets, device.array.n_coils
    cols = {key: np.zeros((n_steps, n, 3)) for key in
            ("estimate_m", "force_ref_n", "force_n", "object_n", "pair_compensated_n")}
    cond, loop_s = np.zeros(n_steps), np.zeros(n_steps)
    new_frame = np.zeros(n_steps, dtype=bool)
    cpu = device.coil_bus.cpu_outside_s
    cur, cmd = np.zeros((n_steps, nc)), np.zeros((n_steps, nc))
    states = []
    bar = tqdm(total=n_steps, desc="simulate", unit="step", disable=not progress,
               mininterval=0.5)
    try:     # the runner gives the garbage collector back on any exit
        for s in range(n_steps):
            source.tick(t[s])
            c0 = cpu()
            rec = runner.step(t[s])
            loop_s[s], new_frame[s] = cpu() - c0, rec.new_frame
            i_true = device.current_a.copy()
            cols["estimate_m"][s] = rec.positions_m
            cols["force_ref_n"][s] = rec.forces_ref_n
            cols["force_n"][s] = device.true_forces_n(s, i_true)
            if scene_force is not None:
                cols["object_n"][s] = [scene_force(true_p[s, k], vel[s, k]) for k in range(n)]
            cols["pair_compensated_n"][s] = rec.pair_forces_n
            cond[s] = rec.condition
            cur[s], cmd[s] = i_true, rec.command_a
            states.append(rec.state)
            device.advance_currents(period)
            device.coil_bus.clear_log()
            bar.update()
        bar.close()
    finally:
        runner.stop()
    return MagnetsResult(list(device.names), period, t, true_p, pair_n=device.pair_n[:n_steps],
                         condition=cond, state=np.array(states), loop_s=loop_s,
                         new_frame=new_frame, current_a=cur,
                         command_a=cmd, fixes=list(source.fixes),
                         fault_log=list(runner.fault_log), **cols)


def magnets_summary(result: MagnetsResult) -> dict:
    """summary.json of an N-magnet run: per magnet (``magnets``, in the design's order) its
    ``name``, the commanded (object) force RMS ``force_rms_n`` and the rendered force's error
    RMS ``force_error_rms_n`` (|true force - object force at the true position|, running
    steps), ``localization_mae_m`` (the rendered-on position's error, steps with a track),
    ``trusted_wrong_fixes`` (trusted fixes more than 5 mm off at their frame time), the pair
    force RMS and the RMS of its compensation error; and the run's running fraction, the
    running steps' measured compute time (p50, p99) and the stacked rows' condition
    numbers."""
    running = result.state == "running"
    out = []
    for k, name in enumerate(result.names):
        err = np.linalg.norm(result.force_n[:, k] - result.object_n[:, k], axis=1)[running]
        obj = np.linalg.norm(result.object_n[:, k], axis=1)[running]
        pair_err = np.linalg.norm(result.pair_n[:, k] - result.pair_compensated_n[:, k],
                                  axis=1)[running]
        loc = np.linalg.norm(result.estimate_m[:, k] - result.true_m[:, k], axis=1)
        loc = loc[np.isfinite(loc)]
        trusted = [f for f in result.fixes if f[1][k]]
        out.append({
            "name": name, "force_rms_n": _rms(obj), "force_error_rms_n": _rms(err),
            "force_error_p95_n": float(np.percentile(err, 95)) if len(err) else None,
            "localization_mae_m": float(np.mean(loc)) if len(loc) else None,
            "trusted_wrong_fixes": int(sum(f[2][k] > STALE_LIMIT_M for f in trusted)),
            "fixes": len(result.fixes), "fixes_trusted": len(trusted),
            "pair_force_rms_n": _rms(np.linalg.norm(result.pair_n[:, k], axis=1)[running]),
            "pair_compensation_error_rms_n": _rms(pair_err)})
    c = result.condition[running]
    loop = result.loop_s[running]
    return {"magnets": out, "steps": int(len(result.t_s)), "period_s": result.period_s,
            "running_fraction": float(np.mean(running)),
            "loop_p50_s": float(np.percentile(loop, 50)) if len(loop) else None,
            "loop_p99_s": float(np.percentile(loop, 99)) if len(loop) else None,
            "condition_median": float(np.median(c)) if len(c) else None,
            "condition_max": float(np.max(c)) if len(c) else None,
            "max_command_a": float(np.abs(result.command_a).max()),
            "fault_log": [{"t_s": float(t), "state": s, "detail": d}
                          for t, s, d in result.fault_log]}


def _rms(x) -> float | None:
    return float(np.sqrt(np.mean(np.square(x)))) if len(x) else None


def write_magnets_csv(path, result: MagnetsResult) -> Path:
    """run.csv of an N-magnet run: t_s, state, per magnet <name>_<column> (true and estimated
    position, object, rendered-on and true force, true and compensated pair force), the
    condition number and per coil i<k>_a, cmd<k>_a (SI)."""
    head, blocks = ["t_s", "state", "condition"], [result.t_s[:, None], None,
                                                   result.condition[:, None]]
    parts = (("x_m y_m z_m", result.true_m), ("xe_m ye_m ze_m", result.estimate_m),
             ("fx_obj_n fy_obj_n fz_obj_n", result.object_n),
             ("fx_ref_n fy_ref_n fz_ref_n", result.force_ref_n),
             ("fx_n fy_n fz_n", result.force_n), ("px_n py_n pz_n", result.pair_n),
             ("pxc_n pyc_n pzc_n", result.pair_compensated_n))
    for k, name in enumerate(result.names):
        for cols, arr in parts:
            head += [f"{name}_{c}" for c in cols.split()]
            blocks.append(arr[:, k])
    nc = result.current_a.shape[1]
    head += [f"i{j + 1}_a" for j in range(nc)] + [f"cmd{j + 1}_a" for j in range(nc)]
    blocks += [result.current_a, result.command_a]
    path = Path(path)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(head)
        for s in range(len(result.t_s)):
            row = []
            for b in blocks:
                row.extend([result.state[s]] if b is None else [f"{x:.9g}" for x in b[s]])
            w.writerow(row)
    return path


def plot_magnets(result: MagnetsResult, out_dir, file_names, title: str = "") -> list:
    """One figure per magnet (``file_names``, e.g. run_<name>.png): its x against time (true, rendered-on), then its Fx: the
    object's at the true position, the true force on it, the pair force, the runner's off
    spans shaded. Returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = result.t_s
    off = result.state != "running"
    paths = []
    for k, name in enumerate(result.names):
        fig, ax = plt.subplots(2, 1, figsize=(10.0, 6.5), constrained_layout=True, sharex=True)
        ax[0].plot(t, result.true_m[:, k, 0] * 1e3, color="tab:blue", label="x (true)")
        ax[0].plot(t, result.estimate_m[:, k, 0] * 1e3, color="tab:orange", lw=0.8,
                   label="x (rendered on)")
        ax[0].set_ylabel("x (mm)")
        ax[1].plot(t, result.object_n[:, k, 0] * 1e3, color="k", label="object Fx at the true x")
        ax[1].plot(t, result.force_n[:, k, 0] * 1e3, color="tab:red", lw=0.9,
                   label="rendered Fx (true force on the magnet)")
        ax[1].plot(t, result.pair_n[:, k, 0] * 1e3, color="tab:purple", ls=":",
                   label="the other magnet's pull (Fx)")
        ax[1].set_ylabel("Fx (mN)")
        ax[1].set_xlabel("time (s)")
        for a in ax:
            a.fill_between(t, 0, 1, where=off, transform=a.get_xaxis_transform(),
                           color="0.9", label="coils off")
            a.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
        ax[0].set_title(f"{title}: {name}" if title else name)
        p = Path(out_dir) / file_names[k]
        fig.savefig(p, dpi=120)
        plt.close(fig)
        paths.append(p)
    return paths
