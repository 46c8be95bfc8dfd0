"""Field measurements for the calibration: the CSV file, its checks, simulated plans.

CSV columns (any order, all required but ``sigma_t``): ``x_m, y_m, z_m`` (the reading's point,
m, array frame), ``i1_a ... iN_a`` (the coils' currents in the design's coil order, A),
``bx_t, by_t, bz_t`` (the 3-axis reading in the array frame, T: an onboard chip's reading
turned by its frame, :meth:`Design.sensor_poses`), ``sigma_t`` (its noise per axis, T; default
:data:`DEFAULT_SIGMA_T`). Each row is one reading at a point with those currents; a row may
come from the onboard Hall arrays (the start-up calibration drives each coil and reads them)
or from a probe. Readings must be below the sensors' range (``design.sensors.range_t``).

Plans (:func:`onboard_plan`, :func:`probe_plan`) give points, currents and noise; :func:`simulate`
fills the readings from a device's exact model with Gaussian noise (``designkit calibrate
--simulate``).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import BadInputError

DEFAULT_SIGMA_T = 5e-5
"""Reading noise when the file has no ``sigma_t`` column, T (an onboard TLV493D average)."""
ONBOARD_TOLERANCE_M = 1e-3
"""A reading this close to a nominal Hall-sensor position counts as an onboard reading, m."""


@dataclass(frozen=True)
class Measurements:
    """Readings: points (n, 3) m, currents (n, n_coils) A, b (n, 3) T, sigma (n,) T."""

    points_m: np.ndarray
    currents_a: np.ndarray
    b_t: np.ndarray
    sigma_t: np.ndarray

    def __len__(self) -> int:
        return len(self.points_m)

    def concat(self, other: "Measurements") -> "Measurements":
        return Measurements(*(np.concatenate([a, b]) for a, b in
                              zip(self.fields(), other.fields())))

    def fields(self):
        return self.points_m, self.currents_a, self.b_t, self.sigma_t

    def unique_points(self):
        """(unique points (m, 3), index of each row's point (n,))."""
        key = np.round(self.points_m, 9)
        uniq, inverse = np.unique(key, axis=0, return_inverse=True)
        return uniq, inverse.ravel()

    def groups(self, sensor_positions_m, sensor_groups) -> np.ndarray:
        """Each row's group (n,) str: the group of the onboard sensor it was read at
        (``sensor_groups`` (n_sensors,), e.g. :func:`sensor_groups`), else 'probe'.
        ``sensor_positions_m``: (n_sensors, 3) m."""
        out = np.full(len(self), "probe", dtype=object)
        pos = np.asarray(sensor_positions_m, dtype=float).reshape(-1, 3)
        d = np.linalg.norm(self.points_m[:, None, :] - pos[None], axis=-1)
        near = d.min(axis=1) < ONBOARD_TOLERANCE_M
        out[near] = np.asarray(sensor_groups, dtype=object)[d.argmin(axis=1)[near]]
        return out


def read_csv(path, n_coils: int, range_t: float, *, readings: bool = True,
             option: str = "--measurements") -> Measurements:
    """Read and check a measurement file; every error names the column or the row.
    ``readings=False``: a plan (points, currents, sigma_t): bx/by/bz may be absent and are
    read as 0. ``option``: the command-line option the file came from (for the errors)."""
    path = Path(path)
    if not path.is_file():
        raise BadInputError(option, "an existing CSV file", str(path))
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise BadInputError(option, "a CSV file with a header row", str(path))
    header = [h.strip() for h in rows[0]]
    currents = [h for h in header if h.startswith("i") and h.endswith("_a")]
    if len(currents) != n_coils:
        raise BadInputError(f"{path.name}: current columns",
                            f"{n_coils} (i1_a ... i{n_coils}_a, one per coil of the design)",
                            len(currents))
    b_cols = ["bx_t", "by_t", "bz_t"]
    required = ["x_m", "y_m", "z_m"] + [f"i{k + 1}_a" for k in range(n_coils)] + (
        b_cols if readings else [])
    for name in required:
        if name not in header:
            raise BadInputError(f"{path.name}: column {name}", "present", "missing")
    extra = [h for h in header if h not in required + b_cols + ["sigma_t"]]
    if extra or len(set(header)) != len(header):
        bad = extra[0] if extra else next(h for h in header if header.count(h) > 1)
        raise BadInputError(f"{path.name}: column {bad}",
                            f"one of {required[:4]}..., bx_t, by_t, bz_t, sigma_t, once each",
                            "extra" if extra else "repeated")
    data = np.empty((len(rows) - 1, len(header)))
    for r, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise BadInputError(f"{path.name}: row {r}", f"{len(header)} values", len(row))
        for c, (name, text) in enumerate(zip(header, row)):
            try:
                data[r - 2, c] = float(text)
            except ValueError:
                raise BadInputError(f"{path.name}: row {r}, column {name}", "a number",
                                    text) from None
            if not math.isfinite(data[r - 2, c]):
                raise BadInputError(f"{path.name}: row {r}, column {name}", "finite", text)
    if len(data) == 0:
        raise BadInputError(option, "at least one data row", str(path))
    col = {h: data[:, k] for k, h in enumerate(header)}
    sigma = col.get("sigma_t", np.full(len(data), DEFAULT_SIGMA_T))
    for r, s in enumerate(sigma, start=2):
        if not s > 0:
            raise BadInputError(f"{path.name}: row {r}, column sigma_t", "> 0 T", s)
    zero = np.zeros(len(data))
    b = np.c_[tuple(col.get(c, zero) if not readings else col[c] for c in b_cols)]
    clipped = np.flatnonzero((np.abs(b) >= range_t * (1 - 1e-9)).any(axis=1))
    if readings and len(clipped):
        raise BadInputError(f"{path.name}: row {clipped[0] + 2}, columns bx_t/by_t/bz_t",
                            f"below the sensor range {range_t:g} T (a reading at the range "
                            "is clipped)", b[clipped[0]].tolist())
    return Measurements(np.c_[col["x_m"], col["y_m"], col["z_m"]],
                        np.column_stack([col[f"i{k + 1}_a"] for k in range(n_coils)]),
                        b, np.asarray(sigma, dtype=float))


def write_csv(path, meas: Measurements, readings: bool = True) -> None:
    """Write a measurement file (``readings=False``: a plan, without bx/by/bz)."""
    nc = meas.currents_a.shape[1]
    head = ["x_m", "y_m", "z_m"] + [f"i{k + 1}_a" for k in range(nc)]
    head += (["bx_t", "by_t", "bz_t"] if readings else []) + ["sigma_t"]
    with Path(path).open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(head)
        for k in range(len(meas)):
            row = list(meas.points_m[k]) + list(meas.currents_a[k])
            row += list(meas.b_t[k]) if readings else []
            w.writerow([f"{x:.9g}" for x in row + [meas.sigma_t[k]]])


def _each_coil(points, n_coils, currents, sigma):
    """Every point read with each coil alone at each current in ``currents``."""
    pts, cur = [], []
    for i in currents:
        for k in range(n_coils):
            drive = np.zeros(n_coils)
            drive[k] = i
            pts.append(points)
            cur.append(np.repeat(drive[None], len(points), axis=0))
    pts, cur = np.concatenate(pts), np.concatenate(cur)
    return Measurements(pts, cur, np.zeros_like(pts), np.full(len(pts), float(sigma)))


def sensor_groups(design) -> list[str]:
    """The group of each of the design's sensors (:meth:`Design.sensor_poses` order):
    'onboard-upper' then 'onboard-lower' for the default layout (one above, one below each
    coil), 'onboard' for a free sensor layout."""
    n = len(design.sensor_poses()[0])
    if design.sensors.layout == "free":
        return ["onboard"] * n
    return ["onboard-upper"] * (n // 2) + ["onboard-lower"] * (n - n // 2)


def onboard_plan(sensor_positions_m, n_coils, current_a=2.0, sigma_t=5e-5) -> Measurements:
    """The onboard sensors (n_sensors, 3) m (any shape ending in 3), each coil alone at
    +-``current_a``."""
    return _each_coil(np.asarray(sensor_positions_m).reshape(-1, 3), n_coils,
                      (current_a, -current_a), sigma_t)


def probe_plan(points_m, n_coils, current_a=1.0, sigma_t=2e-5) -> Measurements:
    """A probe at ``points_m`` (n, 3) m, each coil alone at ``current_a``."""
    return _each_coil(np.asarray(points_m, dtype=float), n_coils, (current_a,), sigma_t)


def workspace_points(design, n: int, rng) -> np.ndarray:
    """``n`` uniform random points in the design's workspace region
    (:meth:`Design.workspace_region`: its bounding box, the points outside the outline drawn
    again), (n, 3) m."""
    region = design.workspace_region()
    lo, hi = region.bounds_m()
    out = rng.uniform(lo, hi, size=(n, 3))
    inside = region.contains(out)
    while not inside.all():
        out[~inside] = rng.uniform(lo, hi, size=(int((~inside).sum()), 3))
        inside = region.contains(out)
    return out


def simulate(array, meas: Measurements, rng) -> Measurements:
    """The plan's readings from ``array``'s exact model plus Gaussian noise (sigma per row)."""
    uniq, inv = meas.unique_points()
    b_cols = array.actuation_matrix(uniq)[:, :3, :]
    b = np.einsum("nik,nk->ni", b_cols[inv], meas.currents_a)
    b = b + rng.normal(size=b.shape) * meas.sigma_t[:, None]
    return Measurements(meas.points_m, meas.currents_a, b, meas.sigma_t)
