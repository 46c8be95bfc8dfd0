"""Virtual objects and force laws for the rendering runner -- numpy only.

What the runner needs at each loop: the object's signed distance g(p) (m, negative inside),
its outward unit normal n(p), the height function h(x, y) of the thesis' eq. 4.2 and a force
law. designkit.render *builds* objects and compiles scenes; this module only *evaluates* the
compiled arrays (one definition, shared by both).

Objects (all solids standing on the coil-top plane z = z0, array frame, z up, SI):

* ``box``: centre (3,), half sizes (3,) -- the thesis' flat surface is its top face;
* ``half_ball``: base centre (3,), radius -- the hemisphere;
* ``half_cylinder``: base-axis centre (3,), radius, half length along y;
* ``prism``: a convex polygon in the (x, z) plane (vertices (m, 2), counter-clockwise),
  extruded along y with a half length -- the wedge is a triangle;
* ``grid``: a signed-distance grid (nx, ny, nz) with its normal grid (nx, ny, nz, 3) and a
  height map (nx, ny) (meshes, precomputed offline by designkit.render).

Analytic signed distances are exact; normals are the gradient of g (central differences of
the exact g with a 10 nm step: exact away from edges, a unit vector of the subgradient on them).
The height h(x, y) is the top of the solid above z0 at (x, y) (0 outside the footprint).

Force laws (``constraint_force``, ``penetration_force``) return N, shape (n, 3). Only the upper
side is renderable: where the outward normal points down (n_z < 0, the underside of a mesh)
both laws return zero force -- a planar array below the hand cannot hold the finger up against
a surface above it (thesis section 4.1.1).
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from pathlib import Path

import numpy as np

from .errors import BadInputError

FORMAT = "designkit-scene"
FORMAT_VERSION = 1
_FD_STEP_M = 1e-8


# ============================================================================ analytic objects
def _half_disc_sdf(r_in_plane, h, radius):
    """Exact SDF of the half disc {rho^2 + h^2 <= R^2, h >= 0} with rho = |r_in_plane| >= 0."""
    rho = np.abs(r_in_plane)
    r = np.hypot(rho, h)
    inside_or_above = h >= 0
    d_up = np.where(r <= radius, np.maximum(r - radius, -h), r - radius)
    d_down = np.where(rho <= radius, -h, np.hypot(rho - radius, h))
    return np.where(inside_or_above, d_up, d_down)


def _extrude(d2, y, half_length):
    """Exact SDF of a 2-D shape (SDF d2) extruded over |y| <= half_length."""
    wy = np.abs(y) - half_length
    out = np.hypot(np.maximum(d2, 0.0), np.maximum(wy, 0.0))
    return out + np.minimum(np.maximum(d2, wy), 0.0)


def _polygon_sdf(px, pz, verts):
    """Exact SDF of a convex polygon (m, 2), counter-clockwise, at points (px, pz)."""
    v0 = verts
    v1 = np.roll(verts, -1, axis=0)
    e = v1 - v0  # (m, 2)
    wx = px[:, None] - v0[None, :, 0]
    wz = pz[:, None] - v0[None, :, 1]
    t = np.clip((wx * e[:, 0] + wz * e[:, 1]) / (e * e).sum(axis=1), 0.0, 1.0)
    dist = np.hypot(wx - t * e[:, 0], wz - t * e[:, 1]).min(axis=1)
    # counter-clockwise: inside iff left of every edge
    cross = e[:, 0] * wz - e[:, 1] * wx
    inside = np.all(cross >= 0, axis=1)
    return np.where(inside, -dist, dist)


def analytic_sdf(kind: str, params: dict, p: np.ndarray) -> np.ndarray:
    """g(p), m, shape (n,), for an analytic object (see the module docstring)."""
    if kind == "box":
        q = np.abs(p - params["centre_m"]) - params["half_size_m"]
        return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
    if kind == "half_ball":
        c = params["centre_m"]
        rho = np.hypot(p[:, 0] - c[0], p[:, 1] - c[1])
        return _half_disc_sdf(rho, p[:, 2] - c[2], params["radius_m"])
    if kind == "half_cylinder":
        c = params["centre_m"]
        d2 = _half_disc_sdf(p[:, 0] - c[0], p[:, 2] - c[2], params["radius_m"])
        return _extrude(d2, p[:, 1] - c[1], params["half_length_m"])
    if kind == "prism":
        c = params["centre_m"]
        d2 = _polygon_sdf(p[:, 0] - c[0], p[:, 2] - c[2], params["polygon_xz_m"])
        return _extrude(d2, p[:, 1] - c[1], params["half_length_m"])
    raise BadInputError("object kind", "'box', 'half_ball', 'half_cylinder', 'prism' or "
                        "'grid'", kind)


def analytic_height(kind: str, params: dict, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Height function h(x, y) of eq. 4.2: z of the solid's top at (x, y) above the coil-top
    plane z = 0, m (0 outside the footprint; the thesis: 0.3 N = 6 N/m x 5 cm)."""
    c = params["centre_m"]
    dx, dy = x - c[0], y - c[1]
    if kind == "box":
        hs = params["half_size_m"]
        inside = (np.abs(dx) <= hs[0]) & (np.abs(dy) <= hs[1])
        return np.where(inside, c[2] + hs[2], 0.0)
    if kind == "half_ball":
        r2 = params["radius_m"] ** 2 - dx * dx - dy * dy
        return np.where(r2 >= 0, c[2] + np.sqrt(np.maximum(r2, 0.0)), 0.0)
    if kind == "half_cylinder":
        r2 = params["radius_m"] ** 2 - dx * dx
        inside = (np.abs(dy) <= params["half_length_m"]) & (r2 >= 0)
        return np.where(inside, c[2] + np.sqrt(np.maximum(r2, 0.0)), 0.0)
    if kind == "prism":
        poly = params["polygon_xz_m"]
        inside = np.abs(dy) <= params["half_length_m"]
        # top of a convex polygon at abscissa dx: max over non-vertical edges of their z at dx
        v0, v1 = poly, np.roll(poly, -1, axis=0)
        lo, hi = np.minimum(v0[:, 0], v1[:, 0]), np.maximum(v0[:, 0], v1[:, 0])
        run = v1[:, 0] - v0[:, 0]
        t = (dx[:, None] - v0[None, :, 0]) / np.where(run != 0, run, 1.0)
        z = v0[None, :, 1] + t * (v1[:, 1] - v0[:, 1])
        ok = (dx[:, None] >= lo) & (dx[:, None] <= hi) & (run != 0)
        top = np.where(ok, z, -np.inf).max(axis=1)
        return np.where(inside & np.isfinite(top), c[2] + np.maximum(top, 0.0), 0.0)
    raise BadInputError("object kind", "'box', 'half_ball', 'half_cylinder' or 'prism'", kind)


