"""The force constant lambda of thesis eq. 4.3, with the exact allocator.

lambda* = min over surface points j of lambda_j, where lambda_j is the largest lambda whose
required force at r_j is renderable within the current bounds (a max-min: the thesis solves it
with fminimax on the mean squared error; here every point must be met exactly, which is what
"renderable everywhere" means). Per point (default, ``method='faces'``) lambda_j is a ray
leaving the reachable polytope R = F X: by LP duality lambda_j = min over R's facet normals w
facing d_j of (h(w) + w.F0_j) / (w.d_j), h the support function of R (a closed-form knapsack),
the facet normals cross products of pairs of the planes where h has a kink
(firmware_io.allocation.reach, all points at once). It is accepted when that candidate set is
complete (F of full rank, a well-conditioned minimizing normal), else when one allocation
renders lambda_j d_j - F0_j; otherwise, and with ``method='secant'`` (the reference), lambda_j
is found on the convex phi(lambda) = dist(lambda d_j - F0_j, R) (sqrt of the allocator's
residual; zero on [0, lambda_j]) by secant steps from above with a bisection safeguard, to
1e-6 relative. Method and timings: docs/rendering.md.

Required force per point (``rows``): 'force' -- the 3-D force lambda h(x, y) n (eq. 4.1 with
eq. 4.2's magnitude); 'fz' -- the thesis' eq. 4.2 literally: only F_z = lambda h(x, y).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from firmware_io.actuation import ActuationSource, selection
from firmware_io.allocation import Allocator, allocate
from firmware_io.allocation.reach import ray_limits

from ..errors import BadInputError
from ..fieldmap import default_box
from ..model.array import CoilArray, force_matrix
from ..support import validate as v
from ..support.progress import tqdm

_OK_TOL = 1e-7
"""lambda d - F0 counts as renderable when the allocator's residual norm is <= this x
max(lambda |d|, |F0|)."""
_RANK_TOL = 1e-6    # F's smallest / largest singular value: below, the faces may be incomplete
_COND_TOL = 1e-6    # sin(plane angle) x cos(normal, d) of the minimizing normal: below, verify
_FLOAT_MAX = np.finfo(float).max  # ray_limits' "no bound found"


@dataclass(frozen=True, eq=False)
class ArrayActuation:
    """designkit's coupled CoilArray as an :class:`~firmware_io.actuation.ActuationSource`: the
    direct model, without a map's interpolation (and at a map's cost per point many times over:
    docs/rendering.md).

    Attributes
    ----------
    array : CoilArray
    moment_a_m2 : ndarray, shape (3,), A m^2 -- the finger magnet's moment (read-only)
    design_sha256 : str
    bounds : (lower (3,), upper (3,)), m -- the workspace box
    rtol : float -- relative accuracy of the winding quadrature
    """

    array: CoilArray
    moment_a_m2: np.ndarray
    design_sha256: str
    bounds: tuple
    rtol: float = 1e-6

    def __post_init__(self):
        m = np.array(self.moment_a_m2, dtype=float).reshape(3)
        m.flags.writeable = False
        object.__setattr__(self, "moment_a_m2", m)

    @classmethod
    def from_design(cls, design, rtol: float = 1e-6) -> "ArrayActuation":
        return cls(CoilArray.from_design(design), design.magnet.moment_vector_a_m2,
                   design.spec_hash(), default_box(design), rtol)

    @property
    def n_coils(self) -> int:
        return self.array.n_coils

    def actuation(self, points, *, rows=None, coils=None) -> np.ndarray:
        """The coupled A (thesis eq. 2.13): (3,) -> (r, c), (n, 3) -> (n, r, c); T/A and
        T/(m A). ``rows``, ``coils``: index sequences into the eight rows and the coils,
        selected after computing all of them (r = len(rows), c = len(coils))."""
        r_sel = selection("rows", rows, 8, BadInputError)
        c_sel = selection("coils", coils, self.n_coils, BadInputError)
        a = self.array.actuation_matrix(points, rtol=self.rtol)
        if r_sel is not None:
            a = a.take(r_sel, axis=-2)
        if c_sel is not None:
            a = a.take(c_sel, axis=-1)
        return a

    def bias_force(self, points) -> np.ndarray:
        """F0, the magnet's pull on the cores at zero current, N: (3,) -> (3,), (n, 3) -> (n, 3)."""
        return self.array.bias_force(points, self.moment_a_m2)

    @property
    def sensor_positions_m(self) -> np.ndarray:
        """(n_sensors, 3) m: the upper array's sensors in coil order, then the lower array's
        (the map's flat order)."""
        return np.asarray(self.array.sensor_positions_m(), float).reshape(-1, 3)

    @property
    def n_sensors(self) -> int:
        return len(self.sensor_positions_m)

    def sensor_coil_field(self, currents=None) -> np.ndarray:
        """The coils' coupled field at the sensors: (n_sensors, 3, n_coils) T/A, or (n_sensors,
        3) T at ``currents`` (n_coils,) A (the direct model, as the map stores it)."""
        g = self.array.actuation_matrix(self.sensor_positions_m, rtol=self.rtol)[:, :3, :]
        if currents is None:
            return g
        i = np.asarray(currents, float)
        if i.shape != (self.n_coils,) or not np.all(np.isfinite(i)):
            raise BadInputError("currents", f"{self.n_coils} finite values, A", i.tolist())
        return g @ i


