"""Axisymmetric gmsh model of a coil (+ core) in the meridian half-plane x = r >= 0, y = z.

Regions (physical tags): 1 core, 2 winding, 3 air (|x| < R_int), 4 shell (R_int..R_ext, mapped
to infinity by GetDP's spherical-shell Jacobian); curves 11 axis, 12 outer arc.
Mesh sizes: fine along the extraction lines above the coil and near the corners of the core and
the winding, where the field gradients are largest; ``level`` halves all sizes per step of 2.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from pathlib import Path

from ..errors import require
from ..support.atomic import atomic_path

CORE, WINDING, AIR, SHELL, AXIS, OUTER = 1, 2, 3, 4, 11, 12


@dataclass(frozen=True)
class MeshSpec:
    """Geometry (SI, winding-centred frame) and mesh controls of one FEM model."""

    inner_radius: float
    outer_radius: float
    length: float
    core_radius: float | None
    core_length: float | None
    core_offset: float
    line_z_lo: float
    """Extraction lines span [line_z_lo, line_z_hi] (local z), m."""
    line_z_hi: float
    line_r_max: float
    level: int = 1
    shell_inner: float = 0.25
    shell_outer: float = 0.30
    probe_box: tuple[float, float, float] | None = None
    """(r_max, z_lo, z_hi), m: region meshed at the probe size (points all around the coil)."""

    @property
    def scale(self) -> float:
        return 2.0 ** (-self.level / 2.0)


def size_near(f, what: str, tags, size_min: float, size_max: float, dist_min: float,
               dist_max: float, sampling: int | None = None) -> int:
    """gmsh Distance + Threshold fields: element size ``size_min`` within ``dist_min`` of the
    curves or points ``tags`` (``what`` = "CurvesList" / "PointsList"), growing to ``size_max``
    at ``dist_max``, m. Returns the Threshold field's tag."""
    dist = f.add("Distance")
    f.setNumbers(dist, what, tags)
    if sampling is not None:
        f.setNumber(dist, "Sampling", sampling)
    thr = f.add("Threshold")
    f.setNumber(thr, "InField", dist)
    f.setNumber(thr, "SizeMin", size_min)
    f.setNumber(thr, "SizeMax", size_max)
    f.setNumber(thr, "DistMin", dist_min)
    f.setNumber(thr, "DistMax", dist_max)
    return thr


@contextlib.contextmanager
def gmsh_model(name: str):
    """A fresh gmsh model ``name``, quiet and on one thread; yields the gmsh module. The model
    is removed when the block ends normally, and gmsh finalized if it was started here (a
    caller's own gmsh session is left running)."""
    gmsh = require("gmsh", "gmsh", "designkit.fem")
    started_here = not gmsh.isInitialized()
    if started_here:
        gmsh.initialize(["-noenv"], interruptible=False)  # keep Python's Ctrl-C handler
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.model.add(name)
        yield gmsh
        gmsh.model.remove()
    finally:
        if started_here:
            gmsh.finalize()