# ============================================================================ grid objects
def _trilinear(grid: np.ndarray, lower, spacing, p: np.ndarray) -> np.ndarray:
    """Trilinear interpolation of grid (nx, ny, nz[, c]) at points (n, 3); clamps outside."""
    shape = np.asarray(grid.shape[:3])
    f = (p - lower) / spacing
    f = np.clip(f, 0.0, shape - 1.0)
    i = np.minimum(f.astype(np.intp), shape - 2)
    t = f - i
    out = 0.0
    for a in (0, 1):
        wa = t[:, 0] if a else 1.0 - t[:, 0]
        for b in (0, 1):
            wb = t[:, 1] if b else 1.0 - t[:, 1]
            for c in (0, 1):
                wc = t[:, 2] if c else 1.0 - t[:, 2]
                w = wa * wb * wc
                v = grid[i[:, 0] + a, i[:, 1] + b, i[:, 2] + c]
                out = out + (w[:, None] * v if v.ndim == 2 else w * v)
    return out


def _bilinear(grid: np.ndarray, lower, spacing, x, y) -> np.ndarray:
    shape = np.asarray(grid.shape)
    f = np.stack([(x - lower[0]) / spacing[0], (y - lower[1]) / spacing[1]], axis=1)
    outside = np.any((f < 0) | (f > shape - 1), axis=1)
    f = np.clip(f, 0.0, shape - 1.0)
    i = np.minimum(f.astype(np.intp), shape - 2)
    t = f - i
    v = (grid[i[:, 0], i[:, 1]] * (1 - t[:, 0]) * (1 - t[:, 1])
         + grid[i[:, 0] + 1, i[:, 1]] * t[:, 0] * (1 - t[:, 1])
         + grid[i[:, 0], i[:, 1] + 1] * (1 - t[:, 0]) * t[:, 1]
         + grid[i[:, 0] + 1, i[:, 1] + 1] * t[:, 0] * t[:, 1])
    return np.where(outside, 0.0, v)


