"""Tolerance-driven field evaluation of a coil array: compute only the outputs asked, skip a coil
where a rigorous bound says it cannot matter, share one (rho, z) table per coil type.

A :class:`SkippingEvaluator` names the sources (a :class:`~designkit.model.array.CoilArray`, optionally
with currents), the points (m), the outputs wanted and a relative tolerance.
:meth:`SkippingEvaluator.evaluate`

* computes only the axisymmetric (rho, z) components the outputs need: ``'B'`` needs Br, Bz;
  ``'fz'`` (vertical force on a z-dipole, coil axes parallel to z) needs only dBz/dz;
  gradients need Br, Bz, dBr/dz, dBz/dz, Br/rho (dBr/drho = -dBz/dz - Br/rho and
  dBz/drho = dBr/dz outside the sources, so the table is curl- and divergence-free exactly);
* skips a coil at a point when a rigorous bound on its contribution is below the tolerance:
  |B| and |grad B|_F are subharmonic outside the sources, so their maximum over the exterior of
  a sphere enclosing a coil's sources is reached on that sphere. The maxima on spheres of
  growing radius are sampled once per coil type (181 directions, times a 1.5 safety margin) and
  a point at distance R uses the sphere just inside R;
* evaluates identical coils through one (rho, z) table (bicubic spline of the components on a
  tensor grid graded with the distance to the sources), built over the points' local
  coordinates, and refined until its error at cell centres -- checked against direct
  evaluation -- is below a quarter of the tolerance.

Tolerance: an output's error is <= ``tolerance`` x the largest magnitude of that output over
the points (per coil column when no currents are given). Half of it goes to skipping, a quarter
to the tables.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from scipy.interpolate import RectBivariateSpline

from ..errors import BadInputError
from ..field import cylindrical_to_cartesian
from ..geometry.pose import Pose
from ..support import validate as v
from .array import CoilArray, force_matrix, g5_from_gradient
from .coil import Coil

Output = Literal["B", "gradient", "force", "fz", "torque"]
OUTPUTS = ("B", "gradient", "force", "fz", "torque")
RZ_COMPONENTS = ("br", "bz", "dbr_dz", "dbz_dz", "br_over_rho")
"""The (rho, z) components a per-coil-type table can hold (T/A, T/(m A))."""


# ============================================================================ per coil type
def _rz_direct(coil: Coil, rho, z, gradient: bool, rtol: float = 1e-10):
    """The coil's (rho, z) components per ampere, from Coil.field on the local xz half-plane."""
    if not coil.pose.is_identity_rotation or any(coil.pose.position):
        coil = dataclasses.replace(coil, pose=Pose())
    p = np.c_[rho, np.zeros_like(rho), z]
    if not gradient:
        b = coil.field(p, 1.0, rtol=rtol)
        return {"br": b[:, 0], "bz": b[:, 2]}
    b, g = coil.field(p, 1.0, gradient=True, rtol=rtol)
    return {"br": b[:, 0], "bz": b[:, 2], "dbr_dz": g[:, 0, 2], "dbz_dz": g[:, 2, 2],
            "br_over_rho": g[:, 1, 1], "dbr_drho": g[:, 0, 0], "dbz_drho": g[:, 2, 0]}


def source_box(coil: Coil) -> tuple[float, float, float]:
    """(rho_max, z_lo, z_hi) of the coil's sources in its local frame, m."""
    r, lo, hi = coil.outer_radius, -coil.length / 2, coil.length / 2
    if coil.core is not None:
        c = coil.core
        r = max(r, c.radius)
        lo = min(lo, c.offset - c.length / 2)
        hi = max(hi, c.offset + c.length / 2)
    return r, lo, hi


@functools.lru_cache(maxsize=16)
def sphere_bounds(coil: Coil):
    """Radii R (m) and bounds on max |B| (T/A) and |grad B|_F (T/(m A)) for |x| >= R."""
    r, lo, hi = source_box(coil)
    coil = dataclasses.replace(coil, pose=Pose())
    zc = 0.5 * (lo + hi)
    r_src = math.hypot(r, 0.5 * (hi - lo))
    radii = r_src * 1.1 * np.geomspace(1.0, 40.0, 48)
    th = np.linspace(0.0, math.pi, 181)
    R, T = np.meshgrid(radii, th, indexing="ij")
    comp = _rz_direct(coil, (R * np.sin(T)).ravel(), (zc + R * np.cos(T)).ravel(), True, 1e-6)
    bmag = np.hypot(comp["br"], comp["bz"]).reshape(R.shape)
    gf = np.sqrt(comp["dbr_drho"] ** 2 + comp["br_over_rho"] ** 2 + comp["dbz_dz"] ** 2
                 + comp["dbr_dz"] ** 2 + comp["dbz_drho"] ** 2).reshape(R.shape)
    # running max from outside in keeps the bound monotone (max principle)
    eb = np.maximum.accumulate(bmag.max(axis=1)[::-1])[::-1] * 1.5
    eg = np.maximum.accumulate(gf.max(axis=1)[::-1])[::-1] * 1.5
    return zc, radii, eb, eg


