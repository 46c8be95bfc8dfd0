"""The export step: checked part files, assembly STEP, assembly PNG and the parts list.

Order of work, so that a bad design writes nothing:

1. design rules on the parameters (:func:`cad.rules.check_rules`);
2. build every part; build-volume fit of each printed part; interference check of the
   assembly;
3. write each file to a temporary name next to its destination and check the bytes
   written (STL/3MF: watertight, manifold, positive volume within area x tolerance of the
   solid's; STEP: re-imported volume);
4. only when everything passed are the temporary files renamed into place.
"""

from __future__ import annotations

import contextlib
import json
import re
import time
import zipfile
from dataclasses import asdict
from pathlib import Path
from typing import Iterable, Literal
from xml.sax.saxutils import quoteattr

import numpy as np

from designkit.support.atomic import atomic_path
from designkit.support.progress import tqdm
from designkit.errors import BadInputError, DesignRuleError

from . import meshcheck
from .assembly import (assembly, build_parts, interferences, part_info, part_names, placements,
                       quantities)
from .params import CadParams
from .rules import check_rules, fit_in_build_volume

Format = Literal["stl", "step", "3mf"]
FORMATS: tuple[Format, ...] = ("stl", "step", "3mf")


class MeshCheckError(DesignRuleError):
    """An exported file failed its check (not watertight, wrong volume, unreadable STEP)."""


def parse_formats(text: str | Iterable[str]) -> tuple[Format, ...]:
    """``"stl,step"`` -> ``("stl", "step")``, checked against :data:`FORMATS`."""
    items = text.split(",") if isinstance(text, str) else list(text)
    out = []
    for item in items:
        f = item.strip().lower().lstrip(".")
        if f not in FORMATS:
            raise BadInputError("format", f"a comma-separated subset of {','.join(FORMATS)}", item)
        if f not in out:
            out.append(f)
    if not out:
        raise BadInputError("format", f"a comma-separated subset of {','.join(FORMATS)}", text)
    return tuple(out)


def _mesh_absolute(shape, p: CadParams) -> None:
    """Triangulate with an absolute chord tolerance (mm), replacing any earlier triangulation.

    build123d's exporters ask OCCT for a deflection relative to each edge's size, which for
    a 24 mm core gives 0.5 mm chords; the absolute mesh is what makes the area x tolerance
    volume bound of :mod:`cad.meshcheck` hold. export_stl keeps this finer mesh.
    """
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.BRepTools import BRepTools

    BRepTools.Clean_s(shape.wrapped)
    BRepMesh_IncrementalMesh(shape.wrapped, p.printer.tolerance_mm, False,
                             p.printer.angular_tolerance_rad, True)


def _triangulation(shape) -> tuple[np.ndarray, np.ndarray]:
    """The shape's current face triangulations as one merged mesh, outward-oriented (mm)."""
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_REVERSED
    from OCP.TopLoc import TopLoc_Location

    corners = []
    for face in shape.faces():
        loc = TopLoc_Location()
        tri = BRep_Tool.Triangulation_s(face.wrapped, loc)
        if tri is None:
            raise MeshCheckError(f"a face of {shape.label or 'a part'} has no triangulation")
        trsf = loc.Transformation()
        nodes = np.array([tuple(tri.Node(i).Transformed(trsf).Coord())
                          for i in range(1, tri.NbNodes() + 1)])
        idx = np.array([[t.Value(1), t.Value(2), t.Value(3)] for t in tri.Triangles()]) - 1
        if face.wrapped.Orientation() == TopAbs_REVERSED:
            idx = idx[:, ::-1]
        corners.append(nodes[idx].reshape(-1, 3))
    return meshcheck.merge_corners(np.concatenate(corners))


_3MF_TYPES = ('<?xml version="1.0" encoding="UTF-8"?>\n<Types xmlns="http://schemas.openxmlformats.org/'
              'package/2006/content-types"><Default Extension="rels" ContentType="application/'
              'vnd.openxmlformats-package.relationships+xml"/><Default Extension="model" '
              'ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/></Types>\n')
