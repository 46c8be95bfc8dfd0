"""Virtual objects of thesis chapter 4: builders around firmware_io.scene (which evaluates them).

All are solids standing on the coil-top plane z = 0 of the array frame (z up), SI units.
Defaults are the thesis' sizes where it gives them (section 4.2: a 100 mm square flat surface
at 50 mm, a 100 mm diameter hemisphere); the half-cylinder and the wedge are not dimensioned
in the thesis: we take the same 100 mm footprint and 50 mm top (assumed).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from firmware_io.scene import SceneObject

from ..errors import BadInputError, require
from ..support import validate as v


class VirtualObject:
    """Common interface: g(p) (``signed_distance``, m, negative inside), ``normal`` (outward unit
    vector, the gradient of g), ``height`` h(x, y) (top z above the coils, m) -- all vectorized
    over points (n, 3), m -- and ``surface_points`` (the renderable upper surface)."""

    kind: str = ""

    def scene_object(self) -> SceneObject:
        return SceneObject(self.kind, self.params(), self.arrays())

    def params(self) -> dict:  # pragma: no cover - overridden
        raise NotImplementedError

    def arrays(self) -> dict:
        return {}

    def signed_distance(self, points) -> np.ndarray:
        """g(p), m, shape (n,), negative inside; points (n, 3) or (3,), m."""
        return self._obj().signed_distance(v.points(points)[0])

    def normal(self, points) -> np.ndarray:
        """Outward unit normal (gradient of g), shape (n, 3)."""
        return self._obj().normal(v.points(points)[0])

    def height(self, points) -> np.ndarray:
        """h(x, y): top of the solid above the coil plane at the points' (x, y), m, (n,)."""
        return self._obj().height(v.points(points)[0])

    def _obj(self) -> SceneObject:
        cached = self.__dict__.get("_scene_object")
        if cached is None:
            cached = self.scene_object()
            object.__setattr__(self, "_scene_object", cached)
        return cached

    def footprint_m(self) -> tuple[float, float, float, float]:
        """(x_min, x_max, y_min, y_max) of the object's footprint, m."""
        raise NotImplementedError  # pragma: no cover

    def surface_points(self, n_side: int = 61) -> tuple[np.ndarray, np.ndarray]:
        """Points on the upper (renderable) surface and their outward normals.

        A regular n_side x n_side grid over the footprint (61 x 61 = 3721 points, the thesis'
        discretization) lifted to z = h(x, y); points outside the footprint and points whose
        outward normal does not point up (not renderable) are dropped.

        Returns
        -------
        points : (n, 3) m;  normals : (n, 3)
        """
        n_side = v.positive_int("n_side", n_side)
        x0, x1, y0, y1 = self.footprint_m()
        xs, ys = np.linspace(x0, x1, n_side), np.linspace(y0, y1, n_side)
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        flat = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
        h = self.height(flat)
        keep = h > 0
        pts = np.c_[flat[keep, :2], h[keep]]
        nrm = self._obj().top_normal(pts)
        up = nrm[:, 2] > 0.0  # the renderable (upper) side only
        return pts[up], nrm[up]


def _xyz(name, value):
    return np.asarray(v.vector3(name, value, "m"), float)


@dataclass(frozen=True)
class Plane(VirtualObject):
    """The thesis' flat surface: a size x size square at height_m (a box from z = 0 to it)."""

    size_m: float = 0.100
    height_m: float = 0.050
    centre_xy_m: tuple = (0.0, 0.0)
    kind: str = field(default="box", init=False, repr=False)

    def __post_init__(self):
        v.positive("size_m", self.size_m, "m")
        v.positive("height_m", self.height_m, "m")
        if len(self.centre_xy_m) != 2 or not all(map(math.isfinite, self.centre_xy_m)):
            raise BadInputError("centre_xy_m", "2 finite numbers, m", self.centre_xy_m)

    def params(self):
        cx, cy = self.centre_xy_m
        return {"centre_m": [cx, cy, self.height_m / 2],
                "half_size_m": [self.size_m / 2, self.size_m / 2, self.height_m / 2]}

    def footprint_m(self):
        cx, cy = self.centre_xy_m
        s = self.size_m / 2
        return (cx - s, cx + s, cy - s, cy + s)


