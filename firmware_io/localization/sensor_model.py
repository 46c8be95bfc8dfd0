"""What the estimators know about the sensors and the magnet (the v2 map's sensor section):
:class:`SensorModel`.

A flat list of sensors, any layout: each sensor's nominal position (m) and orientation (its
axes as the columns of a rotation, array frame: a reading is R^T B), the coils' field and
gradient there per ampere (array frame, T/A, T/(m A)); the magnet (moment A m^2, multipole
ratio m^2, cylinder size m); the field of the cores the magnet magnetizes (a callable of the
position and the moment, linear in the moment); optionally the (upper, lower) sensor pairs of
the thesis' subtraction.
:data:`DEFAULT_NOISE_T` is the TLV493D datasheet's noise per axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import BadInputError
from ..mapfile import MapFile
from .magnet import MU0, multipole_field

DEFAULT_NOISE_T = 0.1e-3
"""TLV493D noise per axis, T rms (datasheet)."""


def stacked_pairs(positions_m: np.ndarray, tol_m: float = 1e-3) -> np.ndarray | None:
    """(k, 2) index pairs (upper, lower) of sensors stacked on one vertical line (x, y within
    ``tol_m``), one pair per line with exactly two sensors, the upper first; None when no
    sensor has a partner (the subtraction needs them)."""
    pts = np.asarray(positions_m, float)
    pairs, used = [], set()
    for i in np.argsort(-pts[:, 2]):
        if i in used:
            continue
        same = [j for j in range(len(pts)) if np.all(np.abs(pts[j, :2] - pts[i, :2]) <= tol_m)]
        if len(same) == 2:
            lower = same[0] if same[1] == i else same[1]
            pairs.append((int(i), int(lower)))
            used.update(same)
    return np.array(sorted(pairs), int) if pairs else None


def induced_from_map(mapfile: MapFile, lo, hi, n: int):
    """The map's magnet-induced field at the sensors per unit moment (``SensorModel.induced``).
    The map stores it for its own moment m0, as m . B of per-sensor adjoint fields (linear in
    m), so copies of its sensor section with the moment along two axes perpendicular to m0 give
    the rest of the basis (built when first asked for: a fit that keeps the direction never
    needs them). Outside the map's box [lo, hi] the nearest box point is used (a small
    correction: safer than extrapolating its polynomials)."""
    m0 = np.asarray(mapfile.moment_a_m2, float)
    size = float(np.linalg.norm(m0))
    frame = np.c_[m0 / size, _perpendicular(m0 / size)]        # (3, 3): u0, e1, e2
    maps = [mapfile]

    def along(k, q):
        if k >= len(maps):
            for axis in frame[:, len(maps):].T:
                arrays = dict(mapfile.arrays)
                arrays["MOMENT"] = axis * size
                maps.append(MapFile.from_arrays(arrays, mapfile.meta))
        return maps[k].sensor_induced_field(q).reshape(len(q), n, 3) / size

    def induced(positions, directions):
        q = np.clip(np.asarray(positions, float).reshape(-1, 3), lo, hi)
        coef = frame.T @ directions                        # directions in (u0, e1, e2)
        need = [k for k in range(3) if np.any(np.abs(coef[k]) > 1e-12)]
        out = np.zeros((len(q), n, 3, directions.shape[1]))
        for k in need:
            out += along(k, q)[..., None] * coef[k]
        return out

    return induced


def _perpendicular(u: np.ndarray) -> np.ndarray:
    """(3, 2): two unit vectors perpendicular to the unit vector u and to each other."""
    helper = np.eye(3)[int(np.argmin(np.abs(u)))]
    e1 = np.cross(helper, u)
    e1 /= np.linalg.norm(e1)
    return np.c_[e1, np.cross(u, e1)]


@dataclass
class SensorModel:
    """What the estimators know (the v2 map's sensor section), n sensors in a flat list.

    sensor_positions_m : (n, 3) m (the default layout: the upper array, then the lower)
    coil_field_t_per_a : (n, 3, n_coils) T/A, the coils' field at the sensors per ampere
    moment_a_m2 : (3,) A m^2
    design_sha256 : str
    octupole_m2 : float, m^2 (0 = pure dipole)
    induced : callable, or None: the field of the magnet-magnetized cores at the sensors per
        unit moment, ``induced(positions (k, 3) m, directions (3, d))`` -> (k, n, 3, d)
        T/(A m^2) (column j: a unit moment along directions[:, j]; linear cores: the field of
        a moment m is the basis of the three axes times m)
    box_lower_m, box_upper_m : (3,) plausible magnet positions (outside: ok = False); default
        25 mm beyond the sensors' footprint, from 2 to 150 mm above the highest sensor
    magnet_size_m : (radius, length) m of the cylinder magnet, or None. Given, the fits use its
        exact field (:func:`cylinder_field`; the multipole with its analytic Jacobian carries
        the iterations, the difference enters as a per-frame linearized correction).
    coil_gradient_t_per_a_m : (n, 3, 3, n_coils) T/(m A) or None: the coils' field gradient
        at the sensors (entry [s, i, j] = dB_i/dx_j), for :func:`calibrate` to recover the
        sensors' position errors; ``gradient_known`` (n,) bool says where it is known.
    coil_rows : callable (k, 3) m -> (k, 8, n_coils), or None: the coils' field and gradient
        rows (Bx, By, Bz, dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz per ampere) at any point where
        ``gradient_known``; given, :func:`calibrate` uses the exact field at the shifted
        position, else its linearization C(p + d) = C(p) + grad C d.
    sensor_orientations : (n, 3, 3) or None (identity): each sensor's axes as columns, array
        frame (a reading is R^T B)
    pairs : (k, 2) int or None: (upper, lower) sensor indices for the subtraction ('dipole');
        None: :func:`stacked_pairs` of the positions
    """

    sensor_positions_m: np.ndarray
    coil_field_t_per_a: np.ndarray
    moment_a_m2: np.ndarray
    design_sha256: str
    octupole_m2: float = 0.0
    induced: Callable[[np.ndarray], np.ndarray] | None = None
    box_lower_m: np.ndarray | None = None
    box_upper_m: np.ndarray | None = None
    magnet_size_m: tuple | None = None
    coil_gradient_t_per_a_m: np.ndarray | None = None
    gradient_known: np.ndarray | None = None
    coil_rows: Callable[[np.ndarray], np.ndarray] | None = None
    sensor_orientations: np.ndarray | None = None
    pairs: np.ndarray | None = None

    def __post_init__(self):
        sp = np.asarray(self.sensor_positions_m, dtype=float)
        if sp.ndim != 2 or sp.shape[1] != 3 or len(sp) < 3 or not np.all(np.isfinite(sp)):
            raise BadInputError("sensor_positions_m", "finite, shape (n_sensors >= 3, 3), m",
                                f"shape {sp.shape}")
        n = len(sp)
        cf = np.asarray(self.coil_field_t_per_a, dtype=float)
        if cf.ndim != 3 or cf.shape[:2] != (n, 3) or not np.all(np.isfinite(cf)):
            raise BadInputError("coil_field_t_per_a", f"finite, shape ({n}, 3, n_coils), T/A",
                                f"shape {cf.shape}")
        m = np.asarray(self.moment_a_m2, dtype=float)
        if m.shape != (3,) or not np.all(np.isfinite(m)) or not np.linalg.norm(m) > 0:
            raise BadInputError("moment_a_m2", "a finite non-zero 3-vector, A m^2", m.tolist())
        self.sensor_positions_m, self.coil_field_t_per_a, self.moment_a_m2 = sp, cf, m
        self._check_orientations(n)
        if self.magnet_size_m is not None:
            size = tuple(float(x) for x in self.magnet_size_m)
            if len(size) != 2 or not all(math.isfinite(x) and x > 0 for x in size):
                raise BadInputError("magnet_size_m", "(radius, length) > 0, m", self.magnet_size_m)
            self.magnet_size_m = size
        if self.coil_gradient_t_per_a_m is not None:
            g = np.asarray(self.coil_gradient_t_per_a_m, dtype=float)
            if g.shape != (n, 3, 3, cf.shape[2]) or not np.all(np.isfinite(g)):
                raise BadInputError("coil_gradient_t_per_a_m", f"finite, shape ({n}, 3, 3, "
                                    f"{cf.shape[2]}), T/(m A)", f"shape {g.shape}")
            self.coil_gradient_t_per_a_m = g
            k = (np.ones(n, bool) if self.gradient_known is None
                 else np.asarray(self.gradient_known, bool))
            if k.shape != (n,):
                raise BadInputError("gradient_known", f"bool, shape ({n},)", f"shape {k.shape}")
            self.gradient_known = k
        if self.box_lower_m is None:
            xy = np.abs(sp[:, :2]).max()
            top = sp[:, 2].max()
            self.box_lower_m = np.array([-xy - 0.025, -xy - 0.025, top + 0.002])
            self.box_upper_m = np.array([xy + 0.025, xy + 0.025, top + 0.15])
        self.pairs = stacked_pairs(sp) if self.pairs is None else self._checked_pairs(n)

    def _check_orientations(self, n: int) -> None:
        if self.sensor_orientations is None:
            self.sensor_orientations = np.tile(np.eye(3), (n, 1, 1))
            return
        r = np.asarray(self.sensor_orientations, float)
        if (r.shape != (n, 3, 3) or not np.all(np.isfinite(r))
                or np.abs(np.einsum("sji,sjk->sik", r, r) - np.eye(3)).max() > 1e-6):
            raise BadInputError("sensor_orientations", f"rotations, shape ({n}, 3, 3)",
                                f"shape {r.shape}")
        self.sensor_orientations = r

    def _checked_pairs(self, n: int) -> np.ndarray:
        p = np.asarray(self.pairs)
        if p.ndim != 2 or p.shape[1] != 2 or not np.issubdtype(p.dtype, np.integer) \
                or p.min() < 0 or p.max() >= n:
            raise BadInputError("pairs", f"(k, 2) sensor indices in [0, {n})", f"{p.tolist()}")
        return p

    @classmethod
    def from_operator(cls, *, induced_samples_m, induced_operator, **kw) -> "SensorModel":
        """Induced field as a linear operator on the magnet's applied H_z at sample points
        (designkit.sim.readings.InducedCoreModel), the applied field the magnet's dipole (per
        unit moment; the l = 3 term changes H_z at the cores, >= 20 mm away, by < 2 %)."""
        # the sample points component-major (3, S): the long axis innermost in every product
        samples = np.ascontiguousarray(np.asarray(induced_samples_m, float).T)
        op = np.asarray(induced_operator, float)
        model = cls(**kw)
        n = model.n_sensors

        def induced(positions, directions):
            r = samples[None] - np.asarray(positions, float)[:, :, None]    # (k, 3, S)
            inv2 = 1.0 / np.einsum("kis,kis->ks", r, r)
            inv3 = inv2 * np.sqrt(inv2) * (1.0 / (4 * math.pi))
            # H_z of a unit dipole along axis j: (3 r_z r_j / r^5 - delta_zj / r^3) / (4 pi)
            hz = (3.0 * inv3 * inv2 * r[:, 2])[:, None, :] * r
            hz[:, 2] -= inv3
            k, d = len(r), directions.shape[1]
            h = np.swapaxes(directions, 0, 1) @ hz                          # (k, d, S)
            # one product for every position and direction: op (3 n, S) @ (S, k d)
            out = op @ h.reshape(k * d, -1).T
            return out.reshape(n, 3, k, d).transpose(2, 0, 1, 3)

        model.induced = induced
        return model

    @classmethod
    def from_map(cls, path, *, expected_design_sha256: str | None = None,
                 octupole_m2: float | None = None, magnet_size_m=None) -> "SensorModel":
        """From a map file's sensor section: its flat sensor list in the map's order, each
        sensor's position and rotation (``SENSOR_POS``, ``SENSOR_ROT``).

        ``magnet_size_m``: (radius, length) m of the cylinder magnet -> its exact field; default
        the map's ``meta['magnet_radius_m']``, ``meta['magnet_length_m']`` if it has them.
        ``octupole_m2``: the magnet's l = 3 coefficient ratio h^2 - 3 a^2 / 4 (m^2); default from
        the magnet's size, else the map's ``meta['magnet_octupole_m2']``, else 0 (pure dipole).
        """
        m = MapFile.load(path, expected_design_sha256=expected_design_sha256)
        sp = np.asarray(m.sensor_positions_m, float).reshape(-1, 3)
        lo, hi = (np.asarray(b, float) for b in m.bounds)
        # plausible positions: the map's box widened (the magnet model is analytic; outside the
        # box the runner fails safe on its own 'out_of_box' test), never below the top sensor
        box_lo = lo - [0.015, 0.015, 0.0]
        box_hi = hi + [0.015, 0.015, 0.02]
        box_lo[2] = max(lo[2], float(sp[:, 2].max()) + 0.002)
        if magnet_size_m is None and "magnet_radius_m" in m.meta and "magnet_length_m" in m.meta:
            magnet_size_m = (m.meta["magnet_radius_m"], m.meta["magnet_length_m"])
        if octupole_m2 is None:
            if magnet_size_m is not None:
                a, length = (float(x) for x in magnet_size_m)
                octupole_m2 = (length / 2) ** 2 - 0.75 * a * a
            else:
                octupole_m2 = float(m.meta.get("magnet_octupole_m2", 0.0))
        nc = m.n_coils
        induced = induced_from_map(m, lo, hi, len(sp))
        # the coils' field gradient at every sensor (the map's SENSOR_COIL_GRAD: the sensors sit
        # below the box of A) for calibrate() to recover their position errors
        grad = np.asarray(m.sensor_coil_gradient(), float).reshape(-1, 3, 3, nc)
        return cls(sp, np.asarray(m.sensor_coil_field(), float).reshape(-1, 3, nc),
                   np.asarray(m.moment_a_m2, float), str(m.design_sha256), float(octupole_m2),
                   induced, box_lo, box_hi, magnet_size_m, grad, np.ones(len(sp), bool),
                   sensor_orientations=np.asarray(m.sensor_rotations, float))

    def induced_field(self, position_m, moment_a_m2=None) -> np.ndarray:
        """(n, 3) T: the cores' field at the sensors for the magnet at ``position_m`` (3,) m with
        ``moment_a_m2`` (3,) A m^2 (default: the model's); zeros without a core model."""
        m = self.moment_a_m2 if moment_a_m2 is None else np.asarray(moment_a_m2, float)
        if self.induced is None:
            return np.zeros((self.n_sensors, 3))
        size = float(np.linalg.norm(m))
        p = np.asarray(position_m, float)[None]
        return size * self.induced(p, (m / size)[:, None])[0, ..., 0]

    @property
    def n_sensors(self) -> int:
        return len(self.sensor_positions_m)

    @property
    def n_coils(self) -> int:
        return self.coil_field_t_per_a.shape[2]