def mesh_to_file(gmsh, fields, dim: int, msh_path: str | Path) -> None:
    """Size the mesh by the minimum of the gmsh ``fields`` alone, mesh in ``dim`` (2: Frontal-
    Delaunay, 3: Delaunay) and write ``msh_path`` as MSH 2.2 ASCII, the format Debian's GetDP
    reads without a linked Gmsh."""
    f = gmsh.model.mesh.field
    fmin = f.add("Min")
    f.setNumbers(fmin, "FieldsList", fields)
    f.setAsBackgroundMesh(fmin)
    gmsh.option.setNumber("Mesh.MeshSizeExtendFromBoundary", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.MeshSizeFromCurvature", 0)
    gmsh.option.setNumber("Mesh.Algorithm3D" if dim == 3 else "Mesh.Algorithm", 1 if dim == 3 else 6)
    gmsh.model.mesh.generate(dim)
    gmsh.option.setNumber("Mesh.MshFileVersion", 2.2)
    gmsh.option.setNumber("Mesh.Binary", 0)
    gmsh.write(str(msh_path))


def build_mesh(spec: MeshSpec, msh_path: str | Path) -> dict:
    """Mesh the model with gmsh and write ``msh_path`` (MSH 2.2: the format Debian's GetDP reads without linked Gmsh).

    Returns mesh statistics: number of nodes and triangles.
    """
    s = spec.scale
    ri, ro, hl = spec.inner_radius, spec.outer_radius, spec.length / 2
    rint, rext = spec.shell_inner, spec.shell_outer
    with gmsh_model("designkit_coil") as gmsh:
        occ = gmsh.model.occ
        half_ext = occ.intersect([(2, occ.addDisk(0, 0, 0, rext, rext))],
                                 [(2, occ.addRectangle(0, -rext, 0, rext, 2 * rext))])[0]
        half_int = occ.intersect([(2, occ.addDisk(0, 0, 0, rint, rint))],
                                 [(2, occ.addRectangle(0, -rint, 0, rint, 2 * rint))])[0]
        tools = list(half_int)
        wind = occ.addRectangle(ri, -hl, 0, ro - ri, 2 * hl)
        tools.append((2, wind))
        core = None
        if spec.core_radius is not None:
            zc0 = spec.core_offset - spec.core_length / 2
            core = occ.addRectangle(0, zc0, 0, spec.core_radius, spec.core_length)
            tools.append((2, core))
        occ.fragment(half_ext, tools)
        occ.synchronize()

        def inside(tag, box):
            x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(2, tag)
            e = 1e-6  # OCC bounding boxes carry a ~1e-7 m tolerance
            return (x0 >= box[0] - e and y0 >= box[1] - e and x1 <= box[2] + e
                    and y1 <= box[3] + e)

        groups = {CORE: [], WINDING: [], AIR: [], SHELL: []}
        for _, tag in gmsh.model.getEntities(2):
            if inside(tag, (ri, -hl, ro, hl)):
                groups[WINDING].append(tag)
            elif core is not None and inside(tag, (0.0, spec.core_offset - spec.core_length / 2,
                                                   spec.core_radius,
                                                   spec.core_offset + spec.core_length / 2)):
                groups[CORE].append(tag)
            elif inside(tag, (0.0, -rint, rint, rint)):
                groups[AIR].append(tag)
            else:
                groups[SHELL].append(tag)
        names = {CORE: "core", WINDING: "winding", AIR: "air", SHELL: "shell"}
        for tag, ents in groups.items():
            if ents:
                gmsh.model.addPhysicalGroup(2, ents, tag, names[tag])
        axis, outer = [], []
        for _, c in gmsh.model.getEntities(1):
            x0, y0, _, x1, y1, _ = gmsh.model.getBoundingBox(1, c)
            if x1 < 1e-6:
                axis.append(c)
            elif abs(math.hypot(x1, max(abs(y0), abs(y1))) - rext) < 1e-6 * rext and x1 > rint:
                outer.append(c)
        gmsh.model.addPhysicalGroup(1, axis, AXIS, "axis")
        gmsh.model.addPhysicalGroup(1, outer, OUTER, "outer")

        # --- mesh size fields
        f = gmsh.model.mesh.field
        h_line = 0.6e-3 * s
        h_obj = 1.0e-3 * s
        h_corner = 0.15e-3 * s
        h_far = 12e-3 * s
        box = f.add("Box")
        f.setNumber(box, "VIn", h_line)
        f.setNumber(box, "VOut", h_far)
        f.setNumber(box, "XMin", 0.0)
        f.setNumber(box, "XMax", spec.line_r_max)
        f.setNumber(box, "YMin", spec.line_z_lo)
        f.setNumber(box, "YMax", spec.line_z_hi)
        f.setNumber(box, "Thickness", 0.02)
        obj_curves = []
        for tag in groups[CORE] + groups[WINDING]:
            obj_curves += [abs(c[1]) for c in gmsh.model.getBoundary([(2, tag)], oriented=False)]
        obj_curves = [c for c in set(obj_curves) if c not in axis]
        thr = size_near(f, "CurvesList", obj_curves, h_obj, h_far, 2e-3, 0.08, sampling=200)
        corner_pts = []
        for tag in groups[CORE] + groups[WINDING]:
            for d, p in gmsh.model.getBoundary([(2, tag)], recursive=True):
                if d == 0:
                    corner_pts.append(p)
        thrp = size_near(f, "PointsList", sorted(set(corner_pts)), h_corner, h_far, 0.3e-3, 0.01)
        fields = [box, thr, thrp]
        if spec.probe_box is not None:
            pbox = f.add("Box")
            f.setNumber(pbox, "VIn", 1.0e-3 * s)
            f.setNumber(pbox, "VOut", h_far)
            f.setNumber(pbox, "XMin", 0.0)
            f.setNumber(pbox, "XMax", spec.probe_box[0])
            f.setNumber(pbox, "YMin", spec.probe_box[1])
            f.setNumber(pbox, "YMax", spec.probe_box[2])
            f.setNumber(pbox, "Thickness", 0.02)
            fields.append(pbox)
        mesh_to_file(gmsh, fields, 2, msh_path)
        node_tags, _, _ = gmsh.model.mesh.getNodes()
        etypes, etags, _ = gmsh.model.mesh.getElements(2)
        ntri = int(sum(len(t) for t in etags))
        return {"nodes": int(len(node_tags)), "triangles": ntri,
                "h_line_m": h_line, "h_corner_m": h_corner}


def export_meshio(msh_path: str | Path, out_stem: str | Path) -> list[Path]:
    """Convert the gmsh mesh to .vtu and .xdmf (XML data) with meshio; returns the paths."""
    meshio = require("meshio", "meshio", "designkit.fem mesh export")

    m = meshio.read(str(msh_path))
    # keep only triangles with their physical tags, in 3D coordinates (x = r, y = z)
    cells = [c for c in m.cells if c.type == "triangle"]
    tri_data = []
    for block, data in zip(m.cells, m.cell_data.get("gmsh:physical", [])):
        if block.type == "triangle":
            tri_data.append(data)
    mesh = meshio.Mesh(m.points, cells, cell_data={"region": tri_data} if tri_data else {})
    out = []
    for ext in (".vtu", ".xdmf"):
        target = Path(str(out_stem) + ext)
        if ext == ".xdmf":
            # meshio's XDMF writer imports h5py even for XML data: a clear error if it is missing
            require("h5py", "h5py", "designkit.fem XDMF export")
            # XDMF with XML data stays a single self-contained file (no HDF5 side file)
            with atomic_path(target) as tmp:
                meshio.xdmf.write(str(tmp), mesh, data_format="XML")
        else:
            with atomic_path(target) as tmp:
                meshio.write(str(tmp), mesh, file_format="vtu")
        out.append(target)
    return out