def bound_at(coil: Coil, local: np.ndarray):
    """Bounds (|B|, |G|_F) per ampere at local points; inf inside the first sphere."""
    zc, radii, eb, eg = sphere_bounds(dataclasses.replace(coil, pose=Pose()))
    d = np.sqrt(local[:, 0] ** 2 + local[:, 1] ** 2 + (local[:, 2] - zc) ** 2)
    k = np.searchsorted(radii, d, side="right") - 1
    ok = k >= 0
    kb = np.where(ok, k, 0)
    return np.where(ok, eb[kb], np.inf), np.where(ok, eg[kb], np.inf)


def _graded(lo, hi, src_lo, src_hi, alpha, dmin):
    """Nodes on [lo, hi] with spacing alpha * max(distance to [src_lo, src_hi], dmin)."""
    xs = [lo]
    x = lo
    while x < hi:
        d = max(src_lo - x, x - src_hi, 0.0)
        # moving towards the sources the distance shrinks: use its value one step ahead
        step = alpha * max(d / (1.0 + alpha) if x < src_lo else d, dmin)
        x = min(x + step, hi)
        if hi - x < 0.3 * step:
            x = hi
        xs.append(x)
    if len(xs) < 5:
        xs = list(np.linspace(lo, hi, 5))
    return np.array(xs)


@dataclass(frozen=True)
class RZTable:
    """Bicubic splines of a coil's (rho, z) components per ampere on a graded tensor grid."""

    coil: Coil
    rho_nodes: np.ndarray
    z_nodes: np.ndarray
    splines: dict
    max_rel_error: dict
    scale: dict

    def covers(self, rho, z) -> bool:
        return bool(rho.min() >= self.rho_nodes[0] and rho.max() <= self.rho_nodes[-1]
                    and z.min() >= self.z_nodes[0] and z.max() <= self.z_nodes[-1])

    def __call__(self, rho, z, comps):
        # a spline outside its nodes extrapolates without warning: refuse instead
        if not self.covers(rho, z):
            raise BadInputError("table points", f"rho in [{self.rho_nodes[0]}, "
                                f"{self.rho_nodes[-1]}] m and z in [{self.z_nodes[0]}, "
                                f"{self.z_nodes[-1]}] m",
                                f"rho [{rho.min()}, {rho.max()}], z [{z.min()}, {z.max()}]")
        return {c: self.splines[c].ev(rho, z) for c in comps}

    @property
    def n_nodes(self) -> int:
        return len(self.rho_nodes) * len(self.z_nodes)


