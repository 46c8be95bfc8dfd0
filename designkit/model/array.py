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
import itertools
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import linprog

from ..cores import ArraySystem, saturation_table
from ..design import default_design
from ..errors import BadInputError, DesignRuleError
from ..geometry.pose import Pose
from ..support import validate as v
from ..support.atomic import atomic_path
from .coil import Coil
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


# ---------------------------------------------------------------------------- geometry
def _cylinders(coil: Coil):
    """Solid cylinders (radius, z_lo, z_hi) a coil occupies in its local frame, with names."""
    out = [("winding", coil.outer_radius, -coil.length / 2, coil.length / 2)]
    if coil.core is not None:
        c = coil.core
        out.append(("core", c.radius, c.offset - c.length / 2, c.offset + c.length / 2))
    return out


def _cyl_overlap(pa: Pose, a, pb: Pose, b) -> bool:
    """Do two solid cylinders (in poses) share interior points?

    Exact for parallel (or anti-parallel) axes; otherwise surface points of each (0.5 mm
    spacing or finer) are tested inside the other, which finds any overlap deeper than that.
    """
    _, ra, za0, za1 = a
    _, rb, zb0, zb1 = b
    ca = np.asarray(pa.position) + pa.matrix[:, 2] * 0.5 * (za0 + za1)
    cb = np.asarray(pb.position) + pb.matrix[:, 2] * 0.5 * (zb0 + zb1)
    rsa = np.hypot(ra, 0.5 * (za1 - za0))
    rsb = np.hypot(rb, 0.5 * (zb1 - zb0))
    if np.linalg.norm(ca - cb) >= rsa + rsb:
        return False
    ua, ub = pa.matrix[:, 2], pb.matrix[:, 2]
    eps = 1e-12
    # each cylinder lies inside the capsule of its radius about its axis segment
    if _segment_distance(ca, ua * 0.5 * (za1 - za0), cb, ub * 0.5 * (zb1 - zb0)) >= ra + rb:
        return False
    if abs(abs(ua @ ub) - 1.0) < 1e-9:
        d = cb - ca
        axial = d @ ua
        radial = np.linalg.norm(d - axial * ua)
        ha, hb = 0.5 * (za1 - za0), 0.5 * (zb1 - zb0)
        return bool(radial < ra + rb - eps and abs(axial) < ha + hb - eps)

    def surface(pose, r, z0, z1):
        step = min(5e-4, r / 8)
        nphi = max(16, int(2 * np.pi * r / step))
        nz = max(2, int((z1 - z0) / step) + 1)
        nr = max(2, int(r / step) + 1)
        phi = np.linspace(0, 2 * np.pi, nphi, endpoint=False)
        zz = np.linspace(z0, z1, nz)
        P, Z = np.meshgrid(phi, zz, indexing="ij")
        pts = [np.stack([r * np.cos(P), r * np.sin(P), Z], -1).reshape(-1, 3)]
        rr = np.linspace(0, r, nr)
        R, P = np.meshgrid(rr, phi, indexing="ij")
        for zc in (z0, z1):
            pts.append(np.c_[(R * np.cos(P)).ravel(), (R * np.sin(P)).ravel(),
                             np.full(R.size, zc)])
        loc = np.vstack(pts)
        return loc @ pose.matrix.T + np.asarray(pose.position)

    def inside(pose, r, z0, z1, pts):
        loc = pose.to_local(pts)
        return (np.hypot(loc[:, 0], loc[:, 1]) < r - eps) & (loc[:, 2] > z0 + eps) & (
            loc[:, 2] < z1 - eps)

    return bool(np.any(inside(pb, rb, zb0, zb1, surface(pa, ra, za0, za1)))
                or np.any(inside(pa, ra, za0, za1, surface(pb, rb, zb0, zb1))))


def _segment_distance(ca, ha, cb, hb) -> float:
    """Shortest distance between the segments ca +- ha and cb +- hb (3-vectors, m)."""
    s, t = np.meshgrid(np.linspace(-1.0, 1.0, 41), np.linspace(-1.0, 1.0, 41))
    d = (ca + s.ravel()[:, None] * ha) - (cb + t.ravel()[:, None] * hb)
    # sampled minimum, less the largest step between samples: a lower bound
    step = 0.05 * (np.linalg.norm(ha) + np.linalg.norm(hb))
    return float(np.sqrt(np.einsum("ij,ij->i", d, d).min()) - step)