# ============================================================================ one object
class SceneObject:
    """One compiled object: ``kind``, ``params`` (floats/arrays, SI) and for grids the arrays.

    Methods are vectorized over points (n, 3) in m.
    """

    def __init__(self, kind: str, params: dict, arrays: dict | None = None):
        self.kind = kind
        self.params = {k: (np.asarray(v, float) if isinstance(v, (list, tuple)) else v)
                       for k, v in params.items()}
        self.arrays = arrays or {}
        if kind == "grid":
            for name in ("sdf", "normal", "height"):
                if name not in self.arrays:
                    raise BadInputError("grid object", "arrays sdf, normal and height",
                                        sorted(self.arrays))
            self._lower = np.asarray(self.params["lower_m"], float)
            self._spacing = np.asarray(self.params["spacing_m"], float)

    def signed_distance(self, points) -> np.ndarray:
        """g(p), m, shape (n,): negative inside the solid."""
        p = _points(points)
        if self.kind == "grid":
            g = _trilinear(self.arrays["sdf"], self._lower, self._spacing, p).astype(float)
            # outside the grid box: the box distance adds to the boundary value
            lo = self._lower
            hi = lo + self._spacing * (np.asarray(self.arrays["sdf"].shape) - 1)
            out = np.linalg.norm(np.maximum(lo - p, 0) + np.maximum(p - hi, 0), axis=1)
            return g + out
        return analytic_sdf(self.kind, self.params, p)

    def normal(self, points) -> np.ndarray:
        """Outward unit normal (the gradient of g), shape (n, 3)."""
        p = _points(points)
        if self.kind == "grid":
            n = _trilinear(self.arrays["normal"], self._lower, self._spacing, p).astype(float)
        else:
            # the six shifted copies in one call (a control step evaluates one point: the
            # call overhead, not the arithmetic, is what costs)
            d = _FD_STEP_M * np.eye(3)
            q = np.concatenate([p[None] + d[:, None], p[None] - d[:, None]]).reshape(-1, 3)
            g = analytic_sdf(self.kind, self.params, q).reshape(2, 3, len(p))
            n = (g[0] - g[1]).T.copy()
        nrm = np.linalg.norm(n, axis=1)
        bad = nrm < 1e-12
        n[bad] = (0.0, 0.0, 1.0)
        nrm[bad] = 1.0
        return n / nrm[:, None]

    def top_normal(self, points, height_m=None) -> np.ndarray:
        """Outward normal of the top surface at (x, y, h(x, y)) (the normal of eq. 4.1 at the
        surface point r_j the finger is over), shape (n, 3): the gradient of g 10 um above it,
        where the nearest surface point is the top one even on the rim of a face.
        ``height_m``: h(x, y) (n,) m when the caller has it already."""
        p = _points(points)
        h = self.height(p) if height_m is None else np.asarray(height_m, float)
        top = p.copy()
        top[:, 2] = h + 1e-5
        return self.normal(top)

    def height(self, points) -> np.ndarray:
        """h(x, y) of eq. 4.2: the top of the solid above its base plane, m, shape (n,)."""
        p = _points(points)
        if self.kind == "grid":
            return _bilinear(self.arrays["height"], self._lower, self._spacing,
                             p[:, 0], p[:, 1]).astype(float)
        return analytic_height(self.kind, self.params, p[:, 0], p[:, 1])


