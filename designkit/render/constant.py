"""The force constant lambda of thesis eq. 4.3, with the exact allocator.

lambda* = min over surface points j of lambda_j, where lambda_j is the largest lambda whose
required force at r_j is renderable within the current bounds (a max-min: the thesis solves it
with fminimax on the mean squared error; here every point must be met exactly, which is what
"renderable everywhere" means). Per point, lambda_j is found on the convex function
phi(lambda) = dist(lambda d_j - F0_j, reachable set) (sqrt of the allocator's residual; zero on
[0, lambda_j]) by secant steps from above (they never undershoot a convex phi) with a
bisection safeguard, to 1e-6 relative.

Required force per point (``rows``): 'force' -- the 3-D force lambda h(x, y) n (eq. 4.1 with
eq. 4.2's magnitude); 'fz' -- the thesis' eq. 4.2 literally: only F_z = lambda h(x, y).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from firmware_io.actuation import ActuationSource, selection
from firmware_io.allocation import allocate

from .. import _validate as v
from .._progress import tqdm
from ..array import CoilArray, force_matrix
from ..errors import BadInputError
from ..fieldmap import default_box


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
    tol = 1e-7

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


def _upper_bound(fm, d, u, tl, unipolar):
    """lambda such that lambda |d| exceeds the largest force along d (closed-form knapsack)."""
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
    return 1.01 * best / np.linalg.norm(d) + 1e-300


def force_constant(obj, fieldmap, *, current_limit_a: float, total_current_a: float,
                   unipolar: bool = False, rows: str = "force", n_side: int = 61,
                   rtol: float = 1e-6, progress: bool = True) -> ForceConstant:
    """Largest lambda (N/m) with every surface point's required force renderable (eq. 4.3).

    Parameters
    ----------
    obj : designkit.render.VirtualObject
    fieldmap : ActuationSource
        A FieldMap, a MapFile or an :class:`ArrayActuation` (designkit's CoilArray directly).
    current_limit_a, total_current_a : the bounds u_i and I_t, A
    unipolar : 0 <= I_i <= u_i (the thesis) instead of |I_i| <= u_i
    rows : 'force' (3-D lambda h n) or 'fz' (eq. 4.2: F_z = lambda h only)
    n_side : surface discretization (61 x 61 grid over the footprint, the thesis' 3721)

    The magnet's pull on the cores at zero current, F0 (the source's ``bias_force``), is
    included: lambda d - F0 must be renderable.
    """
    if rows not in ("force", "fz"):
        raise BadInputError("rows", "'force' or 'fz'", rows)
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
    n_c = fms.shape[2]
    uu = np.full(n_c, u)
    lam = np.empty(len(pts))
    for j in tqdm(range(len(pts)), desc="force constant", disable=not progress,
                  mininterval=2):
        d = d_all[j]
        if np.linalg.norm(d) == 0.0:
            lam[j] = np.inf
            continue
        ub = _upper_bound(fms[j], d, uu, tl, unipolar)
        lam[j] = _point_lambda(fms[j], d, bias[j], uu, tl, unipolar, rtol, ub)
    k = int(np.argmin(lam))
    return ForceConstant(float(lam[k]), pts[k].copy(), k, pts, nrm, heights, lam, excluded,
                         rows, bool(unipolar), float(u), float(tl))
