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

from firmware_io.allocation import allocate

from .. import _validate as v
from ..array import force_matrix
from ..errors import BadInputError


@dataclass(frozen=True)
class ArrayActuation:
    """Adapter giving designkit's CoilArray the map interface: ``actuation(points)`` (n, 8, nc),
    ``moment_a_m2`` (3,), ``design_sha256``, ``bounds`` (workspace box) and
    ``bias_force(points)`` (n, 3) N, the magnet's pull on the cores at zero current F0 (the
    coupled model directly: ~1.4 ms per point, the map's table ~20 us)."""

    array: object
    moment_a_m2: tuple
    design_sha256: str
    bounds: tuple
    rtol: float = 1e-6

    @classmethod
    def from_design(cls, design, rtol: float = 1e-6) -> "ArrayActuation":
        from ..array import CoilArray
        from ..fieldmap import default_box

        return cls(CoilArray.from_design(design), tuple(design.magnet.moment_vector_a_m2),
                   design.spec_hash(), default_box(design), rtol)

    def actuation(self, points) -> np.ndarray:
        return self.array.actuation_matrix(np.atleast_2d(points), rtol=self.rtol)

    def bias_force(self, points) -> np.ndarray:
        return self.array.bias_force(np.atleast_2d(points), np.asarray(self.moment_a_m2))


@dataclass(frozen=True)
class _MapSource:
    fieldmap: object
    moment_a_m2: tuple
    design_sha256: str
    bounds: tuple

    def actuation(self, points) -> np.ndarray:
        return np.ascontiguousarray(self.fieldmap.actuation(np.atleast_2d(points)))

    @property
    def bias_force(self):
        return getattr(self.fieldmap, "bias_force", None)


def actuation_source(fieldmap):
    """ArrayActuation as is; a FieldMap / MapFile (anything with ``actuation`` and ``meta``)
    wrapped with the moment and design hash its file records."""
    if isinstance(fieldmap, (ArrayActuation, _MapSource)):
        return fieldmap
    meta = getattr(fieldmap, "meta", None)
    if not callable(getattr(fieldmap, "actuation", None)) or not isinstance(meta, dict):
        raise BadInputError("fieldmap", "a designkit FieldMap, a firmware_io MapFile or an "
                            "ArrayActuation", type(fieldmap).__name__)
    return _MapSource(fieldmap, tuple(np.asarray(fieldmap.moment_a_m2, float)),
                      meta["design_sha256"],
                      tuple(np.asarray(b, float) for b in fieldmap.bounds))


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


def force_matrices(source, points, rows: str) -> np.ndarray:
    """Per-point force per ampere, (n, k, n_coils), N/A (k = 3 'force' or 1 'fz')."""
    a = source.actuation(points)
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
    fieldmap : FieldMap, MapFile or :class:`ArrayActuation` (designkit's CoilArray directly)
    current_limit_a, total_current_a : the bounds u_i and I_t, A
    unipolar : 0 <= I_i <= u_i (the thesis) instead of |I_i| <= u_i
    rows : 'force' (3-D lambda h n) or 'fz' (eq. 4.2: F_z = lambda h only)
    n_side : surface discretization (61 x 61 grid over the footprint, the thesis' 3721)

    The magnet's pull on the cores at zero current, F0, is included when the source provides
    ``bias_force`` (map v2); then lambda d - F0 must be renderable.
    """
    from .._progress import tqdm

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
    bias = src.bias_force(pts) if callable(src.bias_force) else np.zeros((len(pts), 3))
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
