"""Question: are two finger magnets each located within 1.5 mm (mean absolute error) with no
trusted fix more than 5 mm off, 30-60 mm apart and 30-60 mm above the array, on the thesis'
sensor layout and on the layout ``designkit sensors plan`` places for two magnets?

Data (not the estimator's model): magpylib's finite cylinders (the design's magnet, tilted 0-30
degrees, any azimuth); the cores they magnetize, designkit's rod model (InducedCoreModel) driven
by magpylib's H at the cores; the coils' field at the frame's currents (each coil uniform in
+-2 A: the planned layout stays linear there); the TLV493D chain (0.1 mT noise, 0.098 mT
counts, NaN beyond 130 mT) on each chip's axes. The estimator (MagnetsEstimator, default
settings, uncalibrated: no sensor errors simulated) knows the nominal layout, the coils' field
and the rod model. Pairs: 30-60 mm apart, each 30-60 mm up, their middle within 10 mm of the
centre, moving at up to 50 mm/s for ``--frames`` frames (500 a second). Modes: 'frame' -- each frame
alone, seeded with the true positions displaced by 2 mm (identities only, no covariance: an
acquisition); 'prior' -- each frame alone with a calibrated tracker's prediction, the true
poses displaced by N(0, 0.5 mm) per axis and N(0, 2 degrees) per tangent axis with that
covariance (as studies/pose_integrity.py); 'track' -- a constant-velocity filter a magnet
(FrameTracker) fed the frame-only measurement of each consistent fix predicts the next seed;
'runner' -- the same with the runner's tracker (PoseTracker) fed the fixes themselves.
Printed per layout, mode and magnet: availability, trusted MAE, the one-frame Cramer-Rao
bound's MAE (designkit.sensing, coupled cores, the pair's first frame), trusted fixes > 5 mm
off and beyond their protection level, swaps.

    nice -n 10 python studies/magnets_localization.py OUT [--n 10] [--frames 200] [--full]
        [--planned design.toml] [--layouts thesis,planned] [--modes frame,prior,track,runner]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import magpylib as magpy
import numpy as np
from scipy.spatial.transform import Rotation

from designkit.design import default_design
from designkit.design.files import load_design
from designkit.model.array import CoilArray
from designkit.sensing.crb import BoundSettings, pose_bound
from designkit.sensing.response import MagnetShape, magnet_response
from designkit.sim.readings import InducedCoreModel
from firmware_io.constants import MU0
from firmware_io.hw.tlv493d import TLV493D_LINEAR_RANGE_T, TLV493D_LSB_T
from firmware_io.localization import MagnetsEstimator, Pose, SensorModel
from firmware_io.localization.pose import tangent_axes
from firmware_io.runner.tracker import PoseTracker
from studies._common import ROOT, finish, load_average, run_interruptible

DEFAULT_OUT = ROOT / "out" / "magnets_localization"
MODES = ("frame", "prior", "track", "runner")
LAYOUTS = ("thesis", "planned")
FRAME_S = 2e-3
"""Time between frames, s (500 frames/s)."""
PRIOR_SD = (0.5e-3, math.radians(2.0))
"""The 'prior' mode's tracker prediction: sd per position axis (m) and tangent axis (rad), as
studies/pose_integrity.py's."""
HINT_SD_M = 2e-3
"""The identity hints' displacement sd per axis, m."""
CURRENT_A = 2.0
"""Each coil's current is uniform in +-this, A."""
NOISE_T = 0.1e-3


@dataclass
class Device:
    """The sensors as built (positions (n, 3) m, chip frames (n, 3, 3)), the coils' field
    there per ampere (n, 3, n_coils) T/A, the cores' rod model, the estimator's model and the
    design's coil array."""

    design: object
    positions: np.ndarray
    frames: np.ndarray
    coil: np.ndarray
    cores: InducedCoreModel
    model: SensorModel
    array: CoilArray