def actuation_source(fieldmap) -> ActuationSource:
    """``fieldmap`` itself once it is an :class:`~firmware_io.actuation.ActuationSource` (a
    designkit FieldMap, a firmware_io MapFile or an ArrayActuation); BadInputError if not."""
    if not isinstance(fieldmap, ActuationSource):
        raise BadInputError("fieldmap", "a designkit FieldMap, a firmware_io MapFile or an "
                            "ArrayActuation", type(fieldmap).__name__)
    return fieldmap


@dataclass(frozen=True)
class ForceConstant:
    """Result of :func:`force_constant`.

    lam_n_per_m : lambda*, N/m;  limiting_point_m : (3,) where it is reached;
    points_m (n, 3), normals (n, 3), heights_m (n,), lam_per_point (n,) N/m: the per-point
    largest lambda; excluded : surface points outside the map's box (not evaluated).
    """

    lam_n_per_m: float
    limiting_point_m: np.ndarray
    limiting_index: int
    points_m: np.ndarray
    normals: np.ndarray
    heights_m: np.ndarray
    lam_per_point: np.ndarray
    excluded: int
    rows: str
    unipolar: bool
    current_limit_a: float
    total_current_a: float

    @property
    def unrenderable_points(self) -> int:
        """Surface points where no lambda > 0 is renderable (lambda_j = 0: there the magnet's
        pull on the cores, F0, is beyond what the coils can cancel)."""
        return int(np.sum(self.lam_per_point <= 0.0))

    def lam_where_renderable(self) -> float:
        """lambda*, N/m, over the points where some lambda > 0 is renderable (0 when none is):
        a few points at the workspace's floor over a core would otherwise make the whole
        object's lambda 0."""
        ok = self.lam_per_point > 0.0
        return float(self.lam_per_point[ok].min()) if ok.any() else 0.0

    def limiting_point_where_renderable(self) -> np.ndarray:
        """(3,) m: where :meth:`lam_where_renderable` is reached (the overall limiting point
        when no point is renderable)."""
        lam = np.where(self.lam_per_point > 0.0, self.lam_per_point, np.inf)
        k = int(np.argmin(lam)) if np.isfinite(lam).any() else self.limiting_index
        return self.points_m[k].copy()


def _targets(rows, normals, heights):
    if rows == "force":
        return heights[:, None] * normals
    return heights[:, None]


def force_matrices(source: ActuationSource, points, rows: str) -> np.ndarray:
    """Per-point force per ampere at points (n, 3) m, (n, k, n_coils), N/A (k = 3 'force' or
    1 'fz')."""
    a = np.ascontiguousarray(source.actuation(np.atleast_2d(points)))
    fm = force_matrix(source.moment_a_m2) @ a[:, 3:, :]
    return fm if rows == "force" else fm[:, 2:3, :]


def _point_lambda(fm, d, f0, u, tl, unipolar, rtol, ub):
    """Largest lambda with lambda d - f0 renderable (secant from above, bisection guard)."""
    def phi(lam):
        return float(np.sqrt(allocate(fm, lam * d - f0, u, tl, unipolar=unipolar)[1]))

    scale = float(np.linalg.norm(d))
    tol = _OK_TOL

    def ok(lam, ph):
        return ph <= tol * max(lam * scale, float(np.linalg.norm(f0)), 1e-300)

    if not ok(0.0, phi(0.0)):
        return 0.0
    lo, hi = 0.0, ub
    p_hi = phi(hi)
    if ok(hi, p_hi):
        return hi
    prev = None
    for _ in range(60):
        cand = None
        if prev is not None and prev[0] > hi and prev[1] > p_hi:
            slope = (prev[1] - p_hi) / (prev[0] - hi)
            cand = hi - p_hi / slope
        if cand is None or not (lo < cand < hi):
            cand = 0.5 * (lo + hi)
        p = phi(cand)
        if ok(cand, p):
            lo = cand
        else:
            prev, hi, p_hi = (hi, p_hi), cand, p
        if hi - lo <= rtol * hi:
            break
    return lo