def _points(points) -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim == 1:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 3:
        raise BadInputError("points", "shape (3,) or (n, 3), m", f"shape {np.shape(points)}")
    if not np.all(np.isfinite(p)):
        raise BadInputError("points", "finite (no NaN or Inf), m", p.tolist()[:3])
    return p


# ============================================================================ force laws
def constraint_force(obj: SceneObject, points, lam_n_per_m: float, *,
                     contact_band_m: float = 0.0) -> np.ndarray:
    """The thesis' law (eqs. 4.1-4.2): F = lambda h(x, y) n_top(x, y) where g(p) <= band, else
    0 (n_top: the outward normal of the top surface at (x, y, h(x, y))).

    Parameters
    ----------
    obj : SceneObject
    points : (n, 3) or (3,), m -- the magnet (finger) positions
    lam_n_per_m : float -- the force constant lambda, N/m
    contact_band_m : float -- also render this far outside the surface, m (default 0)

    Returns
    -------
    (n, 3) N; zero outside contact and where the normal points down (not renderable).
    """
    p = _points(points)
    g = obj.signed_distance(p)
    h = obj.height(p)
    n = obj.top_normal(p, h)
    mag = lam_n_per_m * h
    on = (g <= contact_band_m) & (n[:, 2] >= 0.0)
    return np.where(on[:, None], mag[:, None] * n, 0.0)


def passivity_stiffness_bound(loop_period_s: float, device_damping_n_s_per_m: float,
                              virtual_damping_n_s_per_m: float, position_noise_m: float,
                              threshold_n: float) -> tuple[float, str]:
    """Largest wall stiffness, N/m, and which bound limits it.

    Colgate & Brown (1994): a virtual wall K, B sampled at period T on a device with physical
    damping b is passive if b > K T / 2 + |B|, i.e. K < 2 (b - |B|) / T. The magnet floats:
    b is the finger's own damping (an assumption the caller states). Position noise sigma
    makes force noise K sigma, kept below the human detection threshold: K <= F_thr / sigma.
    """
    k_pass = 2.0 * max(device_damping_n_s_per_m - abs(virtual_damping_n_s_per_m), 0.0) \
        / loop_period_s
    k_noise = threshold_n / position_noise_m if position_noise_m > 0 else np.inf
    return (k_pass, "passivity") if k_pass <= k_noise else (k_noise, "position noise")


def penetration_force(obj: SceneObject, points, velocities, stiffness_n_per_m: float,
                      damping_n_s_per_m: float) -> np.ndarray:
    """God-object (proxy) law: the proxy stays on the surface at the closest point, so inside
    the solid F = K (-g) n - B (v . n) n, never pulling (F . n >= 0); 0 outside. (n, 3) N.
    Where the closest surface faces down (the base on the coils, a mesh's underside) the proxy
    is the top surface above instead: depth h(x, y) - z along its normal.

    Clamp K with :func:`passivity_stiffness_bound` before calling (the compiled scene stores
    the clamped value).
    """
    p = _points(points)
    v = np.broadcast_to(np.asarray(velocities, float), p.shape)
    g = obj.signed_distance(p)
    n = obj.normal(p)
    depth = np.maximum(-g, 0.0)
    # nearest surface facing down (the base, an underside): push out through the top instead
    down = n[:, 2] < 0.0
    if down.any():
        n[down] = obj.top_normal(p[down])
        depth[down] = np.maximum(obj.height(p[down]) - p[down, 2], 0.0)
    fn = stiffness_n_per_m * depth - damping_n_s_per_m * np.einsum("ij,ij->i", v, n)
    fn = np.where((g < 0) & (n[:, 2] >= 0.0), np.maximum(fn, 0.0), 0.0)
    return fn[:, None] * n