_3MF_RELS = ('<?xml version="1.0" encoding="UTF-8"?>\n<Relationships xmlns="http://schemas.'
             'openxmlformats.org/package/2006/relationships"><Relationship Target="/3D/3dmodel.model" '
             'Id="rel0" Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/>'
             '</Relationships>\n')


def write_3mf(vertices: np.ndarray, triangles: np.ndarray, path: str | Path, name: str) -> None:
    """Minimal 3MF core package (one mesh object, millimetres).

    Written here rather than with build123d's Mesher because Mesher re-triangulates with a
    relative deflection; this writes exactly the checked triangulation.
    """
    vx = "".join(f'<vertex x="{x:.9g}" y="{y:.9g}" z="{z:.9g}"/>' for x, y, z in vertices)
    tx = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in triangles)
    model = ('<?xml version="1.0" encoding="UTF-8"?>\n<model unit="millimeter" xml:lang="en-US" '
             'xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">'
             f'<metadata name="Title">{name}</metadata><metadata name="Application">designkit cad'
             f'</metadata><resources><object id="1" type="model" name={quoteattr(name)}><mesh>'
             f'<vertices>{vx}</vertices><triangles>{tx}</triangles></mesh></object></resources>'
             '<build><item objectid="1"/></build></model>\n')
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("[Content_Types].xml", _3MF_TYPES)
        zf.writestr("_rels/.rels", _3MF_RELS)
        zf.writestr("3D/3dmodel.model", model)


def _write_part(name: str, shape, path: Path, fmt: Format, p: CadParams) -> None:
    from build123d import export_step, export_stl

    if fmt == "stl":
        _mesh_absolute(shape, p)
        ok = export_stl(shape, path, tolerance=p.printer.tolerance_mm,
                        angular_tolerance=p.printer.angular_tolerance_rad)
    elif fmt == "3mf":
        _mesh_absolute(shape, p)
        write_3mf(*_triangulation(shape), path, name)
        ok = True
    else:
        ok = export_step(shape, path)
    if ok is False or not path.exists() or path.stat().st_size == 0:
        raise MeshCheckError(f"build123d wrote nothing for {path.name} ({fmt})")


def _check_file(name: str, shape, path: Path, fmt: Format, p: CadParams) -> dict:
    """Check the written bytes; return a summary, raise MeshCheckError on a failure."""
    volume, area = float(shape.volume), float(shape.area)
    if fmt == "step":
        from build123d import import_step

        back = import_step(path)
        v_back = float(back.volume)
        if not abs(v_back - volume) <= 1e-6 * volume:
            raise MeshCheckError(f"{name}.step re-imports with volume {v_back:.6g} mm^3, the solid "
                                 f"has {volume:.6g} mm^3")
        return {"step_volume_mm3": v_back}
    verts, tris = (meshcheck.read_stl if fmt == "stl" else meshcheck.read_3mf)(path)
    rep = meshcheck.mesh_report(verts, tris)
    problems = meshcheck.check_mesh(rep, volume, area, p.printer.tolerance_mm)
    if problems:
        raise MeshCheckError(f"{name}.{fmt}: " + "; ".join(problems)
                             + ". Try a smaller --tolerance; report the part if it persists.")
    return {"triangles": rep.n_triangles, "watertight": rep.watertight, "manifold": rep.manifold,
            "mesh_volume_mm3": rep.volume, "volume_bound_mm3": area * p.printer.tolerance_mm,
            "relative_volume_error": (rep.volume - volume) / volume,
            "_mesh": (verts, tris)}


def _coils_of(name: str, p: CadParams) -> str:
    """' (coils 0, 4)' for a part of one coil type when the design has several, else ''."""
    for t in p.types:
        if t.suffix and name.endswith(t.suffix):
            return f" (coils {', '.join(map(str, t.coils))})"
    return ""