def _upper_bound(fm, d, f0, u, tl, unipolar):
    """lambda such that lambda |d| exceeds the largest force along d plus F0's part along d
    (closed-form knapsack: lambda d - F0 renderable needs d.(lambda d - F0) / |d| <= that)."""
    dn = d / np.linalg.norm(d)
    c = dn @ fm  # force along d per ampere, (n_coils,)
    c = np.maximum(c, 0.0) if unipolar else np.abs(c)
    order = np.argsort(-c)
    left, best = tl, 0.0
    for k in order:
        take = min(u[k], left)
        best += take * c[k]
        left -= take
        if left <= 0:
            break
    best += max(float(dn @ f0), 0.0)
    return 1.01 * best / np.linalg.norm(d) + 1e-300


def _renders(alloc, fm, lam, d, f0, u, tl, unipolar):
    """lambda d - f0 renderable by the allocator's criterion (`_point_lambda`'s ok)."""
    res = alloc(fm, lam * d - f0, u, tl, unipolar=unipolar)[1]
    return math.sqrt(res) <= _OK_TOL * max(lam * float(np.linalg.norm(d)),
                                           float(np.linalg.norm(f0)), 1e-300)


def _bias_renderable(fms, bias, u, tl, unipolar):
    """(m,) bool, sufficient for -F0 reachable: the currents nearest to the middle of the
    bounds c (c = 0 bipolar, min(u / 2, I_t / 2n) unipolar) with F I = -F0, I = c + F^T (F
    F^T)^-1 (-F0 - F c), fit it and lie inside the bounds."""
    m, k, n = fms.shape
    c = np.minimum(u / 2, 0.5 * tl / n) if unipolar else np.zeros(n)
    g = np.einsum("mkn,mln->mkl", fms, fms)
    g = g + (1e-14 * np.trace(g, axis1=1, axis2=2))[:, None, None] * np.eye(k)
    rhs = -bias - fms.dot(c)
    try:
        y = np.linalg.solve(g, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return np.zeros(m, bool)
    i0 = c + np.einsum("mkn,mk->mn", fms, y)
    fit = np.linalg.norm(np.einsum("mkn,mn->mk", fms, i0) + bias, axis=1) \
        <= 1e-9 * np.linalg.norm(bias, axis=1)
    box = (np.abs(i0) <= u) if not unipolar else ((i0 >= 0.0) & (i0 <= u))
    return fit & box.all(axis=1) & (np.abs(i0).sum(axis=1) <= tl)


def _well_posed(fms, cond):
    """(m,) bool: the candidate set is complete (F of full row rank) and the minimizing normal
    is not a near-degenerate cross product (its rounding far below the tolerance)."""
    sv = np.linalg.svd(fms, compute_uv=False)
    return (sv[:, -1] > _RANK_TOL * sv[:, 0]) & (cond > _COND_TOL)


def _faces_lambdas(fms, d_all, bias, u, tl, unipolar, rtol, progress):
    """Per-point lambda from the reachable set's faces (`firmware_io.allocation.reach`): the
    dual bound lambda_up, accepted when the candidate facets are complete and well posed, or
    else when one warm-started allocation renders lambda_up d - F0 (then lambda_up is exact:
    it is also an upper bound). Anything else goes to the secant search `_point_lambda`."""
    m, k, _ = fms.shape
    lam = np.full(m, np.inf)
    live = np.flatnonzero(np.linalg.norm(d_all, axis=1) > 0.0)
    fl, dl, bl = fms[live], d_all[live], bias[live]
    up, sep, _, cond = ray_limits(fl, dl, bl, u, tl, unipolar=unipolar)
    proven = _well_posed(fl, cond) if k == 3 else np.ones(len(live), bool)
    inside0 = _bias_renderable(fl, bl, u, tl, unipolar)
    tol0 = _OK_TOL * np.maximum(np.linalg.norm(bl, axis=1), 1e-300)
    x = np.maximum(up, 0.0)
    # -F0 outside the reachable set by more than the tolerance (what `_point_lambda` tests)
    out = sep > tol0
    inside = ~out & (inside0 | (proven & (sep < -tol0)))
    res = np.where(out, 0.0, np.where(inside & proven & (x < _FLOAT_MAX), x, np.nan))
    alloc = Allocator()
    left = np.flatnonzero(np.isnan(res)).tolist()
    # a bar only when points are left to the allocator (an empty one printed "0it" twice)
    for i in tqdm(left, desc="force constant: points checked by the allocator",
                  disable=not progress or not left, mininterval=2):
        fm, d, f0, xi = fl[i], dl[i], bl[i], float(x[i])
        ok = inside[i] and xi < _FLOAT_MAX and _renders(alloc, fm, xi, d, f0, u, tl,
                                                          unipolar)
        res[i] = xi if ok else _point_lambda(fm, d, f0, u, tl, unipolar, rtol,
                                             _upper_bound(fm, d, f0, u, tl, unipolar))
    lam[live] = res
    return lam


def _secant_lambdas(fms, d_all, bias, u, tl, unipolar, rtol, progress):
    """Per-point lambda by the secant search on the allocator's residual (the reference)."""
    lam = np.empty(len(fms))
    for j in tqdm(range(len(fms)), desc="force constant", disable=not progress or not len(fms),
                  mininterval=2):
        d = d_all[j]
        if np.linalg.norm(d) == 0.0:
            lam[j] = np.inf
            continue
        ub = _upper_bound(fms[j], d, bias[j], u, tl, unipolar)
        lam[j] = _point_lambda(fms[j], d, bias[j], u, tl, unipolar, rtol, ub)
    return lam


@dataclass(frozen=True)
class ConstantSettings:
    """How :func:`force_constant` computes lambda.

    Attributes
    ----------
    unipolar : 0 <= I_i <= u_i (the thesis) instead of |I_i| <= u_i
    rows : 'force' (3-D lambda h n) or 'fz' (eq. 4.2: F_z = lambda h only)
    n_side : surface discretization (61 x 61 grid over the footprint, the thesis' 3721)
    rtol : relative tolerance of the secant search (the reference, and the faces' fallback);
        the faces' accepted values are exact to rounding
    method : 'faces' (default: the reachable set's facets, each point's lambda confirmed by
        the allocator or by the facets' completeness) or 'secant' (the secant search on the
        allocator's residual per point, the reference; both to ``rtol``)
    """

    unipolar: bool = False
    rows: str = "force"
    n_side: int = 61
    rtol: float = 1e-6
    method: str = "faces"


def force_constant(obj, fieldmap, *, current_limit_a: float, total_current_a: float,
                   settings: ConstantSettings | None = None, progress: bool = True,
                   **changes) -> ForceConstant:
    """Largest lambda (N/m) with every surface point's required force renderable (eq. 4.3).

    Parameters
    ----------
    obj : designkit.render.VirtualObject
    fieldmap : ActuationSource
        A FieldMap, a MapFile or an :class:`ArrayActuation` (designkit's CoilArray directly).
    current_limit_a, total_current_a : the bounds u_i and I_t, A
    settings : ConstantSettings or None (its defaults); ``changes``: fields of it to replace
        (``force_constant(..., rows="fz")``), a name that is no field refused
    progress : one progress bar over the surface points

    The magnet's pull on the cores at zero current, F0 (the source's ``bias_force``), is
    included: lambda d - F0 must be renderable.
    """
    names = {f.name for f in dataclasses.fields(ConstantSettings)}
    for key in changes:
        if key not in names:
            raise BadInputError("force_constant setting", f"one of {sorted(names)}", key)
    st = dataclasses.replace(settings or ConstantSettings(), **changes)
    unipolar, rows, n_side, rtol, method = st.unipolar, st.rows, st.n_side, st.rtol, st.method
    if rows not in ("force", "fz"):
        raise BadInputError("rows", "'force' or 'fz'", rows)
    if method not in ("faces", "secant"):
        raise BadInputError("method", "'faces' or 'secant'", method)
    u = v.nonnegative("current_limit_a", current_limit_a, "A")
    tl = v.nonnegative("total_current_a", total_current_a, "A")
    src = actuation_source(fieldmap)
    pts, nrm = obj.surface_points(n_side)
    lo, hi = (np.asarray(b, float) for b in src.bounds)
    inside = np.all((pts >= lo - 1e-12) & (pts <= hi + 1e-12), axis=1)
    if not inside.any():
        raise BadInputError("object", f"a surface inside the map's box {lo.tolist()} .. "
                            f"{hi.tolist()} m", type(obj).__name__)
    excluded = int((~inside).sum())
    pts, nrm = pts[inside], nrm[inside]
    heights = obj.height(pts)
    d_all = _targets(rows, nrm, heights)
    fms = force_matrices(src, pts, rows)
    bias = src.bias_force(pts)
    bias = bias if rows == "force" else bias[:, 2:3]
    uu = np.full(fms.shape[2], u)
    degenerate = u == 0.0 or tl == 0.0  # the reachable set is a point: no faces
    run = _secant_lambdas if method == "secant" or degenerate else _faces_lambdas
    lam = run(fms, d_all, bias, uu, tl, unipolar, rtol, progress)
    k = int(np.argmin(lam))
    return ForceConstant(float(lam[k]), pts[k].copy(), k, pts, nrm, heights, lam, excluded,
                         rows, bool(unipolar), float(u), float(tl))