def check_overlap(coils) -> None:
    """Raise :class:`DesignRuleError` naming the first pair of coils whose solids intersect."""
    for (i, ci), (j, cj) in itertools.combinations(enumerate(coils), 2):
        for a in _cylinders(ci):
            for b in _cylinders(cj):
                if _cyl_overlap(ci.pose, a, cj.pose, b):
                    raise DesignRuleError(
                        f"Coils {i} and {j} overlap: the {a[0]} of coil {i} (at "
                        f"{np.round(np.asarray(ci.pose.position) * 1e3, 3).tolist()} mm) "
                        f"intersects the {b[0]} of coil {j} (at "
                        f"{np.round(np.asarray(cj.pose.position) * 1e3, 3).tolist()} mm). "
                        "Move them apart or make them smaller.")


def check_separation(coils) -> None:
    """Raise :class:`DesignRuleError` naming any core that overlaps or touches another coil's
    core or winding (the coupled solve needs every core surrounded by air).

    coils : sequence of :class:`designkit.Coil` in their poses.
    """
    for i, ci in enumerate(coils):
        if ci.core is None:
            continue
        core_cyl = _cylinders(ci)[1]
        for j, cj in enumerate(coils):
            if j == i:
                continue
            # winding and core of cj; core-core pairs once (j > i)
            others = _cylinders(cj) if j > i else _cylinders(cj)[:1]
            for o in others:
                if _cyl_overlap(ci.pose, _grow(core_cyl), cj.pose, _grow(o)):
                    raise DesignRuleError(
                        f"The core of coil {i} (at "
                        f"{np.round(np.asarray(ci.pose.position) * 1e3, 3).tolist()} mm) "
                        f"{'overlaps or touches'} the {o[0]} of coil {j} (at "
                        f"{np.round(np.asarray(cj.pose.position) * 1e3, 3).tolist()} mm); "
                        "cores must be separated from every other coil by air. Move the coils "
                        "apart or make them smaller.")


def _grow(cyl, eps=1e-9):
    """Grow a cylinder by eps so that touching counts as overlapping."""
    name, r, z0, z1 = cyl
    return (name, r + eps, z0 - eps, z1 + eps)


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
        coils = tuple(Coil.of_design(design, k) for k in range(design.n_coils))
        if design.asbuilt is not None:
            coils = design.asbuilt.apply(coils)
        pos, rot = design.sensor_poses()
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


@functools.lru_cache(maxsize=8)
def array_for_design(design) -> CoilArray:
    """``CoilArray.from_design(design)``, cached per design so its coupled solve is reused."""
    return CoilArray.from_design(design)


# ---------------------------------------------------------------------------- workspace metrics
def fz_per_amp(actuation: np.ndarray, moment) -> np.ndarray:
    """Vertical force per ampere of each coil, (n, n_coils), N/A, from A (n, 8, n_coils)."""
    return np.einsum("k,nkc->nc", force_matrix(moment)[2], actuation[:, 3:, :])