def _segment_of(name: str, p: CadParams) -> str:
    """', segment k of n' / ', one of n identical segments' for a plate printed in pieces."""
    m = re.search(r"(frame|sensor_mount)_(upper|lower)_(s(\d+)|segment)$", name)
    if m is None:
        return ""
    n = len((p.sensor_mount if m.group(1) == "sensor_mount" else
             p.upper if m.group(2) == "upper" else p.lower).segments)
    return (f", one of {n} identical segments (the rods clamp the seams)" if m.group(4) is None
            else f", segment {m.group(4)} of {n} (the rods clamp the seams)")


def _part_row(name: str, shape, qty: int, p: CadParams) -> dict:
    info = part_info(name)
    v = float(shape.volume)
    bb = shape.bounding_box()
    size = tuple(round(float(s), 4) for s in bb.size)
    row = {
        "part": name, "description": info.description + _coils_of(name, p) + _segment_of(name, p),
        "quantity": qty,
        "material": info.material, "kind": info.kind,
        "volume_mm3": v, "area_mm2": float(shape.area), "size_mm": size,
        "mass_g": v * dict(p.printer.density_g_cm3)[info.material] * 1e-3,
    }
    if info.kind == "printed":
        order = fit_in_build_volume(size, p.printer.build_volume_mm)
        row["fits_printer"] = order is not None
        row["print_orientation"] = None if order is None else "xyz"[order[0]] + "xyz"[order[1]] + "xyz"[order[2]]
        row["print_time_proxy_h"] = v / p.printer.flow_mm3_per_s / 3600.0
    return row


class _Staging:
    """Files staged as temporary names next to their destinations (``out_dir``); the
    ExitStack renames them into place when its block ends without an error."""

    def __init__(self, stack: contextlib.ExitStack, out: Path):
        self.stack, self.out = stack, out
        self.files: dict[str, Path] = {}

    def __call__(self, filename: str) -> Path:
        """The temporary path to write ``filename`` to."""
        dest = self.out / filename
        tmp = self.stack.enter_context(atomic_path(dest))
        self.files[filename] = dest
        return tmp


def _refuse_oversize(rows: dict, p: CadParams, oversize: str) -> list[str]:
    """Names of the printed parts too big for the build volume (raise with 'error')."""
    too_big = [r for r in rows.values() if r.get("fits_printer") is False]
    if too_big and oversize == "error":
        bv = " x ".join(f"{v:g}" for v in p.printer.build_volume_mm)
        raise DesignRuleError("; ".join(
            f"{r['part']} is {' x '.join(f'{s:.1f}' for s in r['size_mm'])} mm and fits the "
            f"{bv} mm build volume in no orientation" for r in too_big)
            + ": split the part, use a larger printer (--build-volume), or --oversize skip.")
    return [r["part"] for r in too_big]


def _refuse_interference(p: CadParams, parts: dict) -> None:
    """Raise DesignRuleError when instances of the assembly share volume."""
    hits = interferences(p, parts)
    if hits:
        raise DesignRuleError("parts interfere in the assembly: " + "; ".join(
            f"{a} and {b} share {v:.3g} mm^3" for a, b, v in hits[:8])
            + ". Check the clearances (pocket_clearance_mm, core_clearance_mm) and "
            "sensors.offset_m.")