@dataclass(frozen=True)
class Hemisphere(VirtualObject):
    """Half ball of diameter_m on z = 0 (thesis: 100 mm; top at 50 mm)."""

    diameter_m: float = 0.100
    centre_m: tuple = (0.0, 0.0, 0.0)
    kind: str = field(default="half_ball", init=False, repr=False)

    def __post_init__(self):
        v.positive("diameter_m", self.diameter_m, "m")
        _xyz("centre_m", self.centre_m)

    def params(self):
        return {"centre_m": list(map(float, self.centre_m)), "radius_m": self.diameter_m / 2}

    def footprint_m(self):
        cx, cy, _ = self.centre_m
        r = self.diameter_m / 2
        return (cx - r, cx + r, cy - r, cy + r)


@dataclass(frozen=True)
class HalfCylinder(VirtualObject):
    """Half cylinder, axis along y on z = 0: diameter_m, length_m (assumed 100 mm, 100 mm)."""

    diameter_m: float = 0.100
    length_m: float = 0.100
    centre_m: tuple = (0.0, 0.0, 0.0)
    kind: str = field(default="half_cylinder", init=False, repr=False)

    def __post_init__(self):
        v.positive("diameter_m", self.diameter_m, "m")
        v.positive("length_m", self.length_m, "m")
        _xyz("centre_m", self.centre_m)

    def params(self):
        return {"centre_m": list(map(float, self.centre_m)), "radius_m": self.diameter_m / 2,
                "half_length_m": self.length_m / 2}

    def footprint_m(self):
        cx, cy, _ = self.centre_m
        return (cx - self.diameter_m / 2, cx + self.diameter_m / 2,
                cy - self.length_m / 2, cy + self.length_m / 2)


@dataclass(frozen=True)
class Wedge(VirtualObject):
    """Triangular prism (a roof), ridge along y: width_m x length_m base on z = 0, ridge at
    height_m (assumed 100 mm x 100 mm x 50 mm)."""

    width_m: float = 0.100
    length_m: float = 0.100
    height_m: float = 0.050
    centre_m: tuple = (0.0, 0.0, 0.0)
    kind: str = field(default="prism", init=False, repr=False)

    def __post_init__(self):
        for name in ("width_m", "length_m", "height_m"):
            v.positive(name, getattr(self, name), "m")
        _xyz("centre_m", self.centre_m)

    def params(self):
        w = self.width_m / 2
        return {"centre_m": list(map(float, self.centre_m)),
                "polygon_xz_m": [[-w, 0.0], [w, 0.0], [0.0, self.height_m]],
                "half_length_m": self.length_m / 2}

    def footprint_m(self):
        cx, cy, _ = self.centre_m
        return (cx - self.width_m / 2, cx + self.width_m / 2,
                cy - self.length_m / 2, cy + self.length_m / 2)


OBJECTS = {"plane": Plane, "hemisphere": Hemisphere, "half-cylinder": HalfCylinder,
           "wedge": Wedge}