def build_table(coil: Coil, rho_range, z_range, comps, tolerance: float, *,
                max_refinements: int = 5, max_nodes: int | None = None) -> RZTable | None:
    """Table over [rho_range] x [z_range] (local, m) or None if that box touches the sources
    (or if reaching the tolerance would need more than ``max_nodes`` nodes).

    The grid is refined (spacing halved) until the spline's error at the cell centres, against
    direct evaluation, is <= ``tolerance`` x the component's largest |value| on the nodes.
    """
    rs, zs_lo, zs_hi = source_box(coil)
    r0, r1 = rho_range
    z0, z1 = z_range
    gap_r = r0 - rs
    gap_z = max(zs_lo - z1, z0 - zs_hi)
    if gap_r <= 0 and gap_z <= 0:
        return None
    dmin = math.hypot(max(gap_r, 0.0), max(gap_z, 0.0))
    if dmin < 1e-4:
        return None
    pad = 1e-3 * dmin
    r0, r1 = max(0.0, r0 - pad), r1 + pad
    z0, z1 = z0 - pad, z1 + pad
    needs_g = any(c != "br" and c != "bz" for c in comps)
    alpha = 0.3
    for _ in range(max_refinements + 1):
        rn = _graded(r0, r1, -1.0, rs, alpha, dmin)
        zn = _graded(z0, z1, zs_lo, zs_hi, alpha, dmin)
        if max_nodes is not None and len(rn) * len(zn) > max_nodes:
            return None  # direct evaluation of the points is cheaper
        R, Z = np.meshgrid(rn, zn, indexing="ij")
        vals = _rz_direct(coil, R.ravel(), Z.ravel(), needs_g)
        splines = {c: RectBivariateSpline(rn, zn, vals[c].reshape(R.shape), kx=3, ky=3, s=0)
                   for c in comps}
        scale = {c: float(np.max(np.abs(vals[c]))) or 1.0 for c in comps}
        rc = 0.5 * (rn[1:] + rn[:-1])
        zc = 0.5 * (zn[1:] + zn[:-1])
        Rc, Zc = np.meshgrid(rc, zc, indexing="ij")
        # the centres nearest the sources (where errors peak) plus a random sample
        dist = np.hypot(np.maximum(Rc - rs, 0.0),
                        np.maximum(np.maximum(zs_lo - Zc, Zc - zs_hi), 0.0)).ravel()
        rng = np.random.default_rng(0)
        sel = np.unique(np.r_[np.argsort(dist)[:300],
                              rng.choice(dist.size, min(dist.size, 300), replace=False)])
        rr, zz = Rc.ravel()[sel], Zc.ravel()[sel]
        ref = _rz_direct(coil, rr, zz, needs_g)
        err = {c: float(np.max(np.abs(splines[c].ev(rr, zz) - ref[c]))) / scale[c]
               for c in comps}
        worst = max(err.values())
        if worst <= tolerance:
            break
        # the spline error falls as h^4: aim just below the tolerance
        alpha *= min(0.7, max(0.25, 0.85 * (tolerance / worst) ** 0.25))
    return RZTable(coil, rn, zn, splines, err, scale)


# ============================================================================ the evaluator
@dataclass(frozen=True)
class SkippingResult:
    """Outputs of :meth:`SkippingEvaluator.evaluate`, SI. Per-ampere shapes without currents:
    'B' (n, 3, n_coils) T/A, 'gradient' (n, 5, n_coils) T/(m A) (rows 3-7 of A), 'force'
    (n, 3, n_coils) N/A, 'fz' (n, n_coils) N/A, 'torque' (n, 3, n_coils) N m/A; with currents
    the coil axis is summed: (n, 3), (n, 5), (n, 3), (n,), (n, 3)."""

    values: dict
    stats: dict = field(default_factory=dict)

    def __getitem__(self, key):
        return self.values[key]

    def actuation(self) -> np.ndarray:
        """A (n, 8, n_coils) from the 'B' and 'gradient' outputs."""
        if "B" not in self.values or "gradient" not in self.values:
            raise BadInputError("outputs", "to include 'B' and 'gradient' for actuation()",
                                tuple(self.values))
        return np.concatenate([self.values["B"], self.values["gradient"]], axis=1)


