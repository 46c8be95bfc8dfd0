"""A coil array: coils in poses, the 8 x n actuation matrix, force and torque on a dipole.

Thesis chapter 2 (eqs. 2.5-2.13): with the currents I (n_coils,),

    [B; G5] = A(p) I,    G5 = (dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz),
    F = F(m) G5 (eq. 2.5),    tau = Sk(m) B (eq. 2.9).

Five numbers describe grad B because, outside every source, grad B is symmetric (curl B = 0) and
traceless (div B = 0); :func:`gradient_from_g5` rebuilds the full tensor from them.

The array is one magnetic system: every core is magnetized by every winding, by the other
cores and by the finger magnet, all solved together (:mod:`designkit.cores.coupled`, linear cores at
``relative_permeability``; solved once per array and cached). Column k of A is the field per
ampere in coil k with all cores present. With linear cores the force on the magnet is
``F(p, I) = F(m) A(p) I + F0(p)`` with the bias force F0 (:meth:`CoilArray.bias_force`) of the
cores the magnet magnetizes. Saturation (``Core(bh='steel1010')``) is not in A: the per-coil
correction :meth:`CoilArray.saturation_correction` scales the columns.
Cores of the approximate ``model='thesis-uniform'`` keep the uncoupled per-coil model of the
thesis (no neighbour coupling, no magnet pull).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from ..cores import ArraySystem, saturation_table
from ..cores.symmetry import PlacementGroup, find_symmetries
from ..design import default_design
from ..errors import BadInputError
from ..geometry.pose import Pose
from ..support import validate as v
from .coil import Coil
from .magnets import bias_force_matrix, magnets_core_field
from .overlap import (check_layout_overlap, check_overlap, check_sensors_clear,
                      check_separation, sensor_inside)
from firmware_io.mapfile import check_currents
from firmware_io.mapfile.format import ROWS  # the row order of A(p), defined once (re-exported)


# ---------------------------------------------------------------------------- small matrices
def force_matrix(moment) -> np.ndarray:
    """F(m) of thesis eq. 2.5: F = F(m) G5, shape (3, 5), A m^2.

    Uses dBy/dx = dBx/dy, dBz/dx = dBx/dz, dBz/dy = dBy/dz and dBz/dz = -dBx/dx - dBy/dy.
    """
    mx, my, mz = v.vector3("moment", moment, "A m^2")
    return np.array([[mx, my, mz, 0.0, 0.0],
                     [0.0, mx, 0.0, my, mz],
                     [-mz, 0.0, mx, -mz, my]])


def skew_matrix(moment) -> np.ndarray:
    """Sk(m) of thesis eq. 2.8: m x B = Sk(m) B, shape (3, 3), A m^2."""
    mx, my, mz = v.vector3("moment", moment, "A m^2")
    return np.array([[0.0, -mz, my], [mz, 0.0, -mx], [-my, mx, 0.0]])


def g5_from_gradient(g: np.ndarray) -> np.ndarray:
    """(..., 3, 3) gradient ``G[i, j] = dB_i/dx_j`` -> (..., 5) the rows 3-7 of A."""
    return np.stack([g[..., 0, 0], g[..., 0, 1], g[..., 0, 2], g[..., 1, 1], g[..., 1, 2]], -1)


def gradient_from_g5(g5: np.ndarray) -> np.ndarray:
    """(..., 5) -> (..., 3, 3), symmetric and traceless by construction."""
    gxx, gxy, gxz, gyy, gyz = np.moveaxis(np.asarray(g5), -1, 0)
    return np.stack([np.stack([gxx, gxy, gxz], -1), np.stack([gxy, gyy, gyz], -1),
                     np.stack([gxz, gyz, -gxx - gyy], -1)], -2)


def _nested(a: np.ndarray) -> tuple:
    """An array as nested tuples of floats (hashable, immutable)."""
    return tuple(_nested(x) for x in a) if a.ndim > 1 else tuple(float(x) for x in a)


# ---------------------------------------------------------------------------- the array
@dataclass(frozen=True)
class CoilArray:
    """Coils in poses (each :class:`Coil` carries its pose). Immutable.

    Parameters
    ----------
    coils : tuple of Coil
        At least one; their solids (winding envelope, core) must not intersect.
    """

    coils: tuple[Coil, ...]
    sensor_offset_m: float = 0.014
    """Hall sensors, when ``sensors`` is None: this far above each coil's top face and below its
    bottom face, on its axis, m."""
    sensor_coils: tuple[Coil, ...] | None = None
    """The coils that place the sensors when ``sensors`` is None (None: ``coils``); an as-built
    array's are the nominal coils: the Hall arrays are boards, they do not move with a
    displaced coil."""
    sensors: tuple | None = None
    """Sensor poses: (positions (n_sensors, 3) m, frames (n_sensors, 3, 3)) as nested tuples,
    e.g. :meth:`designkit.design.Design.sensor_poses`; None: from the coils (above)."""

    def __post_init__(self):
        coils = tuple(self.coils)
        if not coils:
            raise BadInputError("coils", "a non-empty sequence of Coil", coils)
        for k, c in enumerate(coils):
            if not isinstance(c, Coil):
                raise BadInputError(f"coils[{k}]", "a designkit.Coil", type(c).__name__)
        object.__setattr__(self, "coils", coils)
        if self.sensor_coils is not None:
            object.__setattr__(self, "sensor_coils", tuple(self.sensor_coils))
            if len(self.sensor_coils) != len(coils):
                raise BadInputError("sensor_coils", f"None or {len(coils)} coils",
                                    len(self.sensor_coils))
        v.nonnegative("sensor_offset_m", self.sensor_offset_m)
        if self.sensors is not None:
            pos, rot = (np.asarray(a, dtype=float) for a in self.sensors)
            if pos.ndim != 2 or pos.shape[1] != 3 or rot.shape != (len(pos), 3, 3):
                raise BadInputError("sensors", "(positions (n, 3) m, frames (n, 3, 3))",
                                    f"shapes {pos.shape}, {rot.shape}")
            object.__setattr__(self, "sensors", (_nested(pos), _nested(rot)))
        check_overlap(coils)
        check_separation(coils)

    @classmethod
    def from_design(cls, design) -> "CoilArray":
        """The design's array: its layout's coils (each with its own winding and core), its
        sensors; as built (moved, tilted, rewound, other cores) when the design has
        ``[asbuilt]``, with the sensors where the nominal design puts them."""
        check_layout_overlap(design, _nominal_coils)
        coils = _nominal_coils(design)
        if design.asbuilt is not None:
            coils = design.asbuilt.apply(coils)
        pos, rot = design.sensor_poses()
        check_design_sensors(design, coils, pos)
        return cls(coils, sensor_offset_m=design.sensors.offset_m,
                   sensors=(_nested(pos), _nested(rot)))

    @classmethod
    def default(cls) -> "CoilArray":
        """The thesis array: 9 coils, 3 x 3, 50 mm pitch (with the default core)."""
        return cls.from_design(default_design())

    @property
    def n_coils(self) -> int:
        return len(self.coils)

    def positions(self) -> np.ndarray:
        """Winding centres, shape (n_coils, 3), m."""
        return np.array([c.pose.position for c in self.coils])

    def coil_types(self) -> dict[Coil, list[int]]:
        """Identical coils (all but the pose equal) -> their indices; one (rho, z) model each."""
        out: dict[Coil, list[int]] = {}
        for k, c in enumerate(self.coils):
            out.setdefault(dataclasses.replace(c, pose=Pose()), []).append(k)
        return out

    def symmetries(self) -> PlacementGroup:
        """The array's symmetry group about the vertical axis through its coils' centroid
        (:func:`designkit.cores.symmetry.find_symmetries` of the winding centres, axes and the
        coils without their poses): the elements that map every coil onto an identical coil.
        Built once."""
        if "_group" not in self.__dict__:
            kinds = [dataclasses.replace(c, pose=Pose()) for c in self.coils]
            group = find_symmetries(self.positions(),
                                    [c.pose.matrix[:, 2] for c in self.coils], kinds)
            object.__setattr__(self, "_group", group)
        return self.__dict__["_group"]

    def __getstate__(self):
        # the cached coupled solve (tens of MB) is rebuilt on demand, not pickled to workers
        state = dict(self.__dict__)
        state.pop("_system", None)
        return state

    def __setstate__(self, state):
        for key, value in state.items():
            object.__setattr__(self, key, value)

    # ------------------------------------------------------------------ coupled cores
    def coupled(self):
        """The array-level core solve (:class:`designkit.cores.ArraySystem`), built once.

        None when no core takes part (air coils, or only ``model='thesis-uniform'`` cores).
        """
        if "_system" not in self.__dict__:
            idx = [k for k, c in enumerate(self.coils)
                   if c.core is not None and c.core.model == "surface-current"]
            # frozen dataclass: cache the derived solve on the instance
            object.__setattr__(self, "_system", ArraySystem(self) if idx else None)
        return self.__dict__["_system"]

    # ------------------------------------------------------------------ fields
    def actuation_matrix(self, points, *, rtol: float = 1e-10) -> np.ndarray:
        """A(p) of thesis eq. 2.13 with all cores solved together (coupled).

        Column k: winding k per ampere plus the field of every core magnetized by it (and by
        each other). The core solve is built on the first call and cached on the array (its
        cost: docs/coupling.md).

        Parameters
        ----------
        points : array-like, shape (3,) or (n, 3), m
        rtol : float
            Relative accuracy of the winding quadrature.

        Returns
        -------
        A : ndarray, shape (n, 8, n_coils) (or (8, n_coils) for one point); rows :data:`ROWS`,
            T/A and T/(m A).
        """
        p, single = v.points(points)
        a = np.empty((len(p), 8, self.n_coils))
        system = self.coupled()
        coupled = set() if system is None else set(system.core_index)
        for k, coil in enumerate(self.coils):
            # cores in the coupled solve are added below, all together
            include = "winding" if (k in coupled or coil.core is None) else "all"
            b, g = coil.field(p, 1.0, gradient=True, rtol=rtol, include=include)
            a[:, :3, k] = b
            a[:, 3:, k] = g5_from_gradient(g)
        if system is not None:
            b, g = system.core_field(p, system.coil_solution(), gradient=True,
                                     coil_columns=True)
            a[:, :3, :] += b
            a[:, 3:, :] += g5_from_gradient(np.moveaxis(g, -1, 1)).transpose(0, 2, 1)
        return a[0] if single else a

    def uncoupled_actuation_matrix(self, points, *, rtol: float = 1e-10) -> np.ndarray:
        """A(p) with each core magnetized by its own winding only (the thesis' model; for
        comparison), same shape and units as :meth:`actuation_matrix`."""
        p, single = v.points(points)
        a = np.empty((len(p), 8, self.n_coils))
        for k, coil in enumerate(self.coils):
            b, g = coil.field(p, 1.0, gradient=True, rtol=rtol)
            a[:, :3, k] = b
            a[:, 3:, k] = g5_from_gradient(g)
        return a[0] if single else a

    # ------------------------------------------------------------------ the magnet and the iron
    def magnet_core_field(self, points_m, magnet_position_m, moment_a_m2, *,
                          gradient: bool = False, magnet_size_m=None):
        """Field of the cores magnetized by the finger magnet, at points.

        Parameters
        ----------
        points_m : array-like, shape (3,) or (n, 3), m
        magnet_position_m : array-like, shape (3,), m
        moment_a_m2 : array-like, shape (3,), A m^2 (take it from the design / map file)
        gradient : bool
        magnet_size_m : None or (radius, length), m
            None: the magnet is a point dipole. (radius, length): a uniformly magnetized
            cylinder along the moment, its exact field magnetizes the cores.

        Returns
        -------
        B : ndarray (n, 3), T [, G : ndarray (n, 3, 3), T/m]; zeros without cores.
        """
        p, single = v.points(points_m, "points_m")
        pos = v.vector3("magnet_position_m", magnet_position_m, "m")
        m = v.vector3("moment_a_m2", moment_a_m2, "A m^2")
        size = self._magnet_size(magnet_size_m)
        system = self.coupled()
        if system is None:
            b, g = np.zeros((len(p), 3)), np.zeros((len(p), 3, 3))
        else:
            x = system.magnet_solution(pos[None], m, size)
            res = system.core_field(p, x, gradient=gradient)
            b, g = (res[0][..., 0], res[1][..., 0]) if gradient else (res[..., 0], None)
        if single:
            b = b[0]
            g = None if g is None else g[0]
        return (b, g) if gradient else b

    @staticmethod
    def _magnet_size(magnet_size_m):
        if magnet_size_m is None:
            return None
        try:
            r, length = (float(q) for q in magnet_size_m)
        except (TypeError, ValueError):
            raise BadInputError("magnet_size_m", "None or (radius, length) in m",
                                magnet_size_m) from None
        v.positive("magnet_size_m[0] (radius)", r)
        v.positive("magnet_size_m[1] (length)", length)
        return (r, length)

    def _bias(self, magnet_positions_m, moment_a_m2, magnet_size_m):
        p, single = v.points(magnet_positions_m, "magnet_positions_m")
        m = v.vector3("moment_a_m2", moment_a_m2, "A m^2")
        size = self._magnet_size(magnet_size_m)
        system = self.coupled()
        if system is None:
            return np.zeros((len(p), 3)), np.zeros((len(p), 3)), single
        f = np.empty((len(p), 3))
        t = np.empty((len(p), 3))
        step = 64 if size is None else 16
        for a in range(0, len(p), step):
            f[a:a + step], t[a:a + step] = system.magnet_load(p[a:a + step], m, size)
        return f, t, single

    def bias_force(self, magnet_positions_m, moment_a_m2, *, magnet_size_m=None) -> np.ndarray:
        """Force on the magnet from the cores it magnetizes, at zero current, (n, 3) N.

        Point dipole (default): F0(p) = (m . grad) B_ind(p), B_ind the cores' field induced by
        the magnet itself (moment ``moment_a_m2`` at each of ``magnet_positions_m`` (n, 3) m).
        ``magnet_size_m=(radius, length)``: the finite cylinder (exact source field, face-charge
        force). Zero without cores.
        """
        f, _, single = self._bias(magnet_positions_m, moment_a_m2, magnet_size_m)
        return f[0] if single else f

    def bias_torque(self, magnet_positions_m, moment_a_m2, *, magnet_size_m=None) -> np.ndarray:
        """Torque on the magnet from the cores it magnetizes (about its centre), (n, 3) N m;
        point dipole: m x B_ind(p). ``magnet_size_m`` as in :meth:`bias_force`."""
        _, t, single = self._bias(magnet_positions_m, moment_a_m2, magnet_size_m)
        return t[0] if single else t

    # ------------------------------------------------------------------ several magnets
    def bias_force_matrix(self, magnet_positions_m, moments_a_m2, *, magnet_sizes_m=None):
        """Zero-current forces (N, N, 3) N and torques (N, N, 3) N m of the cores on N
        magnets: entry [i, k] on magnet i (about its centre) from the cores magnetized by
        magnet k (the diagonal: each magnet's own F0, as :meth:`bias_force`; the rest: the
        cross terms). ``magnet_positions_m`` (N, 3) m, ``moments_a_m2`` (N, 3) A m^2,
        ``magnet_sizes_m``: None (point dipoles), (radius, length) m for all or (N, 2);
        overlapping magnets are refused (:mod:`designkit.model.magnets`)."""
        return bias_force_matrix(self, magnet_positions_m, moments_a_m2, magnet_sizes_m)

    def bias_forces(self, magnet_positions_m, moments_a_m2, *, magnet_sizes_m=None):
        """Force (N, 3) N and torque (N, 3) N m on each of N magnets from the cores
        magnetized by all of them, at zero current (each magnet's F0 plus the cross terms:
        :meth:`bias_force_matrix` summed over the sources). The magnets' direct pull on each
        other is :func:`firmware_io.magnet_pair.pair_forces`."""
        f, t = bias_force_matrix(self, magnet_positions_m, moments_a_m2, magnet_sizes_m)
        return f.sum(axis=1), t.sum(axis=1)

    def magnets_core_field(self, points_m, magnet_positions_m, moments_a_m2, *,
                           magnet_sizes_m=None, gradient: bool = False):
        """Field (n, 3) T [, gradient (n, 3, 3) T/m] at ``points_m`` (n, 3) of the cores
        magnetized by all N magnets together (inputs as :meth:`bias_force_matrix`)."""
        return magnets_core_field(self, points_m, magnet_positions_m, moments_a_m2,
                                  magnet_sizes_m, gradient)

    def sensor_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """Sensor positions (n_sensors, 3) m and frames (n_sensors, 3, 3) (columns: each chip's
        x, y, z axes in the array frame). Without ``sensors``: the upper array (``sensor_offset_m``
        above each coil's top face, on its axis) then the lower array (as far below its bottom
        face), each chip in its coil's frame."""
        if self.sensors is not None:
            return np.array(self.sensors[0]), np.array(self.sensors[1])
        up, down, frames = [], [], []
        for c in self.sensor_coils or self.coils:
            axis = c.pose.matrix[:, 2]
            pos = np.asarray(c.pose.position, dtype=float)
            d = c.length / 2 + self.sensor_offset_m
            up.append(pos + d * axis)
            down.append(pos - d * axis)
            frames.append(c.pose.matrix)
        return np.array(up + down), np.array(frames + frames)

    def sensor_positions_m(self) -> np.ndarray:
        """Hall sensor positions of the default layout, (2, n_coils, 3) m: [0] upper array,
        [1] lower array (:meth:`sensor_poses` in two halves). Any other sensor layout:
        :meth:`sensor_poses`."""
        pos = self.sensor_poses()[0]
        if len(pos) != 2 * self.n_coils:
            raise BadInputError("sensor layout", f"two sensors a coil ({2 * self.n_coils}) for "
                                "sensor_positions_m(); use sensor_poses()", len(pos))
        return pos.reshape(2, self.n_coils, 3)

    def saturating_coils(self) -> list[int]:
        """Indices of the coils whose core saturates (``Core.bh == 'steel1010'``; linear cores
        and air coils do not)."""
        return [k for k, c in enumerate(self.coils)
                if c.core is not None and c.core.bh == "steel1010"]

    def saturation_correction(self, height_m: float = 0.03, currents_a=None) -> dict:
        """Saturation correction of the 1010-steel cores (form: :func:`designkit.cores.
        saturation_table`).

        Returns dict: ``saturation_current_a`` (k,) A; ``saturation_factor`` (k, n_coils)
        (1 for air coils and for cores the design calls linear, ``bh='linear'``: their model
        does not saturate); ``core_flux_t_per_a`` (n_coils, n_coils) T/A, the coupled linear
        axial flux density at core k's mid-plane per ampere in coil j (zero rows for air
        coils), for the per-state use.
        """
        tables = {}
        for k in self.saturating_coils():
            key = dataclasses.replace(self.coils[k], pose=Pose())
            if key not in tables:
                tables[key] = saturation_table(self.coils[k], height_m, currents_a)
        cur = (np.arange(0.0, 6.01, 1.0) if currents_a is None
               else np.asarray(currents_a, dtype=float))
        fac = np.ones((len(cur), self.n_coils))
        for k in self.saturating_coils():
            fac[:, k] = tables[dataclasses.replace(self.coils[k], pose=Pose())]["factor"]
        cmat = np.zeros((self.n_coils, self.n_coils))
        system = self.coupled()
        if system is not None:
            idx = system.core_index
            mid = np.array([np.asarray(self.coils[k].pose.position) + self.coils[k].pose.matrix
                            @ [0.0, 0.0, self.coils[k].core.offset] for k in idx])
            axes = np.array([self.coils[k].pose.matrix[:, 2] for k in idx])
            b = system.core_field(mid, system.coil_solution())  # (n, 3, n_coils)
            for j, cj in enumerate(self.coils):
                b[:, :, j] += cj.field(mid, 1.0, include="winding")
            cmat[idx] = np.einsum("na,nac->nc", axes, b)
        return {"saturation_current_a": cur, "saturation_factor": fac,
                "core_flux_t_per_a": cmat}

    def _currents(self, currents) -> np.ndarray:
        return check_currents(currents, self.n_coils, BadInputError)

    def field(self, points, currents) -> tuple[np.ndarray, np.ndarray]:
        """Total B (n, 3), T, and grad B (n, 3, 3), T/m, for the currents (n_coils,), A."""
        i = self._currents(currents)
        a = self.actuation_matrix(np.atleast_2d(np.asarray(points, dtype=float)))
        y = a @ i
        return y[:, :3], gradient_from_g5(y[:, 3:])

    def force(self, points, moment, currents) -> np.ndarray:
        """Force on a point dipole, F = F(m) G5, shape (n, 3), N."""
        fm = force_matrix(moment)
        a = self.actuation_matrix(np.atleast_2d(np.asarray(points, dtype=float)))
        return (a[:, 3:, :] @ self._currents(currents)) @ fm.T

    def torque(self, points, moment, currents) -> np.ndarray:
        """Torque on a point dipole, tau = Sk(m) B, shape (n, 3), N m."""
        sk = skew_matrix(moment)
        a = self.actuation_matrix(np.atleast_2d(np.asarray(points, dtype=float)))
        return (a[:, :3, :] @ self._currents(currents)) @ sk.T


def _nominal_coils(design) -> tuple:
    """The design's coils in their layout's poses (not as built)."""
    return tuple(Coil.of_design(design, k) for k in range(design.n_coils))


def check_design_sensors(design, coils, positions) -> None:
    """BadInputError when a sensor of ``design`` (``positions`` (n, 3) m) lies in a coil's
    winding or core: a free list names ``sensors.positions_m[k]``; the default layout names
    ``sensors.offset_m`` and the offset the cores' ends need."""
    if design.sensors.layout == "free":
        check_sensors_clear(coils, positions, "sensors.positions_m")
        return
    if any(sensor_inside(coils, p) is not None for p in positions):
        need = max(max(0.0, c.core.offset + c.core.length / 2 - c.length / 2,
                       c.core.length / 2 - c.core.offset - c.length / 2)
                   for c in coils if c.core is not None)
        raise BadInputError("sensors.offset_m", f"> {need:.4g} m (the cores reach that far "
                            "beyond their windings' ends: a sensor there sits in the iron)",
                            design.sensors.offset_m)


@functools.lru_cache(maxsize=8)
def array_for_design(design) -> CoilArray:
    """``CoilArray.from_design(design)``, cached per design so its coupled solve is reused."""
    return CoilArray.from_design(design)