# ============================================================================ meshes
@dataclass(frozen=True, eq=False)
class MeshSurface(VirtualObject):
    """A closed triangle mesh (STL/PLY) as a signed-distance grid the runner reads with numpy.

    Only the upper side is renderable: the force laws return zero where the outward normal
    points down (n_z < 0), and ``surface_points`` keeps the top surface z = h(x, y) only -- the
    underside of a mesh cannot be felt with a planar array below the hand (thesis 4.1.1; rotate
    the model to feel another side).

    Build with :meth:`from_file`. ``sdf`` (nx, ny, nz) and ``normal`` (nx, ny, nz, 3) float32
    on the grid ``lower_m`` + index x ``spacing_m``; ``height_map`` (nx, ny) the top z.
    """

    sdf: np.ndarray
    normal_grid: np.ndarray
    height_map: np.ndarray
    lower_m: tuple
    spacing_m: tuple
    source: str = ""
    kind: str = field(default="grid", init=False, repr=False)

    def params(self):
        return {"lower_m": list(self.lower_m), "spacing_m": list(self.spacing_m),
                "source": self.source}

    def arrays(self):
        return {"sdf": self.sdf, "normal": self.normal_grid, "height": self.height_map}

    def footprint_m(self):
        lo = np.asarray(self.lower_m)
        hi = lo + np.asarray(self.spacing_m) * (np.asarray(self.sdf.shape) - 1)
        return (lo[0], hi[0], lo[1], hi[1])

    @classmethod
    def from_file(cls, path, *, scale: float = 1e-3, fit_size_m: float | None = None,
                  position_m=(0.0, 0.0, 0.0), spacing_m: float = 0.002,
                  margin_m: float = 0.006) -> "MeshSurface":
        """Read a closed STL/PLY mesh and precompute its signed-distance grid (pyvista/VTK).

        Parameters
        ----------
        path : STL or PLY file
        scale : float
            File units to m (default 1e-3: millimetres).
        fit_size_m : float, optional
            Scale instead so the larger horizontal extent is this, m.
        position_m : (3,)
            Where the bottom centre of the mesh's bounding box goes, m (default: on the coils'
            top plane, centred).
        spacing_m, margin_m : grid spacing and margin around the mesh, m.

        Raises BadInputError: missing/unreadable file, a mesh that is not closed (open edges),
        not manifold, or has no upward-facing faces.
        """
        pv = _pyvista()
        p = Path(path)
        if not p.is_file() or p.suffix.lower() not in (".stl", ".ply"):
            raise BadInputError("mesh", "an existing .stl or .ply file", str(p))
        try:
            mesh = pv.read(str(p))
            if not isinstance(mesh, pv.PolyData):
                mesh = mesh.extract_surface(algorithm="dataset_surface")
            mesh = mesh.triangulate().clean()
        except Exception as exc:  # VTK readers raise various types on garbage
            raise BadInputError("mesh", "a readable STL/PLY triangle mesh",
                                f"{p} ({type(exc).__name__}: {exc})") from None
        if mesh.n_cells == 0:
            raise BadInputError("mesh", "a mesh with triangles", f"{p} (0 faces)")
        if mesh.n_open_edges > 0:
            raise BadInputError("mesh", "a closed surface (no open edges)",
                                f"{p} ({mesh.n_open_edges} open edges)",
                                "Close the holes (e.g. pyvista fill_holes) and retry.")
        if not mesh.is_manifold:
            raise BadInputError("mesh", "a manifold closed surface", f"{p} (non-manifold)")
        s = v.positive("scale", scale)
        if fit_size_m is not None:
            b = mesh.bounds
            s = v.positive("fit_size_m", fit_size_m, "m") / max(b[1] - b[0], b[3] - b[2])
        mesh = mesh.scale(s, inplace=False)
        mesh = mesh.compute_normals(cell_normals=True, point_normals=False,
                                    auto_orient_normals=True, consistent_normals=True)
        if not np.any(np.asarray(mesh.cell_data["Normals"])[:, 2] > 1e-6):
            raise BadInputError("mesh", "a surface with upward-facing faces (n_z > 0)",
                                f"{p} (none face up)")
        b = np.asarray(mesh.bounds)
        pos = _xyz("position_m", position_m)
        mesh = mesh.translate(pos - np.array([(b[0] + b[1]) / 2, (b[2] + b[3]) / 2, b[4]]),
                              inplace=False)
        return cls._grid_from_mesh(mesh, spacing_m, margin_m, str(p))

    @classmethod
    def _grid_from_mesh(cls, mesh, spacing_m, margin_m, source):
        pv = _pyvista()
        h = v.positive("spacing_m", spacing_m, "m")
        m = v.nonnegative("margin_m", margin_m, "m")
        b = np.asarray(mesh.bounds)
        lo = np.array([b[0], b[2], b[4]]) - m
        hi = np.array([b[1], b[3], b[5]]) + m
        dims = np.maximum(np.ceil((hi - lo) / h).astype(int) + 1, 2)
        img = pv.ImageData(dimensions=dims, spacing=(h, h, h), origin=lo)
        sdf = np.asarray(img.compute_implicit_distance(mesh)["implicit_distance"])
        sdf = sdf.reshape(dims[::-1]).transpose(2, 1, 0)  # VTK x-fastest -> [ix, iy, iz]
        gx, gy, gz = np.gradient(sdf, h)
        nrm = np.stack([gx, gy, gz], axis=-1)
        nn = np.linalg.norm(nrm, axis=-1, keepdims=True)
        nrm = np.where(nn > 1e-12, nrm / np.where(nn > 1e-12, nn, 1.0), [0.0, 0.0, 1.0])
        height = _top_height(sdf, lo[2], h)
        obj = cls(sdf.astype(np.float32), nrm.astype(np.float32), height.astype(np.float32),
                  tuple(map(float, lo)), (h, h, h), source)
        object.__setattr__(obj, "_mesh", mesh)
        return obj

    def grid_error(self, n_samples: int = 4000, band_m: float = 0.005, seed: int = 0) -> dict:
        """Error of the trilinear grid g against the exact point-to-mesh signed distance
        (vtkImplicitPolyDataDistance) at random points in the grid box, m: max and RMS over
        all samples and over those within ``band_m`` of the surface (what rendering uses)."""
        pv = _pyvista()
        mesh = self.__dict__.get("_mesh")
        if mesh is None:
            raise BadInputError("mesh", "a MeshSurface built by from_file in this process",
                                "no source mesh")
        rng = np.random.default_rng(seed)
        lo = np.asarray(self.lower_m)
        hi = lo + np.asarray(self.spacing_m) * (np.asarray(self.sdf.shape) - 1)
        pts = rng.uniform(lo, hi, (n_samples, 3))
        exact = np.asarray(pv.PolyData(pts).compute_implicit_distance(mesh)["implicit_distance"])
        got = self.signed_distance(pts)
        err = np.abs(got - exact)
        near = np.abs(exact) < band_m
        return {"max_m": float(err.max()), "rms_m": float(np.sqrt(np.mean(err**2))),
                "near_max_m": float(err[near].max()) if near.any() else 0.0,
                "near_rms_m": float(np.sqrt(np.mean(err[near] ** 2))) if near.any() else 0.0,
                "n_samples": n_samples, "n_near": int(near.sum()), "spacing_m": self.spacing_m[0]}


def _top_height(sdf: np.ndarray, z0: float, h: float) -> np.ndarray:
    """Top z of the solid per (x, y) column: the highest inside -> outside crossing of g."""
    inside = sdf <= 0
    nz = sdf.shape[2]
    # highest index k with g[k] <= 0 (columns without any: no solid)
    any_in = inside.any(axis=2)
    k = nz - 1 - np.argmax(inside[:, :, ::-1], axis=2)
    k1 = np.minimum(k + 1, nz - 1)
    gk = np.take_along_axis(sdf, k[..., None], 2)[..., 0]
    gk1 = np.take_along_axis(sdf, k1[..., None], 2)[..., 0]
    frac = np.where((k1 > k) & (gk1 > gk), -gk / np.where(gk1 > gk, gk1 - gk, 1.0), 0.0)
    top = z0 + (k + frac) * h
    return np.where(any_in, np.maximum(top, 0.0), 0.0)


def _pyvista():
    return require("pyvista", "pyvista", "meshes (STL/PLY) for rendering")
