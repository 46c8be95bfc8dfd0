"""Independent checks of exported triangle meshes (binary/ASCII STL, 3MF), numpy only.

The check reads the bytes that were written, not the in-memory shape, so it catches what a
slicer would see: vertices are merged by exact coordinates, and the mesh is closed and
edge-manifold with consistent orientation iff every directed edge occurs exactly once and
its reverse also occurs exactly once. The enclosed volume is the divergence-theorem sum
sum(v0 . (v1 x v2)) / 6, positive for outward normals.

Tessellation bound: every mesh vertex lies on the exact surface and every chord stays
within the linear deflection ``tol`` of it, so the mesh volume differs from the solid's by
at most ``area * tol`` (``area`` = exact surface area). That is the acceptance bound used by
:func:`check_mesh`.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from designkit.errors import BadInputError


@dataclass(frozen=True)
class MeshReport:
    """What :func:`mesh_report` found in one mesh (lengths in the file's unit, mm)."""

    n_triangles: int
    n_vertices: int
    n_degenerate: int
    """Triangles with a repeated vertex after merging (dropped before the edge test)."""
    n_boundary_edges: int
    """Directed edges whose reverse is missing: holes or flipped triangles."""
    n_overused_edges: int
    """Directed edges used more than once: non-manifold edges or duplicated faces."""
    volume: float
    """Signed enclosed volume, mm^3 (> 0 for outward-facing triangles)."""
    bounds_min: tuple[float, float, float]
    bounds_max: tuple[float, float, float]

    @property
    def watertight(self) -> bool:
        return self.n_boundary_edges == 0

    @property
    def manifold(self) -> bool:
        return self.n_overused_edges == 0

    @property
    def size(self) -> tuple[float, float, float]:
        return tuple(float(b - a) for a, b in zip(self.bounds_min, self.bounds_max))


def read_stl(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read an STL file.

    Returns
    -------
    vertices : ndarray, shape (n, 3), float64, file unit (mm)
        Merged by exact coordinates.
    triangles : ndarray, shape (m, 3), int64
        Indices into ``vertices``.
    """
    data = Path(path).read_bytes()
    if data[:5] == b"solid" and b"facet" in data[:1024]:
        coords = _ascii_stl_vertices(data)
    else:
        if len(data) < 84:
            raise BadInputError("STL file", "a binary STL of at least 84 bytes", f"{len(data)} bytes")
        n = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
        if len(data) < 84 + 50 * n:
            raise BadInputError("STL file", f"84 + 50 x {n} bytes", f"{len(data)} bytes")
        rec = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
        coords = np.frombuffer(data, dtype=rec, count=n, offset=84)["v"].reshape(-1, 3)
    return merge_corners(coords.astype(np.float64))


def _ascii_stl_vertices(data: bytes) -> np.ndarray:
    rows = [line.split()[1:4] for line in data.decode("ascii", "replace").splitlines()
            if line.strip().startswith("vertex")]
    return np.asarray(rows, dtype=np.float64)


def read_3mf(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read every mesh object of a 3MF file into one (vertices (n, 3), triangles (m, 3))."""
    with zipfile.ZipFile(path) as zf:
        names = [n for n in zf.namelist() if n.lower().endswith(".model")]
        if not names:
            raise BadInputError("3MF file", "a zip holding a 3D/*.model part", str(path))
        root = ElementTree.fromstring(zf.read(names[0]))
    unit = root.get("unit", "millimeter")
    scale = {"micron": 1e-3, "millimeter": 1.0, "centimeter": 10.0, "inch": 25.4,
             "foot": 304.8, "meter": 1000.0}.get(unit)
    if scale is None:
        raise BadInputError("3MF unit", "a 3MF unit name", unit)
    all_xyz, all_tri, offset = [], [], 0
    for mesh in root.iter():
        if not mesh.tag.endswith("}mesh") and mesh.tag != "mesh":
            continue
        verts = [el for el in mesh.iter() if el.tag.endswith("vertex")]
        tris = [el for el in mesh.iter() if el.tag.endswith("triangle")]
        xyz = np.array([[float(e.get("x")), float(e.get("y")), float(e.get("z"))] for e in verts])
        tri = np.array([[int(e.get("v1")), int(e.get("v2")), int(e.get("v3"))] for e in tris],
                       dtype=np.int64).reshape(-1, 3)
        all_xyz.append(xyz.reshape(-1, 3) * scale)
        all_tri.append(tri + offset)
        offset += len(xyz)
    if not all_xyz:
        raise BadInputError("3MF file", "at least one <mesh>", str(path))
    xyz = np.concatenate(all_xyz)
    tri = np.concatenate(all_tri)
    return merge_corners(xyz[tri.reshape(-1)])


def merge_corners(corner_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangle corners (3m, 3) -> unique vertices and (m, 3) indices (exact-coordinate merge)."""
    vertices, inverse = np.unique(corner_xyz, axis=0, return_inverse=True)
    return vertices, inverse.reshape(-1, 3).astype(np.int64)


def mesh_report(vertices: np.ndarray, triangles: np.ndarray) -> MeshReport:
    """Topology and volume of a merged triangle mesh (see the module docstring)."""
    tri = np.asarray(triangles, dtype=np.int64)
    degenerate = (tri[:, 0] == tri[:, 1]) | (tri[:, 1] == tri[:, 2]) | (tri[:, 2] == tri[:, 0])
    good = tri[~degenerate]
    n = np.int64(max(len(vertices), 1))
    a = good.reshape(-1)
    b = np.roll(good, -1, axis=1).reshape(-1)
    directed = a * n + b
    reverse = b * n + a
    uniq, counts = np.unique(directed, return_counts=True)
    overused = int(np.count_nonzero(counts > 1))
    boundary = int(np.count_nonzero(~np.isin(reverse, uniq)))
    v = np.asarray(vertices, dtype=np.float64)
    p0, p1, p2 = v[good[:, 0]], v[good[:, 1]], v[good[:, 2]]
    volume = float(np.einsum("ij,ij->", p0, np.cross(p1, p2)) / 6.0) if len(good) else 0.0
    lo = v.min(axis=0) if len(v) else np.zeros(3)
    hi = v.max(axis=0) if len(v) else np.zeros(3)
    return MeshReport(n_triangles=len(tri), n_vertices=len(v), n_degenerate=int(degenerate.sum()),
                      n_boundary_edges=boundary, n_overused_edges=overused, volume=volume,
                      bounds_min=tuple(map(float, lo)), bounds_max=tuple(map(float, hi)))


def check_mesh(report: MeshReport, solid_volume: float, surface_area: float,
               tolerance: float) -> list[str]:
    """Problems of an exported mesh, as sentences (empty list: the mesh is good).

    Parameters
    ----------
    report : MeshReport
    solid_volume : float
        Exact volume of the B-rep solid, mm^3.
    surface_area : float
        Exact surface area of the solid, mm^2.
    tolerance : float
        Linear deflection used for the tessellation, mm.
    """
    problems = []
    if not report.watertight:
        problems.append(f"not watertight ({report.n_boundary_edges} open or flipped edges)")
    if not report.manifold:
        problems.append(f"not manifold ({report.n_overused_edges} edges shared by > 2 triangles)")
    if not report.volume > 0:
        problems.append(f"volume {report.volume:.6g} mm^3 is not positive (inside-out?)")
    bound = surface_area * tolerance
    if abs(report.volume - solid_volume) > bound:
        problems.append(f"mesh volume {report.volume:.6g} mm^3 differs from the solid's "
                        f"{solid_volume:.6g} mm^3 by more than area x tolerance = {bound:.3g} mm^3")
    return problems