def _write_parts(stage: _Staging, jobs, parts: dict, rows: dict, p: CadParams,
                 bar) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Write and check every (part, format) job; record the checks in ``rows``. Returns the
    checked meshes by part (the first mesh format written), for the picture."""
    meshes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, fmt in jobs:
        tmp = stage(f"{name}.{fmt}")
        _write_part(name, parts[name], tmp, fmt, p)
        summary = _check_file(name, parts[name], tmp, fmt, p)
        mesh = summary.pop("_mesh", None)
        if mesh is not None and name not in meshes:
            meshes[name] = mesh
        rows[name].setdefault("checks", {})[fmt] = summary
        if bar is not None:
            bar.update()
    return meshes


def _write_assembly_step(stage: _Staging, p: CadParams, parts: dict) -> None:
    """assembly.step: every instance, labelled and coloured."""
    from build123d import export_step

    export_step(assembly(p, parts), stage("assembly.step"))


def _write_picture(stage: _Staging, p: CadParams, parts: dict, meshes: dict) -> None:
    """assembly.png; reference parts (winding, magnet) and parts not exported as a mesh are
    drawn from an in-memory tessellation with the same tolerance."""
    for name in part_names(p):
        if name not in meshes:
            meshes[name] = _tessellate(parts[name], p)
    render_assembly_png(p, meshes, stage("assembly.png"))


def export_all(p: CadParams, out_dir: str | Path, formats: Iterable[Format] = FORMATS, *,
               picture: Literal["png", "none"] = "png",
               oversize: Literal["error", "skip"] = "error",
               check_interference: Literal["yes", "no"] = "yes",
               progress: Literal["bar", "none"] = "bar") -> dict:
    """Write every part, the assembly STEP, the assembly PNG and the parts list under out_dir.

    Parameters
    ----------
    p : CadParams
    out_dir : path
        Created if missing. Files: ``<part>.<fmt>``, ``assembly.step``, ``assembly.png``,
        ``parts.json``, ``parts.md``.
    formats : iterable of {'stl', 'step', '3mf'}
    oversize : {'error', 'skip'}
        A printed part that fits the build volume in no axis-aligned orientation raises
        (default, nothing written) or is left out of the export and listed with its size.

    Returns
    -------
    dict
        ``parts`` (rows of the parts list), ``files`` ({name: bytes}), ``skipped``,
        ``seconds`` (per stage), ``out_dir``.
    """
    formats = parse_formats(formats)
    if oversize not in ("error", "skip"):
        raise BadInputError("oversize", "'error' or 'skip'", oversize)
    out = Path(out_dir)
    t0 = time.perf_counter()
    seconds: dict[str, float] = {}
    check_rules(p)
    seconds["rules"] = time.perf_counter() - t0

    t = time.perf_counter()
    parts = build_parts(p)
    qty = quantities(p)
    exported = part_names(p, "exported")
    rows = {name: _part_row(name, parts[name], qty[name], p) for name in part_names(p)}
    seconds["build"] = time.perf_counter() - t
    skipped = _refuse_oversize(rows, p, oversize)
    if check_interference == "yes":
        t = time.perf_counter()
        _refuse_interference(p, parts)
        seconds["interference"] = time.perf_counter() - t

    jobs = [(name, fmt) for name in exported if name not in skipped for fmt in formats]
    bar = None
    if progress == "bar":
        bar = tqdm(total=len(jobs) + 2 + (picture == "png"), desc="designkit cad", unit="file",
                   leave=False)
    t = time.perf_counter()
    with contextlib.ExitStack() as stack:
        stage = _Staging(stack, out)
        meshes = _write_parts(stage, jobs, parts, rows, p, bar)
        seconds["parts"] = time.perf_counter() - t

        if "step" in formats:  # the assembly STEP is a STEP file: only when STEP is asked for
            t = time.perf_counter()
            _write_assembly_step(stage, p, parts)
            seconds["assembly_step"] = time.perf_counter() - t
        if bar is not None:
            bar.update()
        if picture == "png":
            t = time.perf_counter()
            _write_picture(stage, p, parts, meshes)
            seconds["png"] = time.perf_counter() - t
            if bar is not None:
                bar.update()

        seconds["total"] = time.perf_counter() - t0
        report = {
            "design": p.design_name, "out_dir": str(out), "formats": list(formats),
            "mandrel": p.bobbin.mandrel, "printer": asdict(p.printer),
            "parts": list(rows.values()), "skipped_oversize": skipped,
            "totals": _totals(rows.values()), "seconds": seconds,
        }
        stage("parts.json").write_text(json.dumps(report, indent=2) + "\n")
        stage("parts.md").write_text(parts_markdown(report))
        if bar is not None:
            bar.close()
    report["files"] = {k: v.stat().st_size for k, v in sorted(stage.files.items())}
    return report


def _totals(rows) -> dict:
    rows = list(rows)
    printed = [r for r in rows if r["kind"] == "printed"]
    masses = {}
    for r in rows:
        masses[r["material"]] = masses.get(r["material"], 0.0) + r["mass_g"] * r["quantity"]
    return {"mass_g": masses,
            "print_time_proxy_h": sum(r["print_time_proxy_h"] * r["quantity"] for r in printed)}


def parts_markdown(report: dict) -> str:
    """The parts list as a Markdown table (mm, g, h)."""
    lines = [f"# Parts list: {report['design']}", "",
             f"Bobbin mandrel: `{report['mandrel']}`. Masses per piece; print time is a proxy "
             f"(solid volume / {report['printer']['flow_mm3_per_s']:g} mm^3/s); each mass is "
             "the part's volume times the density of its own material "
             f"({', '.join(f'{m} {d:g}' for m, d in report['printer']['density_g_cm3'])} "
             "g/cm^3; the winding is drawn as a solid copper annulus, so its mass is an upper "
             "bound on the wire's).", "",
             "| part | qty | material | kind | volume mm^3 | mass g | size mm "
             "| fits printer | print time proxy h |",
             "| --- | ---: | --- | --- | ---: | ---: | --- | --- | ---: |"]
    for r in report["parts"]:
        size = " x ".join(f"{s:.1f}" for s in r["size_mm"])
        fits = {True: "yes", False: "NO"}.get(r.get("fits_printer"), "-")
        ptime = f"{r['print_time_proxy_h']:.2f}" if "print_time_proxy_h" in r else "-"
        lines.append(f"| {r['part']} | {r['quantity']} | {r['material']} | {r['kind']} | "
                     f"{r['volume_mm3']:.1f} | {r['mass_g']:.1f} | "
                     f"{size} | {fits} | {ptime} |")
    t = report["totals"]
    per = ", ".join(f"{m} {g:.0f} g" for m, g in t["mass_g"].items())
    lines += ["", f"Totals (all pieces): {per}; print time proxy {t['print_time_proxy_h']:.1f} h."]
    if report["skipped_oversize"]:
        lines.append(f"Not exported (larger than the build volume): {', '.join(report['skipped_oversize'])}.")
    return "\n".join(lines) + "\n"


def _tessellate(shape, p: CadParams) -> tuple[np.ndarray, np.ndarray]:
    verts, tris = shape.tessellate(p.printer.tolerance_mm * 5, p.printer.angular_tolerance_rad)
    xyz = np.array([tuple(v) for v in verts], dtype=float)
    # build123d repeats edge vertices per face; merge them so the mesh is closed for capping
    return meshcheck.merge_corners(xyz[np.asarray(tris, dtype=np.int64).reshape(-1)])


def _capped_half(mesh, origin, normal):
    """The part of a closed mesh on the ``normal`` side of the plane through ``origin``,
    closed by a cap on the cut plane."""
    d = (np.asarray(mesh.points) - origin) @ normal
    if d.size and d.min() >= 0:
        return mesh
    if not d.size or d.max() <= 0:
        return mesh.extract_points([], adjacent_cells=False)  # empty
    try:
        return mesh.clip_closed_surface(normal=tuple(normal), origin=tuple(origin))
    except Exception:  # pragma: no cover - VTK refuses non-manifold input; show it open
        return mesh.clip(normal=tuple(normal), origin=tuple(origin), invert=False)


def section_plane(p: CadParams) -> tuple[np.ndarray, np.ndarray, int]:
    """The vertical plane of the assembly picture's section: through the magnet's design point
    and the top of the coil nearest it (the plane y = const when that coil is under it).
    Returns (origin (3,) mm, unit normal (3,), the coil's index)."""
    m = np.asarray(p.magnet_centre_mm, dtype=float)
    tops = np.array([top for top, _ in p.coil_frames])
    d = tops[:, :2] - m[:2]
    dist = np.hypot(d[:, 0], d[:, 1])
    k = int(np.flatnonzero(dist <= dist.min() + 1e-6)[0])  # ties: the first coil
    along = d[k] / np.linalg.norm(d[k]) if np.linalg.norm(d[k]) > 1e-6 else np.array([1.0, 0.0])
    return m, np.array([-along[1], along[0], 0.0]) + 0.0, k


def render_assembly_png(p: CadParams, meshes: dict[str, tuple[np.ndarray, np.ndarray]],
                        path: str | Path, window_size: tuple[int, int] = (1600, 800)) -> Path:
    """Off-screen picture of the assembly: isometric view and a vertical section through the
    magnet's design point and the coil nearest it (:func:`section_plane`).

    Parameters
    ----------
    meshes : dict
        ``{part name: (vertices (n, 3) mm, triangles (m, 3))}`` in each part's local frame;
        the exported STL meshes where there are any.
    path : path
        PNG destination (written directly: pass a temporary path for atomicity).
    """
    import pyvista as pv

    placed: dict[str, list] = {}  # by kind: a plate's segments are one entry of the legend
    for pl in placements(p):
        if pl.part not in meshes:
            continue
        v, t = meshes[pl.part]
        faces = np.hstack([np.full((len(t), 1), 3), t]).ravel()
        mesh = pv.PolyData(v.copy(), faces).transform(pl.matrix(), inplace=False)
        placed.setdefault(re.sub(r"_(s\d+|segment)$", "", pl.part), []).append(mesh)

    origin, normal, nearest = section_plane(p)
    if abs(normal[0]) < 1e-12:
        where = f"y = {origin[1]:g} mm"
    else:
        angle = np.degrees(np.arctan2(-normal[0], normal[1])) % 180.0
        where = f"along {angle:.0f} deg from x"
    with pv.vtk_verbosity("off"):  # no display here: silence VTK's X-server warning
        plotter = pv.Plotter(off_screen=True, window_size=list(window_size), shape=(1, 2),
                             border=False)
    plotter.set_background("white")
    for col, title in [(0, "assembly"),
                       (1, f"section {where} through the magnet and coil {nearest}")]:
        plotter.subplot(0, col)
        for name, group in placed.items():
            shown = group
            if col == 1:
                # keep the half behind the cut, capped, so cores and pockets read as solids
                shown = [_capped_half(m, origin, normal) for m in group]
                shown = [m for m in shown if m.n_points]
                if not shown:
                    continue
            merged = pv.merge(shown) if len(shown) > 1 else shown[0]
            plotter.add_mesh(merged, color=part_info(name).color, smooth_shading=False,
                             label=None if col else f"{name} x{len(group)}")
        plotter.add_text(title, font_size=10, color="black", position="upper_edge")
        if col == 0:
            plotter.add_legend(bcolor=None, face="rectangle", size=(0.24, 0.3), loc="upper left")
            plotter.view_isometric()
            plotter.reset_camera()
            plotter.camera.zoom(0.95)
        else:
            # look at the cut face from the side the kept half is not on
            plotter.enable_parallel_projection()
            plotter.camera.focal_point = tuple(origin)
            plotter.camera.position = tuple(origin - 1000.0 * normal)
            plotter.camera.up = (0.0, 0.0, 1.0)
            plotter.camera.elevation = 8
            plotter.reset_camera()
            plotter.camera.zoom(1.1)
    plotter.subplot(0, 1)
    plotter.add_text(f"designkit cad: {p.design_name} (mm)", font_size=8, color="gray",
                     position="lower_right")
    with pv.vtk_verbosity("off"):
        plotter.screenshot(str(path))
    plotter.close()
    return Path(path)
