"""The array as one magnetic system: all cores magnetized together, by every source at hand.

Per core type a :class:`designkit.cores.core_model.CoreModel` (m = 0 surface currents,
m >= 1 surface charges about the core's own axis). The applied field of a core is the
sources' field plus the field of every *other* core, sampled on its collocation rings and
projected onto the modes; the self blocks are mode-diagonal, the cross blocks (core i's
unknowns -> core j's projected field) are built once per distinct relative placement. One
dense LU per array, reused for every source: each coil's winding per ampere, the finger
magnet at each position (point dipole or uniformly magnetized cylinder).

Inputs: a :class:`designkit.model.array.CoilArray` (m, A); outputs: unknowns per source and the
cores' B (T) and grad B (T/m) at global points, force (N) and torque (N m) on the magnet.
Derivation, costs and the measured accuracy against the 3-D GetDP FEM: docs/coupling.md.
"""

from __future__ import annotations

import dataclasses
import math
from contextlib import nullcontext
from typing import Literal

import numpy as np
from scipy.linalg import lu_factor, lu_solve

from ..constants import MU0
from ..errors import BadInputError
from ..field.kernels import sheet_rz
from ..geometry.pose import Pose
from ..geometry.winding import WindingGeometry
from ..support.blas import one_blas_thread
from .core_model import M_MAX, CoreModel, core_model
from .discretization import gauss
from .symmetric_solve import SymmetricLU
from .symmetry import adapted_frames

N_PHI_RING = 12
"""Azimuthal samples per collocation ring when projecting another core's / a winding's field."""
FIELD_AZIMUTHS = (24, 32)
"""Azimuth counts of the cores' field rules (the compressed far rule, the near panels'
rule: :mod:`.charges`, :mod:`.core_model`): an element of the array's group fills a map's
values at an image exactly only if it maps them onto themselves on every core."""
N_PHI_MAGNET = 32
"""... and when projecting the magnet's field (it can be ~5 mm from a core top).
Observation points where :meth:`CoreModel.far_mask` fails sum a core's panels (m = 0) and
3 Gauss nodes x 32 azimuths per charge panel (m >= 1); the others use compressed product
rules (FAR_NODES rings per interval, FAR_AZIMUTHS azimuths)."""


def _core_model_of(coil, m_max, refine=1) -> CoreModel:
    c = coil.core
    return core_model(float(c.radius), float(c.length), float(c.offset),
                      float(c.relative_permeability), WindingGeometry.of(coil), int(m_max),
                      int(refine))


def rel_key(pa, pb) -> tuple:
    """Hashable relative placement of pose b seen from pose a (rounded to 1e-9 m / 1e-12)."""
    rel_pos = pa.to_local(np.asarray(pb.position, dtype=float)[None])[0]
    rel_rot = pa.matrix.T @ pb.matrix
    return tuple(np.round(rel_pos, 9) + 0.0) + tuple(np.round(rel_rot.ravel(), 12) + 0.0)


def _cylinder_magnet(moment, magnet_size_m):
    """The uniformly magnetized cylinder of moment ``moment`` (3,) A m^2 and size (radius,
    length) m: radius, length, its axis (unit, along the moment; +z for a zero moment) and
    its magnetization M = |m| / volume, A/m."""
    a, length = (float(v) for v in magnet_size_m)
    mm = float(np.linalg.norm(moment))
    u = moment / mm if mm > 0 else np.array([0.0, 0.0, 1.0])
    return a, length, u, mm / (math.pi * a * a * length)


def mode_rotation(m: int, g: np.ndarray) -> np.ndarray:
    """(2, 2): how the (cos, sin) coefficients of mode order m >= 1 change under g (2, 2)
    (:func:`mode_transform`)."""
    a = math.atan2(g[1, 0], g[0, 0])
    c, s = math.cos(m * a), math.sin(m * a)
    return np.array([[c, s], [s, -c]]) if np.linalg.det(g) < 0 else np.array([[c, -s], [s, c]])


