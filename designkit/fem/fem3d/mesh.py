"""gmsh 3-D mesh of a model: the bodies inside an air sphere and a shell, cut to its symmetry part.

Regions (physical tags, :mod:`.bodies`): air (|x| < R_int), shell (R_int..R_ext, mapped to
infinity by GetDP), the magnet, one region per core and per energized winding; the boundary
surface (outer sphere and, with symmetry, the cut planes). Sizes (m) come from a distance
field to the bodies' surfaces, refinement boxes and balls around fitting points; every size
shrinks by sqrt(2) per ``level``. The mesh levels and their accuracy are in docs/fem.md.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..mesh import gmsh_model, mesh_to_file
from .bodies import AIR, BOUNDARY, CORE0, MAGNET, SHELL, WIND0
from .lines import FIT_HALF_WINDOW


def _add_bodies(occ, bodies, symmetry, r_int, r_ext):
    """OCC volumes: outer sphere, inner sphere, then one per body, cut to the symmetry part.

    Returns the list of (3, tag) per input (None for a body outside the modelled part)."""
    outer = occ.addSphere(0, 0, 0, r_ext)
    inner = occ.addSphere(0, 0, 0, r_int)
    vols = []
    for b in bodies:
        base, top = b.end_points()
        d = top - base
        c = occ.addCylinder(*base, *d, b.radius)
        if b.inner_radius > 0:
            h = occ.addCylinder(*base, *d, b.inner_radius)
            c = occ.cut([(3, c)], [(3, h)])[0][0][1]
        vols.append(c)
    objs = [(3, outer), (3, inner)] + [(3, v) for v in vols]
    if symmetry != "none":
        x0 = 0.0 if symmetry == "quarter" else -r_ext * 1.1
        box = occ.addBox(x0, 0.0, -r_ext * 1.1, r_ext * 1.1 - x0, r_ext * 1.1,
                         2.2 * r_ext)
        cut = []
        for o in objs:
            res = occ.intersect([o], [(3, box)], removeObject=True, removeTool=False)[0]
            cut.append(res)
        occ.remove([(3, box)], recursive=True)
        objs = [c[0] if c else None for c in cut]
    return objs


def _volume_groups(bodies, objs, out_map):
    """Which region each fragment volume belongs to: ({AIR, SHELL, MAGNET: [tags]},
    {core or winding region tag: [tags]}); later inputs own the overlaps (bodies inside)."""
    present = [o for o in objs if o is not None]
    owner = {}
    for idx, ents in enumerate(out_map):
        for d, t in ents:
            if d == 3:
                owner[t] = idx  # the innermost (last) input wins
    groups = {AIR: [], SHELL: [], MAGNET: []}
    body_groups = {}
    for t, idx in owner.items():
        src = present[idx]
        k = objs.index(src)
        if k == 0:
            groups[SHELL].append(t)
        elif k == 1:
            groups[AIR].append(t)
        else:
            bi = k - 2
            b = bodies[bi]
            if b.kind == "magnet":
                groups[MAGNET].append(t)
            else:
                tag = (CORE0 if b.kind == "core" else WIND0) + bi
                body_groups.setdefault(tag, []).append(t)
    return groups, body_groups


def _on_sphere(gmsh, tag, r):
    x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, tag)
    return max(abs(x0), abs(x1), abs(y0), abs(y1), abs(z0), abs(z1)) > 0.9 * r


def _boundary_group(gmsh, symmetry, r_int, r_ext):
    """The BOUNDARY surface group: the outer sphere and the symmetry cut planes."""
    bnd = []
    for _, t in gmsh.model.getEntities(2):
        x0, y0, z0, x1, y1, z1 = gmsh.model.getBoundingBox(2, t)
        on_plane = (symmetry != "none" and abs(y0) < 1e-6 and abs(y1) < 1e-6) or \
            (symmetry == "quarter" and abs(x0) < 1e-6 and abs(x1) < 1e-6)
        far = max(abs(x0), abs(x1), abs(y0), abs(y1), abs(z0), abs(z1)) > 0.5 * (r_int
                                                                                + r_ext)
        if on_plane or (far and _on_sphere(gmsh, t, r_ext)):
            bnd.append(t)
    gmsh.model.addPhysicalGroup(2, bnd, BOUNDARY)


def _size_fields(gmsh, body_volumes, s, *, refine, balls, body_size, far_size, point_size):
    """gmsh size fields (m, scaled by ``s``): near the bodies' surfaces, in the ``refine``
    boxes and in balls around the ``balls`` points. Returns the field tags."""
    f = gmsh.model.mesh.field
    body_surfs = set()
    for ents in body_volumes:
        for t in ents:
            for d, st in gmsh.model.getBoundary([(3, t)], oriented=False):
                body_surfs.add(abs(st))
    surf = sorted(body_surfs)
    fields = []
    dist = f.add("Distance")
    f.setNumbers(dist, "SurfacesList", surf)
    f.setNumber(dist, "Sampling", 40)
    thr = f.add("Threshold")
    f.setNumber(thr, "InField", dist)
    f.setNumber(thr, "SizeMin", body_size * s)
    f.setNumber(thr, "SizeMax", far_size * s)
    f.setNumber(thr, "DistMin", 2e-3)
    f.setNumber(thr, "DistMax", 0.1)
    fields.append(thr)
    for (xa, xb, ya, yb, za, zb, h) in refine:
        bx = f.add("Box")
        f.setNumber(bx, "VIn", h * s)
        f.setNumber(bx, "VOut", far_size * s)
        for k, v in zip(("XMin", "XMax", "YMin", "YMax", "ZMin", "ZMax"),
                        (xa, xb, ya, yb, za, zb)):
            f.setNumber(bx, k, v)
        f.setNumber(bx, "Thickness", 0.03)
        fields.append(bx)
    for c in balls:
        bl = f.add("Ball")
        f.setNumber(bl, "Radius", FIT_HALF_WINDOW + 2e-3)
        f.setNumber(bl, "Thickness", 4e-3)
        f.setNumber(bl, "VIn", point_size * s)
        f.setNumber(bl, "VOut", far_size * s)
        for k, v in zip(("XCenter", "YCenter", "ZCenter"), c):
            f.setNumber(bl, k, float(v))
        fields.append(bl)
    return fields


@dataclass(frozen=True)
class MeshSettings:
    """The mesh of a 3-D model: its ``symmetry`` part, refinement ``level`` (sizes shrink by
    sqrt(2) per level), ``refine`` boxes (xmin, xmax, ymin, ymax, zmin, zmax, size), the air
    sphere ``r_int`` and the shell to ``r_ext`` (m), element sizes at the bodies and far
    away, and ``balls``: points (m) meshed at ``point_size`` within FIT_HALF_WINDOW + 2 mm
    (the fitting lines)."""

    symmetry: str = "none"
    level: int = 0
    refine: tuple = ()
    r_int: float = 0.25
    r_ext: float = 0.32
    body_size: float = 3.0e-3
    far_size: float = 25e-3
    balls: object = ()
    point_size: float = 2.0e-3


def build_mesh(bodies, msh_path, settings: MeshSettings = MeshSettings()) -> dict:
    """gmsh 3-D mesh of the bodies in a sphere + shell, cut to the symmetry part
    (:class:`MeshSettings`). Returns mesh statistics."""
    st = settings
    symmetry, level, refine, r_int, r_ext = st.symmetry, st.level, st.refine, st.r_int, st.r_ext
    body_size, far_size, balls, point_size = st.body_size, st.far_size, st.balls, st.point_size
    s = 2.0 ** (-level / 2.0)
    with gmsh_model("designkit_fem3d") as gmsh:
        occ = gmsh.model.occ
        objs = _add_bodies(occ, bodies, symmetry, r_int, r_ext)
        out, out_map = occ.fragment([objs[0]], [o for o in objs[1:] if o is not None])
        occ.synchronize()
        groups, body_groups = _volume_groups(bodies, objs, out_map)
        for tag, ents in groups.items():
            if ents:
                gmsh.model.addPhysicalGroup(3, ents, tag)
        for tag, ents in body_groups.items():
            gmsh.model.addPhysicalGroup(3, ents, tag)
        _boundary_group(gmsh, symmetry, r_int, r_ext)
        fields = _size_fields(gmsh, list(body_groups.values()) + [groups[MAGNET]], s,
                              refine=refine, balls=balls, body_size=body_size,
                              far_size=far_size, point_size=point_size)
        mesh_to_file(gmsh, fields, 3, msh_path)
        nodes = len(gmsh.model.mesh.getNodes()[0])
        _, et, _ = gmsh.model.mesh.getElements(3)
        ntet = int(sum(len(t) for t in et))
        return {"nodes": nodes, "tetrahedra": ntet, "cores": sorted(body_groups),
                "magnet": bool(groups[MAGNET])}