@dataclass(frozen=True)
class SkippingEvaluator:
    """What to compute: sources, points, outputs, tolerance.

    Parameters
    ----------
    array : CoilArray
    points : array-like, shape (n, 3), m
    outputs : tuple of {'B', 'gradient', 'force', 'fz', 'torque'}
    moment : array-like, shape (3,), A m^2
        Dipole for 'force', 'fz' (must be along z) and 'torque'.
    currents : array-like (n_coils,), A, or None for per-ampere columns.
    tolerance : float
        Relative to the largest value of each output over the points, in [1e-9, 0.1].
    tables : {'auto', 'always', 'never'}
        'auto' uses a coil type's table only when it serves > 4000 coil-point pairs and needs
        fewer than a third as many nodes as it serves pairs (else direct evaluation).
    skip : {'bound', 'never'}
    """

    array: CoilArray
    points: np.ndarray
    outputs: tuple = ("B", "gradient")
    moment: tuple | None = None
    currents: tuple | None = None
    tolerance: float = 1e-6
    tables: Literal["auto", "always", "never"] = "auto"
    skip: Literal["bound", "never"] = "bound"

    def __post_init__(self):
        if not isinstance(self.array, CoilArray):
            raise BadInputError("array", "a designkit.model.array.CoilArray", type(self.array).__name__)
        p, _ = v.points(self.points)
        object.__setattr__(self, "points", p)
        outs = (self.outputs,) if isinstance(self.outputs, str) else tuple(self.outputs)
        for o in outs:
            if o not in OUTPUTS:
                raise BadInputError("outputs", f"a tuple of {OUTPUTS}", o)
        if not outs:
            raise BadInputError("outputs", f"a non-empty tuple of {OUTPUTS}", outs)
        object.__setattr__(self, "outputs", outs)
        if any(o in ("force", "fz", "torque") for o in outs):
            if self.moment is None:
                raise BadInputError("moment", "a 3-vector (A m^2) for force/fz/torque", None)
        if self.moment is not None:
            m = v.vector3("moment", self.moment, "A m^2")
            object.__setattr__(self, "moment", tuple(m))
            if "fz" in outs and (m[0] != 0 or m[1] != 0):
                raise BadInputError("moment", "along z (mx = my = 0) for output 'fz'; ask "
                                    "for 'force' for a tilted dipole", tuple(m))
        if self.currents is not None:
            i = np.asarray(self.currents, dtype=float)
            if i.shape != (self.array.n_coils,) or not np.all(np.isfinite(i)):
                raise BadInputError("currents", f"{self.array.n_coils} finite values, A",
                                    self.currents)
            object.__setattr__(self, "currents", tuple(i))
        v.in_range("tolerance", self.tolerance, 1e-9, 0.1)
        if self.tables not in ("auto", "always", "never"):
            raise BadInputError("tables", "'auto', 'always' or 'never'", self.tables)
        if self.skip not in ("bound", "never"):
            raise BadInputError("skip", "'bound' or 'never'", self.skip)

    # ------------------------------------------------------------------ what is needed
    def _needs(self, coil: Coil) -> tuple[bool, tuple]:
        """(needs full gradient, rz components) for these outputs and a coil's orientation."""
        outs = set(self.outputs)
        comps: set[str] = set()
        if outs & {"B", "torque"}:
            comps |= {"br", "bz"}
        full_g = bool(outs & {"gradient", "force"})
        axis_z = abs(abs(coil.pose.matrix[2, 2]) - 1.0) < 1e-12
        if "fz" in outs:
            if axis_z:
                comps.add("dbz_dz")
            else:
                full_g = True
        if full_g:
            comps |= set(RZ_COMPONENTS)
        return full_g, tuple(c for c in RZ_COMPONENTS if c in comps)

    # ------------------------------------------------------------------ evaluation
    def evaluate(self) -> SkippingResult:
        p = self.points
        n, nc = len(p), self.array.n_coils
        outs = self.outputs
        m = np.asarray(self.moment) if self.moment is not None else None
        cur = np.asarray(self.currents) if self.currents is not None else None
        shapes = {"B": (3,), "gradient": (5,), "force": (3,), "fz": (), "torque": (3,)}
        per = {o: np.zeros((n,) + shapes[o] + (nc,)) for o in outs}
        keep = np.ones((nc, n), dtype=bool)
        stats = {"pairs": n * nc, "skipped": 0, "table_nodes": 0, "table_pairs": 0,
                 "table_error": {}}
        if self.skip == "bound":
            keep = self._keep_mask()
            stats["skipped"] = int((~keep).sum())
        for proto, idx in self.array.coil_types().items():
            full_g, comps = self._needs(self.array.coils[idx[0]])
            locs = [self.array.coils[k].pose.to_local(p) for k in idx]
            sel = [np.nonzero(keep[k])[0] for k in idx]
            rho = np.concatenate([np.hypot(l[s, 0], l[s, 1]) for l, s in zip(locs, sel)])
            zl = np.concatenate([l[s, 2] for l, s in zip(locs, sel)])
            if rho.size == 0:
                continue
            table = None
            if self.tables != "never" and (self.tables == "always" or rho.size > 4000):
                # 'auto': give up on the table when its nodes would cost more than the pairs
                table = build_table(proto, (rho.min(), rho.max()), (zl.min(), zl.max()),
                                    comps, 0.25 * self.tolerance,
                                    max_nodes=None if self.tables == "always" else rho.size // 3)
            if table is not None:
                vals = table(rho, zl, comps)
                if full_g:
                    vals["dbr_drho"] = -vals["dbz_dz"] - vals["br_over_rho"]
                    vals["dbz_drho"] = vals["dbr_dz"]
                stats["table_nodes"] += table.n_nodes
                stats["table_pairs"] += rho.size
                stats["table_error"][len(stats["table_error"])] = table.max_rel_error
            else:
                vals = _rz_direct(proto, rho, zl, full_g or "dbz_dz" in comps)
            start = 0
            for k, loc, s in zip(idx, locs, sel):
                cnt = len(s)
                part = {c: a[start:start + cnt] for c, a in vals.items()}
                start += cnt
                assemble(per, self.array.coils[k], k, s, loc[s], part, full_g, m)
        if cur is None:
            return SkippingResult(per, stats)
        return SkippingResult({o: a @ cur for o, a in per.items()}, stats)

    # ------------------------------------------------------------------ skipping
    def _keep_mask(self) -> np.ndarray:
        """(n_coils, n) True where a coil must be evaluated at a point."""
        p = self.points
        arr = self.array
        nc = arr.n_coils
        mm = np.linalg.norm(self.moment) if self.moment is not None else 0.0
        mz = abs(self.moment[2]) if self.moment is not None else 0.0
        locs = [c.pose.to_local(p) for c in arr.coils]
        bounds = [bound_at(c, l) for c, l in zip(arr.coils, locs)]
        eb = np.array([b[0] for b in bounds])  # (nc, n)
        eg = np.array([b[1] for b in bounds])
        fac = {"B": (eb, 1.0), "torque": (eb, mm), "gradient": (eg, 1.0), "force": (eg, mm),
               "fz": (eg, mz)}
        # a lower bound on each output's maximum over the points: exact values at the point nearest
        # each coil (those values exist, so the maximum is at least as large)
        near = np.unique([np.argmin(np.linalg.norm(l - [0, 0, c.length / 2], axis=1))
                          for c, l in zip(arr.coils, locs)])
        sub = SkippingEvaluator(arr, p[near], self.outputs, self.moment, self.currents, 1e-3,
                    tables="never", skip="never").evaluate()
        w = (np.ones(nc) if self.currents is None else np.abs(np.asarray(self.currents)))
        norm = np.zeros((nc, len(p)))
        for o in self.outputs:
            val = np.abs(sub[o])
            lower = float(val.max()) if val.size else 0.0
            if lower == 0.0:
                return np.ones((nc, len(p)), dtype=bool)
            e, f = fac[o]
            norm = np.maximum(norm, w[:, None] * f * e / (0.5 * self.tolerance * lower))
        if self.currents is None:
            return ~(norm <= 1.0)
        # summed outputs: skip the smallest contributions while their sum stays <= 1
        order = np.argsort(norm, axis=0)
        csum = np.cumsum(np.take_along_axis(norm, order, axis=0), axis=0)
        keep = np.ones_like(norm, dtype=bool)
        np.put_along_axis(keep, order, ~(csum <= 1.0), axis=0)
        return keep


def assemble(per: dict, coil: Coil, k: int, s, loc, part: dict, full_g: bool, m) -> None:
    """Write one coil's outputs at points ``s`` (local coordinates ``loc``) into ``per``.

    ``part`` holds the (rho, z) components per ampere; outputs go to column ``k``.
    """
    rho = np.hypot(loc[:, 0], loc[:, 1])
    pos = rho > 0
    c = np.where(pos, loc[:, 0] / np.where(pos, rho, 1.0), 1.0)
    sn = np.where(pos, loc[:, 1] / np.where(pos, rho, 1.0), 0.0)
    outs = set(per)
    if "br" in part or full_g:
        zero = np.zeros(len(s))
        comps = ("br", "bz") + (("dbr_drho", "dbr_dz", "dbz_drho", "dbz_dz", "br_over_rho")
                                if full_g else ())
        res = cylindrical_to_cartesian(c, sn, 1.0, [part.get(q, zero) for q in comps], full_g)
        b, g = res if full_g else (res, None)
    if "br" in part:
        b = coil.pose.vectors_to_global(b)
        if "B" in outs:
            per["B"][s, :, k] = b
        if "torque" in outs:
            per["torque"][s, :, k] = np.cross(m, b)
    if full_g:
        g = coil.pose.tensors_to_global(g)
        g5 = g5_from_gradient(g)
        if "gradient" in outs:
            per["gradient"][s, :, k] = g5
        if "force" in outs:
            per["force"][s, :, k] = g5 @ force_matrix(m).T
        if "fz" in outs:
            per["fz"][s, k] = m[2] * g[:, 2, 2]
    elif "fz" in outs:
        per["fz"][s, k] = m[2] * part["dbz_dz"]


def evaluate(array: CoilArray, points, outputs=("B", "gradient"), **kw) -> SkippingResult:
    """Shortcut: ``SkippingEvaluator(array, points, outputs, **kw).evaluate()``."""
    return SkippingEvaluator(array, points, outputs, **kw).evaluate()