def device(design) -> Device:
    """The device of ``design``'s sensor layout (module docstring)."""
    pos, frames = design.sensor_poses()
    array = CoilArray.from_design(design)
    coil = array.actuation_matrix(pos)[:, :3, :]
    cores = InducedCoreModel(design, pos)
    mg = design.magnet
    model = SensorModel.from_operator(
        induced_samples_m=cores.samples_m.reshape(-1, 3), induced_operator=cores.operator(),
        sensor_positions_m=pos, coil_field_t_per_a=coil,
        moment_a_m2=np.asarray(mg.moment_vector_a_m2), design_sha256=design.spec_hash(),
        octupole_m2=(mg.length_m / 2) ** 2 - 0.75 * mg.radius_m ** 2,
        magnet_size_m=(mg.radius_m, mg.length_m), sensor_orientations=frames)
    return Device(design, pos, frames, coil, cores, model, array)


def rotations(dirs: np.ndarray) -> Rotation:
    """Rotations taking +z onto each unit vector (k, 3)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, dirs)
    s = np.linalg.norm(axis, axis=1)
    ang = np.arctan2(s, dirs @ z)
    vec = axis / np.where(s > 1e-12, s, 1.0)[:, None] * ang[:, None]
    vec[(s <= 1e-12) & (dirs @ z < 0)] = [math.pi, 0.0, 0.0]
    return Rotation.from_rotvec(vec)


def magnet_fields(dev: Device, positions: np.ndarray, dirs: np.ndarray,
                  magnet=None) -> np.ndarray:
    """(k, n, 3) T, array frame: one magnet (``magnet``: a design's magnet table, default the
    design's) along a path of k poses (positions (k, 3) m, unit directions (k, 3)): magpylib's
    cylinder at the sensors plus the cores it magnetizes (the rod model driven by magpylib's
    H_z at the cores' samples)."""
    mg = dev.design.magnet if magnet is None else magnet
    pol = MU0 * mg.magnetization_a_per_m
    cyl = magpy.magnet.Cylinder(polarization=(0.0, 0.0, pol),
                                dimension=(2 * mg.radius_m, mg.length_m),
                                position=positions, orientation=rotations(dirs))
    k = len(positions)
    direct = np.asarray(cyl.getB(dev.positions)).reshape(k, -1, 3)
    samples = dev.cores.samples_m
    hz = np.asarray(cyl.getH(samples.reshape(-1, 3))).reshape(k, -1, 3)[..., 2]
    return direct + dev.cores.field(hz.reshape((k,) + samples.shape[:3]))


def readout(dev: Device, field_t: np.ndarray, rng, noise_t: float = NOISE_T) -> np.ndarray:
    """(k, n, 3) T on each chip's axes: R^T B + noise, rounded to counts, NaN where an axis is
    beyond the linear range (the TLV493D chain)."""
    chip = np.einsum("sai,ksa->ksi", dev.frames, field_t)
    chip = chip + rng.normal(scale=noise_t, size=chip.shape)
    codes = np.clip(np.rint(chip / TLV493D_LSB_T), -2048, 2047)
    out = codes * TLV493D_LSB_T
    out[np.any(np.abs(out) > TLV493D_LINEAR_RANGE_T, axis=-1)] = np.nan
    return out


def tilted(axis0: np.ndarray, tilt: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    """(k, 3) unit vectors tilted by ``tilt`` rad from ``axis0`` towards ``azimuth`` rad."""
    e1, e2 = tangent_axes(axis0)
    side = np.cos(azimuth)[:, None] * e1 + np.sin(azimuth)[:, None] * e2
    return np.cos(tilt)[:, None] * axis0 + np.sin(tilt)[:, None] * side


def pair_tracks(dev: Device, n_pairs: int, n_frames: int, rng) -> dict:
    """The truth of ``n_pairs`` pairs, ``n_frames`` frames each (module docstring): positions
    (p, f, 2, 3) m, directions (p, 2, 3), currents (p, n_coils) A."""
    sep = rng.uniform(0.030, 0.060, n_pairs)
    ang = rng.uniform(0, 2 * np.pi, n_pairs)
    mid = rng.uniform(-0.010, 0.010, (n_pairs, 2))
    half = 0.5 * sep[:, None] * np.c_[np.cos(ang), np.sin(ang)]
    start = np.stack([np.c_[mid + half, rng.uniform(0.030, 0.060, n_pairs)],
                      np.c_[mid - half, rng.uniform(0.030, 0.060, n_pairs)]], 1)
    vel = rng.normal(size=(n_pairs, 2, 3))
    vel *= (rng.uniform(0, 0.05, (n_pairs, 2)) / np.linalg.norm(vel, axis=2))[..., None]
    t = FRAME_S * np.arange(n_frames)
    pos = start[:, None] + t[None, :, None, None] * vel[:, None]
    axis0 = np.asarray(dev.model.moment_a_m2) / np.linalg.norm(dev.model.moment_a_m2)
    dirs = tilted(axis0, np.radians(rng.uniform(0, 30, 2 * n_pairs)),
                  rng.uniform(0, 2 * np.pi, 2 * n_pairs)).reshape(n_pairs, 2, 3)
    cur = rng.uniform(-CURRENT_A, CURRENT_A, (n_pairs, dev.coil.shape[2]))
    return {"pos": pos, "dirs": dirs, "cur": cur}


def pair_readings(dev: Device, truth: dict, j: int, rng) -> np.ndarray:
    """(f, n, 3) T: the readings of pair j's frames."""
    pos, dirs = truth["pos"][j], truth["dirs"][j]
    f = len(pos)
    field = sum(magnet_fields(dev, pos[:, i], np.repeat(dirs[i][None], f, 0)) for i in range(2))
    field = field + (dev.coil @ truth["cur"][j])[None]
    return readout(dev, field, rng)


def crb_mae(dev: Device, positions: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """(2,) m: each magnet's one-frame Cramer-Rao bound (mean absolute error of the position;
    5 unknowns a magnet and the background, cores coupled; designkit.sensing)."""
    resp = magnet_response(dev.positions, positions, dirs, MagnetShape.of(dev.design.magnet),
                           array=dev.array)
    b = pose_bound(resp, [[0, 1]], np.arange(len(dev.positions)), dev.frames, BoundSettings())
    return b.position_mae_m[0]


def hints(truth: dict, j: int, size: float, rng) -> list:
    """Identity hints for pair j's first frame: the true positions displaced, no covariance."""
    return [Pose(truth["pos"][j, 0, i] + rng.normal(scale=HINT_SD_M, size=3),
                 size * truth["dirs"][j, i]) for i in range(2)]


def true_priors(truth: dict, j: int, k: int, size: float, rng) -> list:
    """Pair j's frame k seen by a calibrated tracker: each magnet's true pose displaced by
    N(0, :data:`PRIOR_SD`) per axis, with that covariance."""
    cov = np.diag([PRIOR_SD[0] ** 2] * 3 + [PRIOR_SD[1] ** 2] * 2)
    out = []
    for i in range(2):
        u = truth["dirs"][j, i]
        e1, e2 = tangent_axes(u)
        a, b = rng.normal(scale=PRIOR_SD[1], size=2)
        v = u + a * e1 + b * e2
        out.append(Pose(truth["pos"][j, k, i] + rng.normal(scale=PRIOR_SD[0], size=3),
                        size * v / np.linalg.norm(v), cov))
    return out


ACCEL_RMS_M_S2 = 5.0
"""The 'track' filter's white acceleration, rms m/s^2 (a finger's quick moves)."""
TURN_RMS_RAD_S = math.radians(60.0)
"""The direction's random walk, rms rad/s (the runner's tracker's turning rate)."""


class FrameTracker:
    """One magnet's tracker in mode 'track': a constant-velocity Kalman filter of the position
    whose measurement is the frame's own (``MagnetsEstimate.frame_positions_m`` and its
    covariance: the fix without the prior it was seeded with), and the direction's random walk
    from the newest consistent fix (its covariance block, which the recursion may reuse: the
    fix is the posterior and the prediction only adds the turn). :meth:`prior` is the next
    frame's seed."""

    def __init__(self):
        self.x, self.p, self.t = None, None, 0.0
        self.moment, self.rot = None, None

    def _predicted(self, t: float):
        dt = t - self.t
        f = np.eye(6)
        f[:3, 3:] = dt * np.eye(3)
        q = ACCEL_RMS_M_S2 ** 2 * np.kron(np.array([[dt ** 4 / 4, dt ** 3 / 2],
                                                    [dt ** 3 / 2, dt * dt]]), np.eye(3))
        return f @ self.x, f @ self.p @ f.T + q

    def update(self, fix, position, cov, t: float) -> None:
        """Fold in a magnet's fix (an Estimate) and its frame-only position and covariance."""
        if not fix.consistent or position is None or fix.covariance is None:
            return
        if self.x is None:
            self.x = np.r_[position, np.zeros(3)]
            self.p = np.diag(np.r_[np.diag(cov), [0.3 ** 2] * 3])
            self.p[:3, :3] = cov
        else:
            x, p = self._predicted(t)
            s = p[:3, :3] + cov
            k = p[:, :3] @ np.linalg.inv(s)
            self.x, self.p = x + k @ (position - x[:3]), p - k @ p[:3]
        self.t, self.moment = t, fix.moment_a_m2.copy()
        self.rot = (fix.covariance[3:5, 3:5].copy(), t)

    def prior(self, t: float) -> Pose | None:
        """The seed at ``t`` s: the filter's predicted position and covariance, the newest
        fix's direction with its variance grown by the turn (None before the first fix)."""
        if self.x is None:
            return None
        x, p = self._predicted(t)
        cov = np.zeros((5, 5))
        cov[:3, :3] = p[:3, :3]
        rot, t_rot = self.rot
        cov[3:, 3:] = rot + np.eye(2) * TURN_RMS_RAD_S ** 2 * (t - t_rot) ** 2
        return Pose(x[:3].copy(), self.moment.copy(), cov)


def filtered_seeds(trackers: list, seeds: list, fit, time_s: float) -> list:
    """Mode 'track': each magnet's :class:`FrameTracker` takes its frame-only measurement and
    predicts the next frame's seed (the identity hint until its first)."""
    out = []
    for k, (tr, m, s) in enumerate(zip(trackers, fit.magnets, seeds)):
        tr.update(m, fit.frame_positions_m[k], fit.frame_covariances_m2[k], time_s)
        nxt = tr.prior(time_s + FRAME_S)
        out.append(s if nxt is None else nxt)
    return out


def tracked_seeds(trackers: list, seeds: list, fit, time_s: float) -> list:
    """The runner's tracker (:class:`firmware_io.runner.tracker.PoseTracker`, one a magnet):
    each magnet's consistent fix (its pose covariance) is folded in, and its prediction at the
    next frame's time, with covariance, is that frame's seed; a magnet the tracker has no fix
    of keeps its identity hint."""
    out = []
    for tr, m, s in zip(trackers, fit.magnets, seeds):
        tr.update(m.position_m, time_s, bool(m.consistent), m.moment_a_m2, m.covariance)
        snap = tr.snapshot()
        out.append(s if snap is None else snap.prior(time_s + FRAME_S))
    return out


def run_layout(dev: Device, truth: dict, mode: str, seed: int) -> dict:
    """One layout in one mode: per-fix errors, levels and flags of both magnets."""
    rng = np.random.default_rng(seed)
    est = MagnetsEstimator(dev.model, [dev.design.magnet, dev.design.magnet])
    size = float(np.linalg.norm(dev.model.moment_a_m2))
    n_pairs, n_frames = truth["pos"].shape[:2]
    shape = (n_pairs, n_frames, 2)
    ok, err, pl, swapped = (np.zeros(shape, bool), np.full(shape, np.nan),
                            np.full(shape, np.inf), np.zeros(shape, bool))
    ts = np.empty((n_pairs, n_frames))
    for j in range(n_pairs):
        readings = pair_readings(dev, truth, j, rng)
        est.reset()
        seeds = hints(truth, j, size, rng)
        trackers = [PoseTracker(), PoseTracker()]
        filters = [FrameTracker(), FrameTracker()]
        for k in range(n_frames):
            if mode != "track":
                est.reset()
            if mode == "frame":
                seeds = hints(truth, j, size, rng) if k else seeds
            elif mode == "prior":
                seeds = true_priors(truth, j, k, size, rng)
            t0 = time.thread_time()
            fit = est.estimate(readings[k], truth["cur"][j], seeds=seeds)
            ts[j, k] = time.thread_time() - t0
            true = truth["pos"][j, k]
            for i, m in enumerate(fit.magnets):
                ok[j, k, i], pl[j, k, i] = m.ok, m.protection_level_m
                err[j, k, i] = np.linalg.norm(m.position_m - true[i])
                swapped[j, k, i] = (np.linalg.norm(m.position_m - true[1 - i])
                                    < err[j, k, i])
            if mode == "track":
                seeds = filtered_seeds(filters, seeds, fit, k * FRAME_S)
            elif mode == "runner":
                seeds = tracked_seeds(trackers, seeds, fit, k * FRAME_S)
    return {"ok": ok, "err": err, "pl": pl, "swapped": swapped, "ts": ts}


def summary(layout: str, mode: str, res: dict, crb: np.ndarray) -> dict:
    """Per magnet: the acceptance's numbers (module docstring)."""
    out = {"layout": layout, "mode": mode, "fixes": int(res["ok"][..., 0].size),
           "fix_ms_median": float(np.median(res["ts"]) * 1e3), "magnets": []}
    for i in range(2):
        ok, err, pl = res["ok"][..., i], res["err"][..., i], res["pl"][..., i]
        out["magnets"].append({
            "magnet": i, "availability": float(ok.mean()), "trusted": int(ok.sum()),
            "mae_trusted_mm": float(err[ok].mean() * 1e3) if ok.any() else None,
            "crb_mae_mm": float(np.mean(crb[:, i]) * 1e3),
            "crb_mae_median_mm": float(np.median(crb[:, i]) * 1e3),
            "trusted_above_5mm": int(np.sum(ok & (err > 5e-3))),
            "trusted_beyond_pl": int(np.sum(ok & (err > pl))),
            "trusted_swapped": int(np.sum(ok & res["swapped"][..., i])),
            "mae_all_mm": float(np.nanmean(err) * 1e3),
            "availability_first_last_quarter": [float(q.mean()) for q in (
                ok[:, :max(ok.shape[1] // 4, 1)], ok[:, -max(ok.shape[1] // 4, 1):])]})
    return out


def _fmt(x, f="{:.3f}"):
    return "-" if x is None else f.format(x)


def _lines(r: dict) -> list:
    return [f"{r['layout']:8s} {r['mode']:5s} magnet {m['magnet']} fixes {r['fixes']:6d} "
            f"avail {m['availability']:.3f} MAE {_fmt(m['mae_trusted_mm'])} mm CRB "
            f"{m['crb_mae_mm']:.3f} (median {m['crb_mae_median_mm']:.3f}) mm >5 mm "
            f"{m['trusted_above_5mm']} beyond PL {m['trusted_beyond_pl']} swapped "
            f"{m['trusted_swapped']} (all fixes' MAE {m['mae_all_mm']:.2f} mm) avail first/last "
            f"quarter {m['availability_first_last_quarter'][0]:.3f}/"
            f"{m['availability_first_last_quarter'][1]:.3f} fix {r['fix_ms_median']:.1f} ms"
            for m in r["magnets"]]


def _table(res: dict) -> str:
    lines = [f"two magnets: {res['pairs']} pairs x {res['frames']} frames per layout and mode, "
             f"noise {NOISE_T * 1e3:.3g} mT, currents +-{CURRENT_A:g} A, load "
             f"{_fmt(res['load_average'], '{:.1f}')}",
             "layout mode magnet: fixes, availability (ok), MAE of the trusted fixes, the mean "
             "(median) one-frame Cramer-Rao bound MAE, trusted > 5 mm off, trusted beyond their "
             "protection level, trusted fixes nearer the other magnet (identity swaps), the MAE "
             "of all fixes, availability in the first and last quarter of each pair's frames, "
             "median fix CPU time"]
    for r in res["rows"]:
        lines += _lines(r)
    return "\n".join(lines)


def run(out_dir=DEFAULT_OUT, n_pairs: int = 10, n_frames: int = 200, seed: int = 0,
        layouts=LAYOUTS, modes=MODES, planned=None) -> dict:
    """The study (module docstring); returns its numbers (also written as JSON)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    designs = {"thesis": default_design()}
    if planned is not None:
        designs["planned"] = load_design(planned)
    rows = []
    for name in layouts:
        dev = device(designs[name])
        truth = pair_tracks(dev, n_pairs, n_frames, np.random.default_rng(seed + 1))
        crb = np.array([crb_mae(dev, truth["pos"][j, 0], truth["dirs"][j])
                        for j in range(n_pairs)])
        for mode in modes:
            rows.append(summary(name, mode, run_layout(dev, truth, mode, seed + 7), crb))
            print("\n".join(_lines(rows[-1])), flush=True)
    res = {"pairs": n_pairs, "frames": n_frames, "seed": seed, "planned": str(planned),
           "rows": rows, "load_average": load_average()}
    (out / "magnets_localization.txt").write_text(_table(res) + "\n")
    return finish(out / "magnets_localization.json", res, lambda r: print(_table(r)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=str(DEFAULT_OUT), help="output folder")
    ap.add_argument("--n", type=int, default=10, help="pairs per layout (each --frames frames)")
    ap.add_argument("--frames", type=int, default=200, help="frames per pair (2 ms apart)")
    ap.add_argument("--full", action="store_true", help="10 000 fixes per layout and mode "
                    "(50 pairs x 200 frames; the acceptance run)")
    ap.add_argument("--planned", default=None, help="design file of the planned layout "
                    "(designkit sensors plan --magnets 2 writes OUT/design.toml)")
    ap.add_argument("--layouts", default=None, help="subset of: " + ", ".join(LAYOUTS)
                    + " (default: both when --planned is given, else thesis)")
    ap.add_argument("--modes", default=",".join(MODES), help="subset of: " + ", ".join(MODES))
    ap.add_argument("--seed", type=int, default=0, help="truth and noise seed (>= 0)")
    a = ap.parse_args(argv)
    layouts = tuple(x.strip() for x in (a.layouts or ("thesis,planned" if a.planned else
                                                      "thesis")).split(",") if x.strip())
    modes = tuple(x.strip() for x in a.modes.split(",") if x.strip())
    n_pairs = 50 if a.full else a.n
    bad = [x for x in layouts if x not in LAYOUTS] + [m for m in modes if m not in MODES]
    if bad or n_pairs < 1 or a.frames < 1 or a.seed < 0 or (
            "planned" in layouts and not (a.planned and Path(a.planned).is_file())):
        print(f"error: --layouts/--modes {bad}, --n {n_pairs}, --frames {a.frames}, --seed "
              f"{a.seed}, --planned {a.planned}: layouts from {LAYOUTS} ('planned' needs "
              f"--planned FILE, an existing design file), modes from {MODES}, n, frames >= 1, "
              f"seed >= 0", file=sys.stderr)
        return 2
    return run_interruptible(run, a.out, n_pairs, 200 if a.full else a.frames, a.seed, layouts,
                             modes, a.planned)


if __name__ == "__main__":
    sys.exit(main())