def max_vertical_force(fz_coeff: np.ndarray, max_current: float, total_current: float, *,
                       lateral: Literal["free", "zero"] = "free") -> np.ndarray:
    """Largest upward force reachable at each point under the drive limits, N.

    Maximize ``Fz = a . I`` subject to ``|I_k| <= max_current`` and ``sum |I_k| <= total_current``.

    ``lateral='free'``: closed form (a fractional knapsack with equal weights): give
    ``max_current`` with sign(a_k) to the coils with the largest |a_k| until the budget is spent.
    ``lateral='zero'``: also require Fx = Fy = 0 (a pure push); one linear program per point
    (scipy.optimize.linprog, HiGHS) -- then ``fz_coeff`` must be (n, 3, n_coils) force per amp.

    Parameters
    ----------
    fz_coeff : ndarray, shape (n, n_coils) N/A ('free') or (n, 3, n_coils) N/A ('zero')
    max_current, total_current : float, A

    Returns
    -------
    ndarray, shape (n,), N (>= 0).
    """
    imax = v.positive("max_current", max_current, "A")
    itot = v.positive("total_current", total_current, "A")
    if lateral == "free":
        a = np.sort(np.abs(np.asarray(fz_coeff, dtype=float)), axis=1)[:, ::-1]
        n_full = int(min(a.shape[1], itot // imax))
        out = imax * a[:, :n_full].sum(axis=1)
        if n_full < a.shape[1]:
            out += (itot - n_full * imax) * a[:, n_full]
        return out
    if lateral != "zero":
        raise BadInputError("lateral", "'free' or 'zero'", lateral)
    f = np.asarray(fz_coeff, dtype=float)
    nc = f.shape[2]
    # I = Ip - In with Ip, In >= 0: the L1 budget becomes linear
    a_ub = np.ones((1, 2 * nc))
    out = np.empty(len(f))
    for k in range(len(f)):
        c = -np.r_[f[k, 2], -f[k, 2]]
        a_eq = np.c_[f[k, :2], -f[k, :2]]
        res = linprog(c, A_ub=a_ub, b_ub=[itot], A_eq=a_eq, b_eq=[0.0, 0.0],
                      bounds=[(0, imax)] * (2 * nc), method="highs")
        out[k] = -res.fun if res.status == 0 else 0.0
    return out


def condition_number(actuation: np.ndarray, length_scale: float = 0.03) -> np.ndarray:
    """2-norm condition number of A(p) with the gradient rows times ``length_scale`` (m).

    The rows of A have different units (T/A and T/(m A)); scaling the gradient rows by a length
    (default 30 mm, the design height) makes the singular values comparable.
    Returns shape (n,); inf where A is rank deficient.
    """
    a = np.array(actuation, dtype=float, copy=True)
    a[:, 3:, :] *= v.positive("length_scale", length_scale)
    s = np.linalg.svd(a, compute_uv=False)
    with np.errstate(divide="ignore"):
        return np.where(s[:, -1] > 0, s[:, 0] / np.where(s[:, -1] > 0, s[:, -1], 1.0), np.inf)


def workspace_metrics(design, *, spacing: float = 0.005, heights=None, out_png=None,
                      array: CoilArray | None = None) -> dict:
    """Largest vertical force, where it passes the human threshold, and conditioning.

    Evaluated on horizontal planes (``heights``, m above the coil tops; default 10, 30, 50 mm)
    over the workspace footprint with the design's drive limits (per coil and total) and a
    magnet of the design (its moment vector, MagnetSpec.direction).

    Returns a dict of arrays and summary numbers; writes a PNG map to ``out_png`` if given.
    """
    arr = array or CoilArray.from_design(design)
    ws = design.workspace
    heights = (0.010, 0.030, 0.050) if heights is None else tuple(heights)
    xs = np.arange(-ws.half_width_m, ws.half_width_m + 1e-12, spacing)
    m = np.array(design.magnet.moment_vector_a_m2)
    thr = design.render.threshold_n
    fmax, cond = [], []
    for h in heights:
        X, Y = np.meshgrid(xs, xs, indexing="xy")
        pts = np.c_[X.ravel(), Y.ravel(), np.full(X.size, h)]
        # the array's own exact matrix: designkit.model.skipping (tables, faster) imports this module
        a = arr.actuation_matrix(pts)
        fz = fz_per_amp(a, m)
        fmax.append(max_vertical_force(fz, design.drive.max_current_a,
                                       design.drive.total_current_a).reshape(X.shape))
        cond.append(condition_number(a).reshape(X.shape))
    fmax, cond = np.array(fmax), np.array(cond)
    out = {"heights_m": np.array(heights), "x_m": xs, "max_fz_n": fmax, "condition": cond,
           "fraction_above_threshold": [(f > thr).mean() for f in fmax],
           "threshold_n": thr}
    if out_png is not None:
        _plot_metrics(out, out_png)
    return out


def _plot_metrics(res: dict, out_png) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hs = res["heights_m"]
    ext = np.array([res["x_m"][0], res["x_m"][-1]] * 2) * 1e3
    fig, axes = plt.subplots(2, len(hs), figsize=(4 * len(hs), 7), squeeze=False)
    for k, h in enumerate(hs):
        ax = axes[0, k]
        im = ax.imshow(res["max_fz_n"][k] * 1e3, origin="lower", extent=ext, cmap="viridis")
        ax.contour(res["max_fz_n"][k] * 1e3, levels=[res["threshold_n"] * 1e3], colors="w",
                   extent=ext, origin="lower")
        ax.set_title(f"max Fz (mN), z = {h * 1e3:.0f} mm\nwhite: {res['threshold_n'] * 1e3} mN")
        fig.colorbar(im, ax=ax)
        ax = axes[1, k]
        im = ax.imshow(np.log10(res["condition"][k]), origin="lower", extent=ext, cmap="magma")
        ax.set_title("log10 cond A (grad rows x 30 mm)")
        fig.colorbar(im, ax=ax)
        for a in axes[:, k]:
            a.set_xlabel("x (mm)")
            a.set_ylabel("y (mm)")
    fig.tight_layout()
    with atomic_path(out_png, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=90)
    plt.close(fig)
