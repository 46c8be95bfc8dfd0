"""Output of the figures: PNG files (rendered off-screen, written atomically), one figure by
name (``designkit viz KIND``), every figure into a folder (``designkit report``: a figure that
fails is recorded, the others are written) and the figures' data as VTK files for ParaView
(metres, SI arrays and their mT/mN copies)."""

from __future__ import annotations

import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

from ..errors import BadInputError, MissingDependencyError
from ..support.atomic import atomic_path
from .common import KINDS, Kind, Quality, import_pyvista
from .fieldlines import field_line_data, plot_field_lines
from .forcemap import force_map_data, plot_force_map
from .isosurface import force_isosurface_data, plot_force_isosurface
from .physics import resolve_currents
from .scene import plot_array_scene, scene_meshes
from .slices import plot_slices, slice_data
from .style import round_colour_bars

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from ..design import Design


def save_png(plotter: "pyvista.Plotter", path: str | Path) -> Path:
    """Render the plotter off-screen and write a PNG atomically; returns the path."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise BadInputError("path", "a file name ending in .png", str(path))
    round_colour_bars(plotter)
    with atomic_path(path, suffix=".png") as tmp:
        plotter.screenshot(str(tmp))
    return path


def render(kind: Kind, design: "Design", currents: Sequence[float] | None = None, *,
           quality: Quality = "full", window_size=None) -> "pyvista.Plotter":
    """The plotter of one figure by name (``designkit viz KIND``); see :data:`KINDS`."""
    if kind not in KINDS:
        raise BadInputError("kind", f"one of {KINDS}", kind)
    kw = {} if window_size is None else {"window_size": window_size}
    if kind == "scene":
        return plot_array_scene(design, currents, **kw)
    if kind == "fieldlines":
        return plot_field_lines(design, currents, quality=quality, **kw)
    if kind in ("slice-B", "slice-F"):
        return plot_slices(design, currents, quantity=kind[-1], quality=quality, **kw)
    if kind == "forcemap":
        return plot_force_map(design, currents, quality=quality, **kw)
    return plot_force_isosurface(design, currents, quality=quality, **kw)


DATA_OF = {"scene": "scene", "fieldlines": "fieldlines", "slice-B": "slices",
           "slice-F": "slices", "forcemap": "forcemap", "isosurface": "isosurface"}
"""The dataset each figure kind draws (both slices draw one)."""
WIDE_KINDS = ("scene", "slice-B", "slice-F")
"""Figures of two panels side by side, drawn in the wide window size."""


@dataclass
class FigureSet:
    """What :func:`write_figures` wrote: ``figures`` (kind -> PNG path), ``failed`` (kind -> the
    error, one line, and where it was raised) and ``data`` (the datasets drawn, keyed as
    :func:`export_vtk` takes them)."""

    figures: dict = field(default_factory=dict)
    failed: dict = field(default_factory=dict)
    data: dict = field(default_factory=dict)


def write_figures(design: "Design", out_dir: str | Path, currents: Sequence[float] | None = None,
                  *, quality: Quality = "full", sizes=((1024, 768), (1500, 640)),
                  kinds: Sequence[str] = KINDS) -> FigureSet:
    """Render each figure kind into ``out_dir/KIND.png``; ``sizes``: (window, wide window) in
    pixels (:data:`WIDE_KINDS` take the wide one). A figure whose data or drawing fails is
    recorded in ``failed`` with its error and the others are still written; only a missing
    pyvista (:class:`MissingDependencyError`) stops the lot."""
    out = Path(out_dir)
    cur = resolve_currents(design, currents)
    builders = {
        "scene": lambda: scene_meshes(design, cur),
        "fieldlines": lambda: field_line_data(design, cur, quality=quality),
        "slices": lambda: slice_data(design, cur, quality=quality),
        "forcemap": lambda: force_map_data(design, cur, quality=quality),
        "isosurface": lambda: force_isosurface_data(design, cur, quality=quality),
    }
    result = FigureSet()
    errors: dict = {}
    for kind in kinds:
        key = DATA_OF[kind]
        try:
            if key in errors:
                raise errors[key]
            if key not in result.data:
                result.data[key] = builders[key]()
            size = sizes[1] if kind in WIDE_KINDS else sizes[0]
            plotter = _plot(kind, design, cur, quality, size, result.data)
            try:
                save_png(plotter, out / f"{kind}.png")
            finally:
                plotter.close()
            result.figures[kind] = out / f"{kind}.png"
        except MissingDependencyError:
            raise
        except Exception as exc:  # noqa: BLE001 -- a figure's failure is reported, not fatal
            if key not in result.data:
                errors[key] = exc
            result.failed[kind] = _one_line(exc)
    return result


def _plot(kind, design, cur, quality, size, data):
    """The plotter of one kind from the datasets already built."""
    blocks = data.get("scene")
    if kind == "scene":
        return plot_array_scene(design, cur, window_size=size, blocks=blocks)
    if kind == "fieldlines":
        return plot_field_lines(design, cur, window_size=size, data=data["fieldlines"],
                                blocks=blocks)
    if kind in ("slice-B", "slice-F"):
        return plot_slices(design, cur, quantity=kind[-1], window_size=size,
                           data=data["slices"], blocks=blocks)
    if kind == "forcemap":
        return plot_force_map(design, cur, window_size=size, data=data["forcemap"],
                              blocks=blocks)
    return plot_force_isosurface(design, cur, window_size=size, data=data["isosurface"],
                                 blocks=blocks)


def _one_line(exc: BaseException) -> str:
    """'ValueError: message (slices.py:123)': the error and the line that raised it."""
    where = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    place = f" ({Path(where.filename).name}:{where.lineno})" if where else ""
    text = " ".join(str(exc).split()) or "no message"
    return f"{type(exc).__name__}: {text}{place}"


def _write_vtk(mesh, path: Path) -> Path:
    with atomic_path(path, suffix=path.suffix) as tmp:
        mesh.save(str(tmp), binary=True)
    return path


def export_vtk(design: "Design", out_dir: str | Path, currents: Sequence[float] | None = None,
               *, moment=None, quality: Quality = "full", data: dict | None = None,
               compute_missing: bool = True) -> dict[str, Path]:
    """Write the figures' data for ParaView into ``out_dir`` (metres, SI arrays + mT/mN copies).

    Files: ``coils.vtp`` (windings with ``"current (A)"``), ``cores.vtp``, ``magnet.vtp``,
    ``workspace.vtp``, ``field_volume.vts`` (B on the streamline grid), ``streamlines.vtp``,
    ``slice_vertical.vts``, ``slice_horizontal.vts``, ``force_map.vtp``,
    ``force_volume.vts`` (F on the iso-surface grid) and ``fz_isosurface.vtp``.

    Parameters
    ----------
    data : dict, optional
        Precomputed datasets keyed ``"scene"``, ``"fieldlines"``, ``"slices"``, ``"forcemap"``,
        ``"isosurface"`` (the builders' return values) to avoid evaluating the field again.
    compute_missing : bool
        Build the datasets ``data`` lacks (default); False writes only the files of those given.

    Returns
    -------
    dict of str -> Path
    """
    import_pyvista()
    out = Path(out_dir)
    cur = resolve_currents(design, currents)
    data = dict(data or {})
    builders = {
        "scene": lambda: scene_meshes(design, cur, moment=moment),
        "fieldlines": lambda: field_line_data(design, cur, quality=quality),
        "slices": lambda: slice_data(design, cur, moment=moment, quality=quality),
        "forcemap": lambda: force_map_data(design, cur, moment=moment, quality=quality),
        "isosurface": lambda: force_isosurface_data(design, cur, moment=moment,
                                                    quality=quality),
    }
    for key, build in builders.items():
        if key not in data and compute_missing:
            data[key] = build()
    items = {}
    if "scene" in data:
        blocks = data["scene"]
        items.update({"coils.vtp": blocks["windings"], "magnet.vtp": blocks["magnet"],
                      "workspace.vtp": blocks["workspace"]})
        if "cores" in blocks.keys():
            items["cores.vtp"] = blocks["cores"]
    if "fieldlines" in data:
        vol, lines = data["fieldlines"]
        items.update({"field_volume.vts": _structured(vol), "streamlines.vtp": lines})
    if "slices" in data:
        vert, horiz = data["slices"]
        items.update({"slice_vertical.vts": _structured(vert),
                      "slice_horizontal.vts": _structured(horiz)})
    if "forcemap" in data:
        items["force_map.vtp"] = data["forcemap"]
    if "isosurface" in data:
        fvol, iso, _ = data["isosurface"]
        items.update({"force_volume.vts": _structured(fvol), "fz_isosurface.vtp": iso})
    written = {}
    for name, mesh in items.items():
        if hasattr(mesh, "extract_surface") and name.endswith(".vtp") and \
                not isinstance(mesh, import_pyvista().PolyData):
            mesh = mesh.extract_surface()
        written[name] = _write_vtk(mesh, out / name)
    return written


def _structured(mesh):
    """A grid as a StructuredGrid (.vts): image grids are cast, structured ones kept."""
    return mesh.cast_to_structured_grid() if isinstance(mesh, import_pyvista().ImageData) \
        else mesh