def mode_transform(model: CoreModel, g: np.ndarray) -> np.ndarray:
    """T (n_unknowns, n_unknowns): the unknowns of ``model`` whose field is g H_u(g^-1 p), for
    an orthogonal 2 x 2 ``g`` acting about the core's axis (rotation by a or reflection
    R(a) diag(1, -1)). m = 0 fields are poloidal and axisymmetric (T = 1); a charge density
    c cos(m phi) + s sin(m phi) becomes sigma(g^-1 phi): a rotation of (c, s) by m a, or with
    the reflection (c, s) -> (c cos ma + s sin ma, c sin ma - s cos ma)."""
    n0, n1 = model.n0, model.n1
    t = np.eye(model.n_unknowns)
    for m in range(1, model.m_max + 1):
        rot = mode_rotation(m, g)
        i = n0 + 2 * (m - 1) * n1
        for r in range(2):
            for q in range(2):
                t[i + r * n1:i + (r + 1) * n1, i + q * n1:i + (q + 1) * n1] = \
                    rot[r, q] * np.eye(n1)
    return t


def turn(b: np.ndarray, model: CoreModel, g: np.ndarray) -> np.ndarray:
    """T(g) @ b for T = :func:`mode_transform` (model, g), without forming T: each mode
    order's (cos, sin) row blocks mixed by its 2 x 2 rotation."""
    out = b.copy()
    n0, n1 = model.n0, model.n1
    for m in range(1, model.m_max + 1):
        r = mode_rotation(m, g)
        i = n0 + 2 * (m - 1) * n1
        c, s = b[i:i + n1], b[i + n1:i + 2 * n1]
        out[i:i + n1] = r[0, 0] * c + r[0, 1] * s
        out[i + n1:i + 2 * n1] = r[1, 0] * c + r[1, 1] * s
    return out


def coupled_cores(array) -> list:
    """Indices of the coils whose cores take part in the coupled solve: linear at
    ``relative_permeability`` (a 1010-steel core too: its saturation is the separate
    correction, ``saturation_table``); 'thesis-uniform' cores stay uncoupled."""
    return [k for k, c in enumerate(array.coils)
            if c.core is not None and c.core.model == "surface-current"]


def solve_symmetry(array, cores, use: Literal["auto", "none"] = "auto") -> tuple:
    """The array's symmetries the coupled solve uses and the coils' frames it works in
    (PlacementGroup, (n_coils, 3, 3)): the coils' own frames when every element of the
    array's group (:meth:`designkit.model.array.CoilArray.symmetries`) maps the collocation
    rings of the ``cores`` (coil indices) onto themselves in them, else frames adapted to the
    group (:func:`.symmetry.adapted_frames`); the group is cut to the elements that do
    (:meth:`.symmetry.PlacementGroup.keeping_grids`), so that a block or a column taken from
    its image is the one computed directly. ``use`` 'none': the identity alone in the coils'
    own frames (the reference the symmetric solve is checked against)."""
    if use not in ("auto", "none"):
        raise BadInputError("symmetry", "'auto' or 'none'", use)
    group = array.symmetries()
    own = np.array([c.pose.matrix for c in array.coils])
    if use == "none":
        return group.subgroup(lambda e, s: False), own

    def usable(frames):
        return group.keeping_grids(group.local_actions(frames), (N_PHI_RING,), cores)

    best, frames = usable(own), own
    if len(best) < len(group):
        adapted = adapted_frames(group, own)
        other = usable(adapted)
        if len(other) > len(best):
            best, frames = other, adapted
    return best, frames


