"""Output of the figures: PNG files (rendered off-screen, written atomically), one figure by
name (``designkit viz KIND``) and the figures' data as VTK files for ParaView (metres, SI arrays
and their mT/mN copies)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Sequence

from ..errors import BadInputError
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


def _write_vtk(mesh, path: Path) -> Path:
    with atomic_path(path, suffix=path.suffix) as tmp:
        mesh.save(str(tmp), binary=True)
    return path


def export_vtk(design: "Design", out_dir: str | Path, currents: Sequence[float] | None = None,
               *, moment=None, quality: Quality = "full", data: dict | None = None
               ) -> dict[str, Path]:
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

    Returns
    -------
    dict of str -> Path
    """
    import_pyvista()
    out = Path(out_dir)
    cur = resolve_currents(design, currents)
    data = dict(data or {})
    if "scene" not in data:
        data["scene"] = scene_meshes(design, cur, moment=moment)
    if "fieldlines" not in data:
        data["fieldlines"] = field_line_data(design, cur, quality=quality)
    if "slices" not in data:
        data["slices"] = slice_data(design, cur, moment=moment, quality=quality)
    if "forcemap" not in data:
        data["forcemap"] = force_map_data(design, cur, moment=moment, quality=quality)
    if "isosurface" not in data:
        data["isosurface"] = force_isosurface_data(design, cur, moment=moment, quality=quality)
    blocks = data["scene"]
    vol, lines = data["fieldlines"]
    vert, horiz = data["slices"]
    fvol, iso, _ = data["isosurface"]
    items = {
        "coils.vtp": blocks["windings"],
        "magnet.vtp": blocks["magnet"],
        "workspace.vtp": blocks["workspace"],
        "field_volume.vts": vol.cast_to_structured_grid(),
        "streamlines.vtp": lines,
        "slice_vertical.vts": vert.cast_to_structured_grid(),
        "slice_horizontal.vts": horiz.cast_to_structured_grid(),
        "force_map.vtp": data["forcemap"],
        "force_volume.vts": fvol.cast_to_structured_grid(),
        "fz_isosurface.vtp": iso,
    }
    if "cores" in blocks.keys():
        items["cores.vtp"] = blocks["cores"]
    written = {}
    for name, mesh in items.items():
        if hasattr(mesh, "extract_surface") and name.endswith(".vtp") and \
                not isinstance(mesh, import_pyvista().PolyData):
            mesh = mesh.extract_surface()
        written[name] = _write_vtk(mesh, out / name)
    return written