# ============================================================================ scene file
def _bad(path, what):
    return BadInputError("scene file", f"a designkit compiled scene ({what})", str(path))


def _hash(arrays: dict) -> str:
    h = hashlib.sha256()
    for name in sorted(arrays):
        h.update(name.encode())
        h.update(np.ascontiguousarray(arrays[name]).tobytes())
    return h.hexdigest()


class Scene:
    """A loaded scene: ``objects`` (list of SceneObject), ``meta`` (dict), ``lam_n_per_m``,
    ``law`` parameters, the map's ``design_sha256``."""

    def __init__(self, objects, meta):
        self.objects = objects
        self.meta = meta

    @property
    def lam_n_per_m(self) -> float:
        return float(self.meta["lambda_n_per_m"])

    def force(self, points, velocities=None) -> np.ndarray:
        """Required force on the magnet at points (n, 3), N, by the scene's law, summed over
        objects (the runner allocates it with firmware_io.allocation)."""
        p = _points(points)
        law = self.meta["law"]
        out = np.zeros_like(p)
        for obj in self.objects:
            if law["name"] == "constraint":
                out += constraint_force(obj, p, self.lam_n_per_m,
                                        contact_band_m=law.get("contact_band_m", 0.0))
            else:
                v = np.zeros_like(p) if velocities is None else velocities
                out += penetration_force(obj, p, v, law["stiffness_n_per_m"],
                                         law["damping_n_s_per_m"])
        return out

    @classmethod
    def load(cls, path, expected_design_sha256: str | None = None) -> "Scene":
        """Read a compiled scene (numpy only). With ``expected_design_sha256`` (the map's
        ``meta['design_sha256']``), a scene compiled for another map is refused."""
        p = Path(path)
        if not p.is_file():
            raise BadInputError("scene file", "a path to an existing .npz scene", str(p))
        with open(p, "rb") as fh:
            magic = fh.read(4)
        if magic != b"PK\x03\x04":  # every .npz is a zip archive (np.load would try pickle)
            raise _bad(p, "a .npz archive; this file is not one, so it is not a scene file; "
                          "make one with: designkit scene compile OBJECT --out FILE.npz")
        try:
            with np.load(p, allow_pickle=False) as z:
                if "meta" not in z.files:
                    raise _bad(p, f"array meta; found {sorted(z.files)}")
                meta = json.loads(str(z["meta"]))
                arrays = {k: z[k] for k in z.files if k != "meta"}
        except BadInputError:
            raise
        except (zipfile.BadZipFile, EOFError, OSError, ValueError, KeyError) as exc:
            raise _bad(p, f"readable npz; {type(exc).__name__}: {exc}") from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT or \
                meta.get("version") != FORMAT_VERSION:
            raise _bad(p, f"format {FORMAT!r} version {FORMAT_VERSION}")
        if _hash(arrays) != meta.get("data_sha256"):
            raise _bad(p, "data matching its recorded SHA-256 (corrupted)")
        if expected_design_sha256 is not None and \
                meta.get("map_design_sha256") != expected_design_sha256:
            got = meta.get("map_design_sha256") or "none"
            raise BadInputError(
                "scene file", f"compiled for the map in use (design SHA-256 "
                f"{expected_design_sha256[:12]}...)", f"{p} (compiled for design SHA-256 "
                f"{got[:12]}...)", "Recompile it: designkit scene compile OBJECT --map MAP.")
        objects = []
        for k, o in enumerate(meta["objects"]):
            arr = {name: arrays[f"obj{k}_{name}"] for name in o.get("arrays", [])}
            objects.append(SceneObject(o["kind"], o["params"], arr))
        return cls(objects, meta)


def scene_arrays(objects_meta: list, arrays: dict, meta: dict) -> dict:
    """The npz content of a scene (designkit.render writes it atomically): meta gets the format,
    version and the data hash."""
    meta = dict(meta, format=FORMAT, version=FORMAT_VERSION, objects=objects_meta,
                data_sha256=_hash(arrays))
    return {**arrays, "meta": np.array(json.dumps(meta))}
