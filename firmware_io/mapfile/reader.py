"""The map file as the controller reads it: :class:`MapFile` (numpy only).

``MapFile.load(path)`` reads and validates a map (:mod:`.format`) and prepares its lookups
once: A(p) from the harmonic cells (:mod:`.cells`), the bias force F0(p) from the per-core
magnet tables plus a trilinear residual grid (:mod:`.modes`, :mod:`.grid`), the magnet-induced
field at the Hall sensors from the core modes (:mod:`.modes`). It satisfies
:class:`firmware_io.actuation.ActuationSource`. Points in m; A in T/A and T/(m A), rows
:data:`ROWS`; forces in N; fields in T.

Usage::

    m = MapFile.load("fieldmap.npz")
    a = m.actuation((0.0, 0.0, 0.03))            # (8, n_coils)
    f0 = m.bias_force((0.0, 0.0, 0.03))          # (3,) N
    b = m.sensor_induced_field((0.0, 0.0, 0.03))  # (n_sensors, 3) T
    a = m.actuation(points, rows=(3, 6), coils=(0, 4))  # (n, 2, 2): only those entries
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import BadInputError
from .cells import CELL_CHUNK, cells_many, cells_one, prepare_cells
from .format import REBUILD, map_error, read
from .grid import trilinear, trilinear_one
from .saturation import SaturationTable
from .modes import (BATCH_CHUNK, gradient_tensor, kernel_rows_many, magnet_terms,
                    magnet_terms_one, mode_rows, modes_one, prepare_magnet, prepare_magnet_one,
                    prepare_modes, prepare_one)
from .source import selection

def check_currents(currents, n_coils: int, error=BadInputError) -> np.ndarray:
    """``currents`` as a float array (n_coils,) A, or ``error`` (an InputRangeError class: the
    caller's own, e.g. designkit's BadInputError) naming the parameter and the shape."""
    i = np.asarray(currents, dtype=float)
    if i.shape != (n_coils,) or not np.all(np.isfinite(i)):
        raise error("currents", f"{n_coils} finite values, A", f"shape {i.shape}")
    return i


@dataclass(frozen=True, eq=False)
class MapFile:
    """A validated map file (what each part means: docs/mapfile_format.md).

    Attributes: ``meta`` (dict), ``bounds`` ((lower, upper) corners of the box, m), ``n_coils``,
    ``n_sensors``, ``sensor_positions_m`` (n_sensors, 3), ``sensor_rotations`` (n_sensors, 3,
    3), ``moment_a_m2`` (3,), ``design_sha256``, ``max_current_a`` (per coil),
    ``total_current_a`` (sum of |I|), ``arrays`` (the raw arrays). The sensors are a flat list
    in the map's order (the default layout: the upper array's sensors in coil order, then the
    lower array's); every field at a sensor is in the array frame.
    """

    arrays: dict
    meta: dict
    bounds: tuple
    n_coils: int
    kernels: dict = field(repr=False)
    """The prepared lookups: 'cells' (A, :func:`prepare_cells`), 'scoef', 'magnet',
    'magnet_f0', the one-point kernels 'sensor_one', 'magnet_one' (None where the general
    path runs) and 'saturation' (:class:`SaturationTable`)."""

    @classmethod
    def load(cls, path, expected_design_sha256: str | None = None) -> "MapFile":
        """Read and validate ``path``; with ``expected_design_sha256``, refuse another
        design's map."""
        arrays, meta = read(path)
        if expected_design_sha256 is not None and meta["design_sha256"] != expected_design_sha256:
            raise map_error(path, f"built from the design with SHA-256 {expected_design_sha256[:12]}"
                       f"...; this one is from design {meta.get('design_name')!r} "
                       f"({meta['design_sha256'][:12]}...)", REBUILD)
        return cls.from_arrays(arrays, meta)

    @classmethod
    def from_arrays(cls, arrays: dict, meta: dict) -> "MapFile":
        """A MapFile from already validated arrays (what :func:`read` returns)."""
        nc = int(meta["n_coils"])
        layers = meta["a_layers"]
        cells = prepare_cells(layers, [arrays[lay["name"]] for lay in layers], nc)
        stabs = meta["sensor_mode_tables"]
        smodes = prepare_modes([arrays[t["name"]] for t in stabs], stabs,
                               meta["coil_positions_m"], meta["coil_rotations"])
        sc = arrays["SCOEF"]
        n3 = 3 * int(meta["n_sensors"])
        scoefs = tuple((t, np.ascontiguousarray(sc[t["idx"]][:, t["order"]]
                                                .reshape(-1, n3))) for t in smodes)
        maxes = tuple(np.asarray(arrays[k], float) for k in ("M_X", "M_Y", "M_Z"))
        f0 = arrays["F0_RES"]
        mt = meta["magnet_tables"]
        magnet = prepare_magnet([arrays[t["name"]] for t in mt], mt, meta["coil_positions_m"],
                                meta["coil_rotations"])
        g = meta["box_m"]
        kernels = {
            "cells": cells, "scoef": scoefs,
            "magnet": tuple(magnet),
            "magnet_f0": (maxes, np.ascontiguousarray(f0.reshape(-1, 3)), f0.shape[:3]),
            "sensor_one": (prepare_one(smodes, tuple(c for _, c in scoefs), arrays["MOMENT"])
                           if smodes else None),
            "magnet_one": prepare_magnet_one(magnet),
            "saturation": SaturationTable(arrays["SAT_I"], arrays["SAT_FACTOR"])}
        return cls(arrays, meta, (np.asarray(g[0], float), np.asarray(g[1], float)), nc,
                   kernels)

    # ------------------------------------------------------------------ plain attributes
    @property
    def n_sensors(self) -> int:
        """Number of Hall sensors the map describes (independent of the coil count)."""
        return len(self.arrays["SENSOR_POS"])

    @property
    def sensor_positions_m(self) -> np.ndarray:
        """(n_sensors, 3) m: the sensors' centres in the map's sensor order."""
        return self.arrays["SENSOR_POS"].copy()

    @property
    def sensor_rotations(self) -> np.ndarray:
        """(n_sensors, 3, 3): each sensor's rotation, sensor frame -> array frame (a field b
        in the array frame reads ``R.T @ b`` on the sensor's axes)."""
        return self.arrays["SENSOR_ROT"].copy()

    @property
    def moment_a_m2(self) -> np.ndarray:
        """The finger magnet's moment (3,) A m^2 the map's bias force was computed for."""
        return self.arrays["MOMENT"].copy()

    @property
    def design_sha256(self) -> str:
        return self.meta["design_sha256"]

    @property
    def max_current_a(self) -> float:
        """Per-coil current limit, A."""
        return float(self.meta["max_current_a"])

    @property
    def total_current_a(self) -> float:
        """Budget on the sum of |I_k| over the coils, A."""
        return float(self.meta["total_current_a"])

    # ------------------------------------------------------------------ point checks
    def _points(self, points, extrapolate: bool, name: str = "points"):
        """(p (n, 3) float64, single) after the shape, finiteness and box checks."""
        p = np.asarray(points, dtype=float)
        single = p.ndim == 1
        if p.shape[-1:] != (3,) or p.ndim > 2:
            raise BadInputError(name, "array-like of shape (3,) or (n, 3), m",
                                f"shape {p.shape}")
        p = p.reshape(-1, 3)
        # per-column extremes first (NaN propagates into them; one reduction per column: numpy's
        # p.min(axis=0) over (n, 3) is ~20x slower): the row-wise search below runs only for a
        # bad input
        if not len(p):
            return p, single
        p_min = [p[:, k].min() for k in range(3)]
        p_max = [p[:, k].max() for k in range(3)]
        if not all(math.isfinite(v) for v in p_min + p_max):
            raise BadInputError(name, "finite (no NaN or Inf)", p.tolist()[:3])
        lo, hi = self.bounds
        tol = 1e-9
        box_lo, box_hi = self._box_lists
        if not extrapolate and (any(v < b for v, b in zip(p_min, box_lo))
                                or any(v > b for v, b in zip(p_max, box_hi))):
            bad = np.any((p < lo - tol) | (p > hi + tol), axis=1)
            if bad.any():
                k = int(np.argmax(bad))
                raise BadInputError(name, f"inside the map box {lo.tolist()} .. {hi.tolist()} m"
                                    " (or extrapolate=True)", f"{p[k].tolist()} at row {k}")
        return p, single

    def _one_point(self, points, extrapolate: bool, name: str = "points"):
        """Three Python floats, or None when ``points`` is not one point."""
        try:
            arr = np.asarray(points, dtype=float)
        except (TypeError, ValueError):
            raise BadInputError(name, "array-like of shape (3,) or (n, 3), m",
                                points) from None
        if arr.shape != (3,) and arr.shape != (1, 3):
            return None
        q = arr.reshape(3).tolist()
        lo, hi = self._box_lists
        for k in range(3):
            if not math.isfinite(q[k]):
                raise BadInputError(name, "finite (no NaN or Inf)", q)
            if not extrapolate and not (lo[k] <= q[k] <= hi[k]):
                raise BadInputError(name, f"inside the map box {self.bounds[0].tolist()} .. "
                                    f"{self.bounds[1].tolist()} m (or extrapolate=True)", q)
        return q

    @property
    def _box_lists(self) -> tuple:
        """The box corners as Python floats widened by the 1e-9 m tolerance."""
        got = self.__dict__.get("_box_cache")
        if got is None:
            got = ([float(v) - 1e-9 for v in self.bounds[0]],
                   [float(v) + 1e-9 for v in self.bounds[1]])
            object.__setattr__(self, "_box_cache", got)
        return got

    # ------------------------------------------------------------------ the interpolators
    def actuation(self, points, extrapolate: bool = False, *, rows=None,
                  coils=None) -> np.ndarray:
        """The coupled A at points (3,) -> (8, n_coils) or (n, 3) -> (n, 8, n_coils), float64.

        Rows :data:`ROWS`, T/A and T/(m A). Outside the box: BadInputError unless
        ``extrapolate`` (the end cells' polynomials, which degrade quickly away from the box).
        ``rows``, ``coils``: index sequences (into :data:`ROWS`, resp. the coils) to evaluate
        only those: (len(rows), len(coils)) per point, in the given order; a batch's per-cell
        products then take only those columns (a single point computes all 8 x n_coils and
        selects).
        """
        nc = self.n_coils
        r_sel = selection("rows", rows, 8)
        c_sel = selection("coils", coils, nc)
        C = self.kernels["cells"]
        q = self._one_point(points, extrapolate)
        if q is not None:
            a = cells_one(C, q).astype(np.float64).reshape(8, nc)
            if r_sel is not None:
                a = a[r_sel]
            if c_sel is not None:
                a = a[:, c_sel]
            return a if np.ndim(points) == 1 else a[None]
        p, single = self._points(points, extrapolate)
        r = np.arange(8) if r_sel is None else r_sel
        c = np.arange(nc) if c_sel is None else c_sel
        cols = None if r_sel is None and c_sel is None else (r[:, None] * nc + c).ravel()
        n = len(p)
        if n <= CELL_CHUNK:
            out = cells_many(C, p, cols)
        else:
            out = np.empty((n, 8 * nc if cols is None else len(cols)))
            for s in range(0, n, CELL_CHUNK):
                cells_many(C, p[s:s + CELL_CHUNK], cols, out[s:s + CELL_CHUNK])
        out = out.reshape(n, len(r), len(c))
        return out[0] if single else out

    def bias_force(self, points, extrapolate: bool = False) -> np.ndarray:
        """F0, the force on the magnet (moment :attr:`moment_a_m2`) at zero current, N:
        (3,) -> (3,), (n, 3) -> (n, 3)."""
        q = self._one_point(points, extrapolate)
        if q is not None:
            f = magnet_terms_one(self.kernels["magnet"], self.kernels["magnet_one"], q)
            f += trilinear_one(self.kernels["magnet_f0"], q)
            return f if np.ndim(points) == 1 else f[None]
        p, single = self._points(points, extrapolate)
        f = magnet_terms(self.kernels["magnet"], p) + trilinear(self.kernels["magnet_f0"], p)
        return f[0] if single else f

    def sensor_induced_field(self, magnet_position_m, extrapolate: bool = False) -> np.ndarray:
        """Field of the cores magnetized by the magnet at the Hall sensors, T (array frame):
        (3,) -> (n_sensors, 3), (n, 3) -> (n, n_sensors, 3).

        Linear cores: component c at sensor s is m . B(p) of the coupled system's adjoint
        sources for that component (in the continuum, the cores magnetized by a unit dipole
        along c at s: reciprocity) -- a mode sum like A (``SCOEF``)."""
        ns = self.n_sensors
        q = self._one_point(magnet_position_m, extrapolate, "magnet_position_m")
        one = self.kernels["sensor_one"]
        if q is not None and one is not None:
            b = (modes_one(one, q) @ one["coef"]).reshape(ns, 3)
            return b if np.ndim(magnet_position_m) == 1 else b[None]
        p, single = self._points(magnet_position_m, extrapolate, "magnet_position_m")
        out = np.zeros((len(p), 3 * ns))
        if one is not None:
            for s in range(0, len(p), BATCH_CHUNK):
                f = kernel_rows_many(one, p[s:s + BATCH_CHUNK])  # (m, K): m . B per basis
                out[s:s + BATCH_CHUNK] = f @ one["coef"]
            b = out.reshape(-1, ns, 3)
            return b[0] if single else b
        one = q is not None
        m = self.arrays["MOMENT"]
        for t, c in self.kernels["scoef"]:
            rows = mode_rows(t, p)[..., :3]  # (n, k, nb, 3): B per unit coefficient
            out += (rows @ m).reshape(len(p), -1) @ c
        b = out.reshape(-1, ns, 3)
        return b[0] if (single or (one and np.ndim(magnet_position_m) == 1)) else b

    def sensor_coil_field(self, currents=None) -> np.ndarray:
        """The coils' field at the sensors (array frame): per ampere (n_sensors, 3, n_coils)
        T/A, or with ``currents`` (n_coils,) A the field (n_sensors, 3) T (saturation not
        applied)."""
        g = self.arrays["SENSOR_COIL"]
        if currents is None:
            return g.copy()
        return g @ self._currents(currents)

    def sensor_coil_gradient(self) -> np.ndarray:
        """The coils' field gradient at the sensors per ampere (array frame), (n_sensors, 3,
        3, n_coils) T/(m A), entry [s, i, j, k] = dB_i/dx_j of coil k (:func:`gradient_tensor`
        of the stored rows)."""
        g = gradient_tensor(np.moveaxis(self.arrays["SENSOR_COIL_GRAD"], 1, -1))
        return np.moveaxis(g, (-2, -1), (1, 2))

    def saturation_factor(self, currents) -> np.ndarray:
        """Per-coil factors (n_coils,) on the columns of A at these currents (A): the
        saturation correction (1 for air coils and linear cores; docs/coupling.md)."""
        return self.kernels["saturation"].factor_at(self._currents(currents))

    def saturation_table(self) -> SaturationTable:
        """The stored saturation correction (``SAT_I``, ``SAT_FACTOR``) as the runner applies
        it (:class:`SaturationTable`: factors, linear-equivalent currents, linearization)."""
        return self.kernels["saturation"]

    def _currents(self, currents) -> np.ndarray:
        return check_currents(currents, self.n_coils)

    def currents_for(self, point, wanted: np.ndarray, rows=slice(None)) -> np.ndarray:
        """Least-norm currents (A) with A[rows] I = wanted at ``point`` (pseudo-inverse)."""
        a = self.actuation(point)[rows]
        return np.linalg.lstsq(a, np.asarray(wanted, float), rcond=None)[0]