class ArraySystem:
    """All cores of a :class:`~designkit.model.array.CoilArray` solved together (linear cores).

    Built once per array (:meth:`designkit.model.array.CoilArray.coupled`). Sources are projected
    onto the cores' modes, the block system is solved by a stored LU factorization, and the
    cores' fields are evaluated from the solved unknowns.
    """

    def __init__(self, array, m_max: int = M_MAX, refine: int = 1,
                 symmetry: Literal["auto", "none"] = "auto"):
        self.array = array
        self.m_max = int(m_max)
        self.core_index = coupled_cores(array)
        self.models = [_core_model_of(array.coils[k], self.m_max, refine)
                       for k in self.core_index]
        self.group, frames = solve_symmetry(array, self.core_index, symmetry)
        self.frames = frames  # (n_coils, 3, 3): the cores' frames of the solve
        self.poses = [Pose(array.coils[k].pose.position, frames[k]) for k in self.core_index]
        sizes = [m.n_unknowns for m in self.models]
        self.offsets = np.r_[0, np.cumsum(sizes)].astype(int)
        n = int(self.offsets[-1])
        self.factors = np.concatenate([m.factors() for m in self.models]) if n else np.zeros(0)
        self.n_unknowns = n
        self._lu = None
        self._sym = None
        self._coil_solution = None
        if not n:
            return
        with one_blas_thread():
            reps, pairs = self.placements()
        # identical cores in a symmetric layout: one LU per isotypic component, each block
        # summed from the distinct placements' cross blocks (M itself is never formed)
        if len(self.group) > 1:
            self._sym = SymmetricLU.from_orbits(self, self._core_group(), mode_rotation,
                                                self.models[0].self_block(), reps, pairs)
        if self._sym is None:
            mat = np.zeros((n, n))
            with one_blas_thread():
                self._assemble(mat, reps, pairs)
            with one_blas_thread() if n <= 2000 else nullcontext():  # as in :meth:`solve`
                self._lu = lu_factor(mat)

    # ------------------------------------------------------------------ symmetry
    def _core_group(self):
        """The group on the cores: (matrices (n_g, 3, 3), core permutations (n_g, n_cores),
        local actions (n_g, n_cores, 2, 2)) for :class:`SymmetricLU`."""
        slot = {k: jj for jj, k in enumerate(self.core_index)}
        acts = self.group.local_actions(self.frames)[:, self.core_index]
        perms = np.array([[slot[int(s.perm[k])] for k in self.core_index]
                          for s in self.group.elements])
        return np.array([s.g for s in self.group.elements]), perms, acts

    def placements(self):
        """The cross blocks: ``reps`` {key: block} computed (:meth:`coupling_block`), one per
        distinct relative placement (models and :func:`rel_key`) that is not an image of a
        computed one under the group, and ``pairs`` [(j, i, key, h_j, h_i)]: block (j, i) of
        M is T(h_j) reps[key] T(h_i)^T (:func:`mode_transform` of the local actions h, None:
        the identity)."""
        mats, perms, acts = self._core_group()
        inv = [np.argsort(p) for p in perms]
        models, poses = self.models, self.poses

        def key(j, i):
            return id(models[i]), id(models[j]), rel_key(poses[i], poses[j])

        reps, pairs, seen = {}, [], set()
        for jj in range(len(models)):
            for ii in range(len(models)):
                if ii == jj:
                    continue
                k = key(jj, ii)
                seen.add(k)
                src = None if k in reps else next(
                    ((k0, acts[e, j0], acts[e, i0]) for e in range(1, len(mats))
                     for j0, i0 in [(inv[e][jj], inv[e][ii])]
                     for k0 in [key(j0, i0)] if k0 in reps), None)
                if src is None:
                    if k not in reps:
                        reps[k] = self.coupling_block(models[ii], poses[ii], models[jj],
                                                       poses[jj])
                    src = (k, None, None)
                pairs.append((jj, ii) + src)
        self.n_blocks, self.n_computed_blocks = len(seen), len(reps)
        return reps, pairs

    def _assemble(self, mat, reps, pairs):
        """Fill the dense system ``mat`` (n, n): self blocks and the cross blocks of
        :meth:`placements` (turned where taken from an image)."""
        selfs = {}
        for jj, mj in enumerate(self.models):
            sj = slice(self.offsets[jj], self.offsets[jj + 1])
            if id(mj) not in selfs:  # one self block per core type
                selfs[id(mj)] = mj.self_block()
            mat[sj, sj] = selfs[id(mj)]
        for jj, ii, k, hj, hi in pairs:
            block = reps[k]
            if hj is not None:
                block = turn(turn(block, self.models[jj], hj).T, self.models[ii], hi).T
            mat[self.offsets[jj]:self.offsets[jj + 1],
                self.offsets[ii]:self.offsets[ii + 1]] = block

    def in_coil_frames(self, x: np.ndarray) -> np.ndarray:
        """Unknowns (n_unknowns, ...) of the solve's core frames (:attr:`poses`) expressed in
        the coils' own frames (``array.coils[k].pose``): each core's (cos, sin) pairs turned
        by the rotation between the two about its axis (:func:`turn`)."""
        out = np.array(x, dtype=float, copy=True)
        for jj, k in enumerate(self.core_index):
            h = self.array.coils[k].pose.matrix.T @ self.poses[jj].matrix
            if np.allclose(h, np.eye(3), rtol=0.0, atol=1e-14):
                continue
            rows = slice(self.offsets[jj], self.offsets[jj + 1])
            flat = out[rows].reshape(self.models[jj].n_unknowns, -1)
            out[rows] = turn(flat, self.models[jj], h[:2, :2]).reshape(out[rows].shape)
        return out

    def coupling_block(self, mi, pi, mj, pj):
        """M's block of rows core j, columns core i: -F_j times :meth:`_cross_block` (the
        row factors F commute with the symmetries' mode turns)."""
        return np.multiply(-mj.factors()[:, None], self._cross_block(mi, pi, mj, pj))

    # ------------------------------------------------------------------ assembly
    @staticmethod
    def _cross_block(mi, pi, mj, pj):
        """Projected field at core j's rings per unit unknown of core i, (nu_j, nu_i)."""
        ring = mj.ring_points(N_PHI_RING)  # local j
        shape = ring.shape[:2]
        glob = ring.reshape(-1, 3) @ pj.matrix.T + np.asarray(pj.position)
        loc_i = pi.to_local(glob)
        h = mi.basis_field(loc_i, fine=False)  # (n, 3, nu_i) in frame i
        rot = pj.matrix.T @ pi.matrix  # frame i -> frame j
        h = np.einsum("ab,nbu->nau", rot, h)
        return mj.project(h.reshape(shape + (3, -1)))

    def _project_global_field(self, field_fn, n_phi, near_points=None) -> np.ndarray:
        """RHS: F * projection of a source's H (callable on global points -> (n, 3, k)).

        Without ``near_points``: ``n_phi`` azimuths per ring on every core. With
        ``near_points`` (k, 3) global m, one source per column (column q sits at
        near_points[q], and ``field_fn(points, cols)`` evaluates only columns ``cols``): a
        core uses ``n_phi`` azimuths for the sources closer than 30 mm to it and
        ``N_PHI_RING`` for the others (a source that far has no significant azimuthal
        content beyond the kept modes on the core's rings). Returns (n_unknowns, k).
        """
        rows = []
        for mj, pj in zip(self.models, self.poses):
            if near_points is None:
                groups = [(n_phi, None)]
            else:
                loc = pj.to_local(near_points)
                rho = np.hypot(loc[:, 0], loc[:, 1])
                dist = np.maximum.reduce([mj.z_lo - loc[:, 2], loc[:, 2] - mj.z_hi,
                                          rho - mj.radius])
                close = dist < 0.03
                groups = [(n_phi, np.flatnonzero(close)), (N_PHI_RING, np.flatnonzero(~close))]
            out = None
            for nphi, cols in groups:
                if cols is not None and len(cols) == 0:
                    continue
                ring = mj.ring_points(nphi)
                glob = ring.reshape(-1, 3) @ pj.matrix.T + np.asarray(pj.position)
                h = field_fn(glob) if cols is None else field_fn(glob, cols)  # (n, 3, k)
                if not pj.is_identity_rotation:
                    h = np.einsum("ba,nbk->nak", pj.matrix, h)  # to local j
                proj = mj.project(h.reshape(ring.shape[:2] + h.shape[1:]))
                if cols is None:
                    out = proj
                else:
                    if out is None:
                        out = np.zeros((mj.n_unknowns, len(near_points)))
                    out[:, cols] = proj
            rows.append(out)
        return self.factors[:, None] * np.concatenate(rows, axis=0)

    def solve(self, rhs: np.ndarray, transpose: bool = False) -> np.ndarray:
        """M^-1 rhs, or M^-T rhs with ``transpose`` (the adjoint system, :meth:`adjoint`)."""
        if self._sym is not None:
            return self._sym.solve(rhs, transpose)
        with one_blas_thread() if self.n_unknowns <= 2000 else nullcontext():
            # a single core's system: threads wait longer than compute
            return lu_solve(self._lu, rhs, trans=int(transpose))

    def adjoint(self, points: np.ndarray) -> np.ndarray:
        """Y = M^-T E^T (n_unknowns, 3 n): E the cores' B (T) at global ``points`` (n, 3) per
        unit unknown, column (point, component). The cores' field there for the source
        columns X is E X = Y^T X: for a magnet, Y^T (F * projection of its field) -- the
        discrete system's own answer, where a unit dipole at the point and reciprocity
        would add the collocation's error for that near source."""
        pts = np.asarray(points, float)
        e = np.zeros((len(pts), 3, self.n_unknowns))
        with one_blas_thread():
            for jj, (mj, pj) in enumerate(zip(self.models, self.poses)):
                h = mj.basis_field(pj.to_local(pts))  # (n, 3, nu_j), frame j
                e[:, :, self.offsets[jj]:self.offsets[jj + 1]] = \
                    MU0 * np.einsum("ab,nbu->nau", pj.matrix, h)
        return self.solve(e.reshape(-1, self.n_unknowns).T, transpose=True)

    # ------------------------------------------------------------------ coil sources
    def coil_solution(self) -> np.ndarray:
        """Unknowns of all cores per ampere in each coil, (n_unknowns, n_coils) (cached)."""
        if self._coil_solution is None:
            self._coil_solution = self.solve(self.factors[:, None] * self.coil_columns())
        return self._coil_solution

    def coil_columns(self) -> np.ndarray:
        """Projection of each coil's winding field per ampere onto every core's modes,
        (n_unknowns, n_coils) A/m per A (the right-hand side of :meth:`coil_solution` without
        the row factors)."""
        coils = self.array.coils
        rhs = np.zeros((self.n_unknowns, len(coils)))
        cache, done = {}, {}
        poses = [Pose(c.pose.position, f) for c, f in zip(coils, self.frames)]
        acts = self.group.local_actions(self.frames)
        inv = [np.argsort(s.perm) for s in self.group.elements]
        for jj, (mj, pj) in enumerate(zip(self.models, self.poses)):
            ring = mj.ring_points(N_PHI_RING)
            glob = ring.reshape(-1, 3) @ pj.matrix.T + np.asarray(pj.position)
            j = self.core_index[jj]
            for k, c in enumerate(coils):
                # identical windings at the same relative placement: one evaluation; at the
                # image of a computed placement under the group: that column turned (an
                # axisymmetric winding's field turns with the placement)
                key = (dataclasses.replace(c, core=None, pose=Pose()), id(mj),
                       rel_key(poses[k], pj))
                if key not in cache:
                    col = next((turn(cache[done[(k0, j0)]][:, None], mj, acts[e, j0])[:, 0]
                                for e in range(1, len(inv))
                                for k0, j0 in [(inv[e][k], inv[e][j])] if (k0, j0) in done),
                               None)
                    if col is None:
                        h = c.field(glob, 1.0, include="winding", rtol=1e-9) / MU0
                        h = h @ pj.matrix  # to local j
                        col = mj.project(h.reshape(ring.shape[:2] + (3,)))
                    cache[key] = col
                done[(k, j)] = key
                rhs[self.offsets[jj]:self.offsets[jj + 1], k] = cache[key]
        return rhs

    # ------------------------------------------------------------------ evaluation
    def core_field(self, points: np.ndarray, x: np.ndarray, gradient: bool = False, *,
                   coil_columns: bool = False):
        """B of all cores for the unknown columns x (n_unknowns, k) at global points.

        ``coil_columns``: x is :meth:`coil_solution` (column k = coil k), and each core's own
        column is evaluated by the single-core field rules. Returns B (n, 3, k) T [, G (n, 3, 3, k)
        T/m].
        """
        return self._field(points, x, gradient, False, coil_columns)

    def core_field_pointwise(self, points: np.ndarray, x: np.ndarray, gradient: bool = False):
        """Like :meth:`core_field` but point i uses its own column x[:, i]: B (n, 3) [, G]."""
        return self._field(points, x, gradient, True)

    def _field(self, points, x, gradient, pointwise, coil_columns=False):
        with one_blas_thread():
            return self._field_impl(points, x, gradient, pointwise, coil_columns)

    def _field_impl(self, points, x, gradient, pointwise, coil_columns=False):
        pts = np.asarray(points, dtype=float)
        tail = () if pointwise else (x.shape[1],)
        b = np.zeros((len(pts), 3) + tail)
        g = np.zeros((len(pts), 3, 3) + tail) if gradient else None
        for jj, (mj, pj) in enumerate(zip(self.models, self.poses)):
            xs = x[self.offsets[jj]:self.offsets[jj + 1]]
            res = mj.field(pj.to_local(pts), xs, gradient, pointwise,
                           self.core_index[jj] if coil_columns else None)
            rot = pj.matrix
            h = res[0] if gradient else res
            if pj.is_identity_rotation:
                b += MU0 * h
                if gradient:
                    g += MU0 * res[1]
                continue
            b += MU0 * np.einsum("ab,nb...->na...", rot, h)
            if gradient:
                gl = np.einsum("ab,nbc...->nac...", rot, res[1])
                g += MU0 * np.einsum("nac...,dc->nad...", gl, rot)
        return (b, g) if gradient else b

    # ------------------------------------------------------------------ magnet source
    def magnet_solution(self, positions: np.ndarray, moment: np.ndarray,
                        magnet_size_m=None) -> np.ndarray:
        """Unknowns of all cores magnetized by the magnet at each position, (nu, n).

        ``magnet_size_m``: None for a point dipole ``moment``; (radius, length) m for the
        uniformly magnetized cylinder (axis along ``moment``, M = |m| / volume; its exact
        field, :func:`designkit.field.magnetized_cylinder_field`).
        """
        pos = np.atleast_2d(np.asarray(positions, dtype=float))
        m = np.asarray(moment, dtype=float)
        if magnet_size_m is None:
            def src(glob, cols):
                # H of the point dipole (magnet outside every core: r > 0 at ring points),
                # per component on contiguous (n, k) differences
                pc = pos[cols]
                d = [glob[:, i, None] - pc[None, :, i] for i in range(3)]  # 3 x (n, k)
                inv_r3 = 1.0 / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
                a = sum(di * mi for di, mi in zip(d, m) if mi != 0.0) * inv_r3
                inv_r3 *= np.sqrt(inv_r3) * (1.0 / (4.0 * math.pi))
                a *= 3.0 * inv_r3
                out = np.empty((len(glob), 3, len(pc)))
                for i in range(3):
                    np.multiply(d[i], a, out=out[:, i])
                    if m[i] != 0.0:
                        out[:, i] -= m[i] * inv_r3
                return out
        else:
            a, length, u, mag = _cylinder_magnet(m, magnet_size_m)

            def src(glob, cols):
                d = glob[:, None, :] - pos[None, cols, :]  # (n, k, 3)
                zl = d @ u
                rv = d - zl[..., None] * u
                rho = np.sqrt(np.einsum("nki,nki->nk", rv, rv))
                br, bz = sheet_rz(a, 0.5 * length, rho.ravel(), zl.ravel())
                br, bz = br.reshape(rho.shape), bz.reshape(rho.shape)
                with np.errstate(invalid="ignore", divide="ignore"):
                    er = np.where(rho[..., None] > 0, rv / np.where(rho > 0, rho, 1.0)[..., None],
                                  0.0)
                h = mag * (br[..., None] * er + bz[..., None] * u)
                return np.swapaxes(h, 1, 2)

        with one_blas_thread():
            rhs = self._project_global_field(src, N_PHI_MAGNET, pos)
        return self.solve(rhs)

    def magnet_load(self, positions: np.ndarray, moment: np.ndarray, magnet_size_m=None,
                    n_r: int = 4, n_phi: int = 8):
        """Force (n, 3) N and torque (n, 3) N m on the magnet from the cores it magnetizes.

        Point dipole (``magnet_size_m`` None): F = (m . grad) B_ind(p), tau = m x B_ind(p).
        Cylinder (radius, length): its uniform axial M as face charges +-M on the end faces,
        F = M [int_top B_ind dA - int_bot B_ind dA], tau = M [int_top (r - p) x B_ind dA -
        int_bot ...] (exact for a uniformly magnetized body in a curl-free field; Gauss rule
        of n_r x n_phi points per face).
        """
        pos = np.atleast_2d(np.asarray(positions, dtype=float))
        m = np.asarray(moment, dtype=float)
        x = self.magnet_solution(pos, m, magnet_size_m)
        if magnet_size_m is None:
            b, g = self.core_field_pointwise(pos, x, gradient=True)
            return np.einsum("nji,j->ni", g, m), np.cross(m[None], b)
        a, length, u, mag = _cylinder_magnet(m, magnet_size_m)
        e1 = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(u, e1)
        xr, wr = gauss(n_r)
        s = 0.5 * (xr + 1.0)
        r = a * np.sqrt(s)
        ph = 2.0 * math.pi * np.arange(n_phi) / n_phi
        R, P = np.meshgrid(r, ph, indexing="ij")
        w = np.repeat(0.5 * wr * math.pi * a * a / n_phi, n_phi)  # area weights
        disc = (R.ravel()[:, None] * (np.cos(P.ravel())[:, None] * e1
                                      + np.sin(P.ravel())[:, None] * e2))
        nq = len(w)
        force = np.zeros((len(pos), 3))
        torque = np.zeros((len(pos), 3))
        for sign in (1.0, -1.0):
            rel = disc + sign * 0.5 * length * u  # (nq, 3) about the centre
            pts = (pos[:, None, :] + rel[None]).reshape(-1, 3)
            bq = self.core_field_pointwise(pts, np.repeat(x, nq, axis=1))
            bq = bq.reshape(len(pos), nq, 3)
            force += sign * mag * np.einsum("q,nqi->ni", w, bq)
            torque += sign * mag * np.einsum("q,nqi->ni", w, np.cross(rel[None], bq))
        return force, torque
