"""Off-screen pyvista figures and ParaView (VTK) files of a design's coils, fields and forces.

Two layers, as everywhere in designkit:

* data builders (``scene_meshes``, ``field_line_data``, ``slice_data``, ``force_map_data``,
  ``force_isosurface_data``) evaluate the array's field on a grid and return pyvista datasets in
  the design frame (metres, coil top faces at z = 0, z up) carrying SI arrays
  (``"B (T)"``, ``"grad B (T/m)"``, ``"F (N)"``) and, for colouring, the same magnitudes in the
  units people read (``"B magnitude (mT)"``, ``"F magnitude (mN)"``, ``"Fz (mN)"``);
* ``plot_*`` functions turn them into a :class:`pyvista.Plotter` (``off_screen=True``, never
  shown) drawn in millimetres with titles and colour bars; :func:`save_png` writes it atomically
  and :func:`export_vtk` writes the datasets as ``.vtp`` / ``.vts`` files for ParaView.

The force on the finger magnet is ``F = (grad B)^T m`` (:func:`designkit.array.force_matrix`,
thesis eq. 2.5) with ``m`` the design's magnet moment (MagnetSpec.direction, default -z) unless
another moment is given.

pyvista is imported only here, lazily: without it the functions raise
:class:`designkit.errors.MissingDependencyError` ("designkit.viz needs pyvista: pip install
pyvista"). Without a display (no ``DISPLAY``), VTK is pointed at its EGL render window, which
renders off-screen on machines with no X server.

Default currents (``currents=None``): the coil nearest the array centre at the design's
``drive.max_current_a`` and every other coil at 0 A -- the situation of the design point in
``designkit report``. Coils at 0 A are skipped when the field is evaluated.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Sequence

import numpy as np

from . import _validate as v
from ._io import atomic_path
from .errors import BadInputError, MissingDependencyError

if TYPE_CHECKING:  # pragma: no cover
    import pyvista

    from .design import Design

Quality = Literal["quick", "full"]
Kind = Literal["scene", "fieldlines", "slice-B", "slice-F", "forcemap", "isosurface"]
KINDS: tuple[str, ...] = ("scene", "fieldlines", "slice-B", "slice-F", "forcemap", "isosurface")
QUALITIES: tuple[str, ...] = ("quick", "full")

# Grid points per axis. "quick" is for tests and `designkit report --quick`; "full" keeps the
# whole report under about a minute on the default design (a gradient costs ~0.15 ms per point
# per active coil).
_RES = {
    "quick": {"volume": (17, 17, 19), "slice": (33, 21), "plane": (35, 35), "map": 9,
              "iso": (19, 19, 17)},
    "full": {"volume": (33, 33, 41), "slice": (81, 51), "plane": (81, 81), "map": 15,
             "iso": (37, 37, 31)},
}

B_T, B_MT = "B (T)", "B magnitude (mT)"
GRAD_T_M, F_N, F_MN, FZ_MN = "grad B (T/m)", "F (N)", "F magnitude (mN)", "Fz (mN)"
CURRENT_A = "current (A)"
IN_SOLID = "inside a core or winding"
REACH_M = "height where |Fz| on the coil axes falls below the level (m)"

_COPPER, _STEEL, _MAGNET = "#c87533", "#8c8c8c", "#b22222"
MIN_ARROW = 0.3
"""Shortest force arrow in the force map, as a fraction of the longest."""


# ----------------------------------------------------------------------------- pyvista
def _pv():
    """Import pyvista for off-screen use, or raise MissingDependencyError with the fix."""
    if not os.environ.get("DISPLAY"):
        # VTK otherwise tries X first and logs "bad X server connection" before falling back.
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    try:
        import pyvista
    except ImportError as exc:
        raise MissingDependencyError("pyvista", "pyvista", "designkit.viz") from exc
    return pyvista


def _quality(quality: str) -> dict:
    if quality not in QUALITIES:
        raise BadInputError("quality", f"one of {QUALITIES}", quality)
    return _RES[quality]


def _window(window_size) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in window_size)
    except (TypeError, ValueError):
        raise BadInputError("window_size", "two whole numbers (width, height) in pixels",
                            window_size) from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise BadInputError("window_size", "(width, height) each in [16, 8192] px", window_size)
    return w, h


# ----------------------------------------------------------------------------- physics
def resolve_currents(design: "Design", currents: Sequence[float] | None = None) -> np.ndarray:
    """Per-coil currents, A, shape (ncoils,), row-major like :meth:`Design.coil_centres_m`.

    ``None`` gives the default: the coil nearest the array centre at ``drive.max_current_a``.
    """
    centres = np.array(design.coil_centres_m())
    n = len(centres)
    if currents is None:
        out = np.zeros(n)
        out[int(np.argmin(np.hypot(centres[:, 0], centres[:, 1])))] = design.drive.max_current_a
        return out
    try:
        arr = np.asarray(currents, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise BadInputError("currents", f"{n} numbers in A (one per coil)", currents) from None
    if arr.size != n:
        raise BadInputError("currents", f"{n} numbers in A (one per coil, row-major)",
                            f"{arr.size} values")
    if not np.all(np.isfinite(arr)):
        raise BadInputError("currents", "finite numbers in A", arr.tolist())
    return arr


def magnet_moment(design: "Design", moment=None) -> np.ndarray:
    """The finger magnet's dipole moment, A m^2, shape (3,): the design's (MagnetSpec.direction)."""
    if moment is None:
        return np.array(design.magnet.moment_vector_a_m2)
    return np.asarray(v.vector3("moment", moment, "A m^2"), dtype=float)


def array_field(design: "Design", points, currents: Sequence[float] | None = None, *,
                gradient: bool = True):
    """Flux density (and gradient) of the design's whole coil array at points.

    :class:`designkit.array.CoilArray` of the whole array (its cores solved together, so the
    unpowered coils' cores count too): the one place where the coils' fields are summed.

    Parameters
    ----------
    design : Design
    points : array-like, shape (n, 3), m
    currents : sequence of float, shape (ncoils,), A, or None (see :func:`resolve_currents`)
    gradient : bool
        Also return ``G[:, i, j] = dB_i/dx_j``.

    Returns
    -------
    B : ndarray, shape (n, 3), T
    G : ndarray, shape (n, 3, 3), T/m (only when gradient=True)
    """
    import warnings

    from .array import array_for_design

    p, _ = v.points(points)
    cur = resolve_currents(design, currents)
    if not np.any(cur):
        b, g = np.zeros((len(p), 3)), np.zeros((len(p), 3, 3))
    else:
        # the whole array, unpowered coils included: their cores are magnetized by the others
        with warnings.catch_warnings():
            # A figure is not the place to repeat the linear-core saturation warning for every
            # grid; `designkit report` states it once in its summary.
            warnings.simplefilter("ignore")
            b, g = array_for_design(design).field(p, cur)
    return (b, g) if gradient else b


def force_from_gradient(gradient_t_per_m: np.ndarray, moment_a_m2: np.ndarray) -> np.ndarray:
    """Force on a point dipole in air, ``F = F(m) G5`` (:func:`designkit.array.force_matrix`),
    N, shape (n, 3), from the gradient (n, 3, 3), T/m."""
    from .array import force_matrix, g5_from_gradient

    return g5_from_gradient(np.asarray(gradient_t_per_m)) @ force_matrix(moment_a_m2).T


def _add_field_arrays(mesh, b, g=None, moment=None):
    mesh.point_data[B_T] = b
    mesh.point_data[B_MT] = np.linalg.norm(b, axis=1) * 1e3
    if g is not None:
        f = force_from_gradient(g, moment)
        mesh.point_data[GRAD_T_M] = g.reshape(-1, 9)
        mesh.point_data[F_N] = f
        mesh.point_data[F_MN] = np.linalg.norm(f, axis=1) * 1e3
        mesh.point_data[FZ_MN] = f[:, 2] * 1e3
    return mesh


def _footprint_half_m(design: "Design") -> float:
    """Half side of a square that covers the coils and the workspace, m."""
    a = design.array
    coils = max(a.rows, a.columns) - 1
    return max(design.workspace.half_width_m, coils * a.pitch_m / 2 + design.coil.outer_radius_m)


def _image(pv, lo, hi, dims):
    dims = tuple(int(d) for d in dims)
    spacing = tuple((h - l) / (d - 1) if d > 1 else 1.0 for l, h, d in zip(lo, hi, dims))
    return pv.ImageData(dimensions=dims, spacing=spacing, origin=tuple(lo))


# ----------------------------------------------------------------------------- data builders
def scene_meshes(design: "Design", currents: Sequence[float] | None = None, *,
                 moment=None, resolution: int = 64) -> "pyvista.MultiBlock":
    """Solids of the device, m: windings (hollow cylinders, cell data ``"current (A)"``), cores,
    the finger magnet (cylinder at the design point) and the workspace box outline."""
    pv = _pv()
    cur = resolve_currents(design, currents)
    c = design.coil
    windings, cores = [], []
    for (x, y, zc), current in zip(design.coil_centres_m(), cur):
        ring = pv.Disc(center=(x, y, zc - c.length_m / 2), inner=c.inner_radius_m,
                       outer=c.outer_radius_m, c_res=resolution)
        w = ring.extrude((0.0, 0.0, c.length_m), capping=True)
        w.cell_data[CURRENT_A] = np.full(w.n_cells, float(current))
        windings.append(w)
        if design.core is not None:
            core = pv.Cylinder(center=(x, y, zc + design.core.offset_m), direction=(0, 0, 1),
                               radius=design.core.radius_m, height=design.core.length_m,
                               resolution=resolution)
            cores.append(core)
    m = magnet_moment(design, moment)
    mag = design.magnet
    axis = m / np.linalg.norm(m) if np.linalg.norm(m) > 0 else np.array([0.0, 0.0, 1.0])
    magnet = pv.Cylinder(center=design.design_point_m, direction=axis, radius=mag.radius_m,
                         height=mag.length_m, resolution=resolution)
    ws = design.workspace
    box = pv.Box(bounds=(-ws.half_width_m, ws.half_width_m, -ws.half_width_m, ws.half_width_m,
                         ws.z_min_m, ws.z_max_m)).extract_all_edges()
    blocks = pv.MultiBlock()
    blocks["windings"] = pv.merge(windings)
    if cores:
        blocks["cores"] = pv.merge(cores)
    blocks["magnet"] = magnet
    blocks["workspace"] = box
    return blocks


def field_line_data(design: "Design", currents: Sequence[float] | None = None, *,
                    quality: Quality = "full"):
    """Streamlines of B from the array.

    Returns
    -------
    volume : pyvista.ImageData
        Grid around the array (coils and workspace), with ``"B (T)"`` and ``"B magnitude (mT)"``.
    lines : pyvista.PolyData
        Streamlines seeded on rings just above the energized coils, with the same arrays.
    """
    pv = _pv()
    res = _quality(quality)
    cur = resolve_currents(design, currents)
    half = _footprint_half_m(design) + 0.02
    zlo = -design.coil.length_m - 0.03
    zhi = design.workspace.z_max_m + 0.03
    vol = _image(pv, (-half, -half, zlo), (half, half, zhi), res["volume"])
    b = array_field(design, vol.points, cur, gradient=False)
    _add_field_arrays(vol, b)
    seeds = []
    nring = 16 if quality == "full" else 10
    for (x, y, _), current in zip(design.coil_centres_m(), cur):
        if current == 0.0:
            continue
        for radius in (0.3, 0.6, 0.9) if quality == "full" else (0.4, 0.8):
            r = radius * design.coil.outer_radius_m
            phi = np.linspace(0, 2 * np.pi, nring, endpoint=False)
            seeds.append(np.c_[x + r * np.cos(phi), y + r * np.sin(phi),
                               np.full(nring, 0.004)])
    if not seeds:
        return vol, pv.PolyData()
    source = pv.PolyData(np.vstack(seeds))
    lines = vol.streamlines_from_source(source, vectors=B_T, integration_direction="both",
                                        max_steps=4000, initial_step_length=0.2,
                                        terminal_speed=1e-9, compute_vorticity=False)
    return vol, lines


def slice_data(design: "Design", currents: Sequence[float] | None = None, *,
               moment=None, height_m: float | None = None, quality: Quality = "full"):
    """|B| and the force on the magnet on a vertical (y = 0) and a horizontal slice.

    The vertical slice spans the array's footprint in x and z from 2 mm above the coil tops to
    the top of the workspace; the horizontal one is at ``height_m`` (default: the design height).

    Returns
    -------
    vertical, horizontal : pyvista.ImageData
        Flat grids with ``"B (T)"``, ``"B magnitude (mT)"``, ``"grad B (T/m)"``, ``"F (N)"``,
        ``"F magnitude (mN)"`` and ``"Fz (mN)"``.
    """
    pv = _pv()
    res = _quality(quality)
    cur = resolve_currents(design, currents)
    m = magnet_moment(design, moment)
    h = design.optimize.height_m if height_m is None else v.positive("height_m", height_m)
    half = _footprint_half_m(design)
    nx, nz = res["slice"]
    vert = _image(pv, (-half, 0.0, 0.002), (half, 0.0, design.workspace.z_max_m), (nx, 1, nz))
    horiz = _image(pv, (-half, -half, h), (half, half, h), (nx, nx, 1))
    for mesh in (vert, horiz):
        b, g = array_field(design, mesh.points, cur, gradient=True)
        _add_field_arrays(mesh, b, g, m)
        mesh.point_data[IN_SOLID] = inside_solids(design, mesh.points).astype(np.uint8)
    return vert, horiz


def force_map_data(design: "Design", currents: Sequence[float] | None = None, *,
                   moment=None, height_m: float | None = None, quality: Quality = "full"):
    """Force on the magnet at the nodes of a square grid over the workspace at one height.

    Returns
    -------
    pyvista.PolyData
        Points (m) with ``"F (N)"``, ``"F magnitude (mN)"``, ``"Fz (mN)"``, ``"B (T)"``, ``"B magnitude (mT)"``.
    """
    pv = _pv()
    res = _quality(quality)
    cur = resolve_currents(design, currents)
    m = magnet_moment(design, moment)
    h = design.optimize.height_m if height_m is None else v.positive("height_m", height_m)
    hw = design.workspace.half_width_m
    n = res["map"]
    xs = np.linspace(-hw, hw, n)
    xx, yy = np.meshgrid(xs, xs, indexing="ij")
    pts = np.c_[xx.ravel(), yy.ravel(), np.full(xx.size, h)]
    cloud = pv.PolyData(pts)
    b, g = array_field(design, pts, cur, gradient=True)
    _add_field_arrays(cloud, b, g, m)
    return cloud


def _reach_height_m(design, cur, m, level_n) -> float:
    """Height above which |Fz| on the energized coils' axes stays below ``level_n``, m."""
    zs = np.linspace(design.workspace.z_min_m, 0.5, 120)
    best = design.workspace.z_max_m
    for (x, y, _), current in zip(design.coil_centres_m(), cur):
        if current == 0.0:
            continue
        _, g = array_field(design, np.c_[np.full_like(zs, x), np.full_like(zs, y), zs], cur)
        fz = np.abs(force_from_gradient(g, m)[:, 2])
        above = np.nonzero(fz >= level_n)[0]
        if above.size:
            best = max(best, zs[above[-1]])
    return float(min(best * 1.25, 0.5))


def force_isosurface_data(design: "Design", currents: Sequence[float] | None = None, *,
                          moment=None, level_n: float | None = None, quality: Quality = "full"):
    """Surfaces where the vertical force on the magnet equals +level and -level.

    The level defaults to the human detection threshold ``render.threshold_n`` (0.8 mN). The
    grid covers the workspace footprint from ``workspace.z_min_m`` up to where |Fz| on the axes of
    the energized coils falls below the level (at least the workspace top, at most 0.5 m): with
    the design's full current the threshold surface lies far above the workspace, and that reach
    is what the figure is for.

    Returns
    -------
    volume : pyvista.ImageData
        With ``"Fz (mN)"``, ``"F (N)"``, ``"F magnitude (mN)"``, ``"B (T)"``, ``"B magnitude (mT)"``.
    surface : pyvista.PolyData
        Contours at ``Fz = +level`` and ``-level`` with point data ``"Fz (mN)"`` (the level).
    level_n : float
        The level, N.
    """
    pv = _pv()
    res = _quality(quality)
    cur = resolve_currents(design, currents)
    m = magnet_moment(design, moment)
    level = design.render.threshold_n if level_n is None else v.positive("level_n", level_n, "N")
    reach = _reach_height_m(design, cur, m, level)
    # a box sized to the array (twice its footprint, at most 4 footprints high), not to the
    # reach of the surfaces (up to 0.5 m): the array would be a speck; the plot states the cut
    foot = _footprint_half_m(design)
    half = 2.0 * foot
    top = max(min(reach, 4.0 * foot), design.workspace.z_max_m)
    vol = _image(pv, (-half, -half, design.workspace.z_min_m), (half, half, top), res["iso"])
    b, g = array_field(design, vol.points, cur, gradient=True)
    _add_field_arrays(vol, b, g, m)
    vol.field_data[REACH_M] = [reach / 1.25]
    surface = vol.contour([-level * 1e3, level * 1e3], scalars=FZ_MN)
    return vol, surface, level


# ----------------------------------------------------------------------------- plotting helpers
def _plotter(pv, window_size, shape=(1, 1)):
    p = pv.Plotter(off_screen=True, window_size=_window(window_size), shape=shape)
    p.set_background("white")
    return p


def _mm(mesh):
    """A copy of the mesh with its points in millimetres (data arrays untouched)."""
    out = mesh.cast_to_structured_grid() if hasattr(mesh, "spacing") else mesh.copy()
    out.points = np.asarray(out.points) * 1e3
    return out


def _bar(title, **extra):
    args = dict(title=title, color="black", vertical=True, position_x=0.87, position_y=0.2,
                width=0.05, height=0.6, title_font_size=14, label_font_size=12, fmt="%.3g",
                n_labels=5)
    args.update(extra)
    return args


def _title(p, text, font_size=12):
    """Title at the upper left, each line wrapped to the width of its (sub)plot."""
    import textwrap

    width = p.window_size[0] / p.shape[1]
    # VTK's default font: a character is about 0.6 font sizes wide, in pixels
    chars = max(20, int(0.92 * width / (0.6 * font_size)))
    lines = [w for line in text.split("\n") for w in (textwrap.wrap(line, chars) or [""])]
    p.add_text("\n".join(lines), position="upper_left", font_size=font_size, color="black")


def _vtk_tick_spacing(span: float) -> float:
    """The major tick spacing ``vtkCubeAxesActor`` picks for an axis of this span (it labels
    ``vmin + k * spacing`` whatever label count it is asked for, once that count reaches its
    own; pyvista's ``_axis_label_values`` mirrors the same rule)."""
    power = math.log10(span)
    if power != 0.0:
        power = math.copysign(abs(power) + 10.0e-10, power)
    if power < 0.0:
        power -= 1.0
    decade = 10.0 ** float(int(power))
    ticks = int(span / decade) + 1
    return decade / (5.0 if ticks <= 2 else 2.0 if ticks < 5 else 1.0)


def nice_ticks(lo: float, hi: float, target: int = 5) -> tuple[float, float, float]:
    """``(lo', hi', step)``: the range widened so that the axis VTK draws over it is labelled
    on round values: ``lo'`` a multiple of ``step``, ``step`` VTK's own tick spacing for the
    widened span (a 1, 2 or 5 x 10^k), 3 to 11 labels; of those, the least widening (then the
    label count nearest ``target`` + 1)."""
    span = hi - lo
    if not (span > 0 and math.isfinite(span)):
        return lo - 1.0, hi + 1.0, 1.0
    k = 10.0 ** math.floor(math.log10(span))
    best = None
    for base in (0.05, 0.1, 0.2, 0.25, 0.5, 1.0, 2.0, 2.5, 5.0):
        step = base * k
        a = math.floor(lo / step + 1e-9) * step
        b = math.ceil(hi / step - 1e-9) * step
        major = _vtk_tick_spacing(b - a)
        if abs(a / major - round(a / major)) > 1e-9:
            continue  # VTK would label a + j * major: not round
        a, b = round(a / major) * major, b  # exact multiples, no 1e-17 residues in the labels
        n = math.floor((b - a) / major + 1e-9)
        if 2 <= n <= 10:
            key = ((b - a) / span, abs(n - target))
            if best is None or key < best[0]:
                best = (key, (a, b, major))
    return best[1] if best else (lo, hi, span / target)


def _nice_bounds(bounds) -> tuple[list[float], dict]:
    b = list(map(float, bounds))
    counts = {}
    for i, axis in enumerate("xyz"):
        lo, hi, step = nice_ticks(b[2 * i], b[2 * i + 1])
        b[2 * i], b[2 * i + 1] = lo, hi
        # at least VTK's own count: it then labels lo + k * step (see _vtk_tick_spacing)
        counts[f"n_{axis}labels"] = int(math.floor((hi - lo) / step + 1e-9)) + 1
    return b, counts


def _axes(p, mesh_bounds=None, location="outer", **kw):
    """Axes in mm on round tick values (the bounds are widened to the nearest round ticks)."""
    b, counts = _nice_bounds(p.bounds if mesh_bounds is None else mesh_bounds)
    p.show_bounds(bounds=b, xtitle="x (mm)", ytitle="y (mm)", ztitle="z (mm)",
                  color="black", font_size=10, grid=False, location=location, ticks="outside",
                  minor_ticks=False, fmt="%g", **counts, **kw)
    return b


def _fit_camera(p, bounds_mm, elevation_deg=25.0, azimuth_deg=-58.0, margin=1.22):
    """Look at the box from (elevation, azimuth) from just far enough that its bounding sphere,
    widened by ``margin`` for the axis labels, fits the view: nothing is cut at the edges."""
    b = np.asarray(bounds_mm, dtype=float)
    every = np.asarray(p.bounds, dtype=float)  # every actor, e.g. coils below the axes box
    b[0::2], b[1::2] = np.minimum(b[0::2], every[0::2]), np.maximum(b[1::2], every[1::2])
    centre = (b[0::2] + b[1::2]) / 2
    radius = 0.5 * float(np.linalg.norm(b[1::2] - b[0::2]))
    half_angle = math.radians(p.camera.view_angle / 2)
    _iso_camera(p, tuple(centre), margin * radius / math.sin(half_angle), elevation_deg,
                azimuth_deg)


def _add_device(p, design, blocks, *, opacity=1.0, magnet=True, workspace=True):
    p.add_mesh(_mm(blocks["windings"]), color=_COPPER, opacity=opacity, smooth_shading=True,
               name="windings")
    if "cores" in blocks.keys():
        p.add_mesh(_mm(blocks["cores"]), color=_STEEL, opacity=opacity, name="cores")
    if magnet:
        p.add_mesh(_mm(blocks["magnet"]), color=_MAGNET, name="magnet")
    if workspace:
        p.add_mesh(_mm(blocks["workspace"]), color="#1f4e9c", line_width=1.5, name="workspace")


def _currents_text(cur) -> str:
    nz = [(i, c) for i, c in enumerate(cur) if c != 0.0]
    if not nz:
        return "all coils at 0 A"
    if len(nz) <= 3:
        return ", ".join(f"coil {i + 1} at {c:+.3g} A" for i, c in nz) + ", others 0 A" * (
            len(nz) < len(cur))
    return "I = [" + ", ".join(f"{c:+.2g}" for c in cur) + "] A"


def _log_fmt(lo: float, hi: float) -> str:
    if lo >= 1.0:
        return "%.0f"
    return "%.2g" if hi < 100 else "%.3g"


def _iso_camera(p, focus_mm, distance_mm, elevation_deg=28.0, azimuth_deg=-58.0):
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    d = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    pos = np.asarray(focus_mm) + distance_mm * d
    p.camera_position = [tuple(pos), tuple(focus_mm), (0.0, 0.0, 1.0)]


def _magnet_text(design, moment) -> str:
    m = magnet_moment(design, moment)
    direction = "+z" if np.allclose(m[:2], 0) and m[2] > 0 else (
        "-z" if np.allclose(m[:2], 0) else "(" + ", ".join(f"{x:.2g}" for x in m) + ")")
    return f"m = {np.linalg.norm(m):.3g} A m^2 along {direction}"


# ----------------------------------------------------------------------------- figures
def plot_array_scene(design: "Design", currents: Sequence[float] | None = None, *,
                     moment=None, window_size=(1024, 768), blocks=None) -> "pyvista.Plotter":
    """The coil array (windings coloured by current, cores), the magnet with its moment as an
    arrow at the design point, and the workspace box. Off-screen; never shown."""
    pv = _pv()
    cur = resolve_currents(design, currents)
    blocks = scene_meshes(design, cur, moment=moment) if blocks is None else blocks
    m = magnet_moment(design, moment)
    p = _plotter(pv, window_size)
    imax = float(np.max(np.abs(cur))) or 1.0
    p.add_mesh(_mm(blocks["windings"]), scalars=CURRENT_A, cmap="coolwarm", clim=(-imax, imax),
               smooth_shading=True, name="windings",
               scalar_bar_args=_bar("coil current (A)", fmt="%+.2g"))
    if "cores" in blocks.keys():
        p.add_mesh(_mm(blocks["cores"]), color=_STEEL, name="cores")
    p.add_mesh(_mm(blocks["magnet"]), color=_MAGNET, name="magnet")
    p.add_mesh(_mm(blocks["workspace"]), color="#1f4e9c", line_width=2, name="workspace")
    dp = np.asarray(design.design_point_m) * 1e3
    mdir = m / (np.linalg.norm(m) or 1.0)
    arrow = pv.Arrow(start=dp, direction=mdir, scale=30.0, tip_length=0.3, tip_radius=0.12,
                     shaft_radius=0.05)
    p.add_mesh(arrow, color="black", name="moment")
    p.add_point_labels([dp + mdir * 30.0 + np.array([8.0, 0.0, 0.0])], ["magnet moment m"],
                       font_size=12, text_color="black", shape=None, show_points=False,
                       always_visible=True)
    ws = design.workspace
    p.add_point_labels([(ws.half_width_m * 1e3, ws.half_width_m * 1e3, ws.z_max_m * 1e3)],
                       ["workspace"], font_size=12, text_color="#1f4e9c", shape=None,
                       show_points=False, always_visible=True)
    c = design.coil
    _title(p, f"{design.name}: {design.array.rows} x {design.array.columns} coils, pitch "
              f"{design.array.pitch_m * 1e3:.0f} mm; winding Ri/Ro/L = "
              f"{c.inner_radius_m * 1e3:.0f}/{c.outer_radius_m * 1e3:.0f}/"
              f"{c.length_m * 1e3:.0f} mm, {c.turns} turns\n"
              f"magnet ({_magnet_text(design, moment)}) at the design point "
              f"z = {design.optimize.height_m * 1e3:.0f} mm; {_currents_text(cur)}",
           font_size=10)
    _fit_camera(p, _axes(p), elevation_deg=22.0)
    return p


def plot_field_lines(design: "Design", currents: Sequence[float] | None = None, *,
                     quality: Quality = "full", window_size=(1024, 768), data=None,
                     blocks=None) -> "pyvista.Plotter":
    """Streamlines of B coloured by the magnitude of B (mT, log scale) over the coil array."""
    pv = _pv()
    cur = resolve_currents(design, currents)
    vol, lines = field_line_data(design, cur, quality=quality) if data is None else data
    blocks = scene_meshes(design, cur) if blocks is None else blocks
    p = _plotter(pv, window_size)
    _add_device(p, design, blocks, opacity=0.3, magnet=True, workspace=True)
    clip_note = ""
    if lines.n_points:
        bmt = np.asarray(lines[B_MT])
        # the data range, as in the slices; a floor 4 decades down is the only clip, stated
        hi = max(float(bmt.max()), 1e-6)
        lo = max(float(bmt.min()), 1e-6)
        if lo < hi * 1e-4:
            lo = hi * 1e-4
            clip_note = f"; colours below {lo:.2g} mT clipped"
        p.add_mesh(_mm(lines).tube(radius=0.7), scalars=B_MT, cmap="viridis", log_scale=True,
                   clim=(lo, hi), name="streamlines",
                   scalar_bar_args=_bar("B (mT)", fmt=_log_fmt(lo, hi)))
    else:
        p.add_text("no field: all coils at 0 A", position="lower_left", color="black")
    p.add_mesh(_mm(vol.outline()), color="grey", line_width=1)
    _title(p, f"Field lines of B, coloured by its magnitude (log scale)\n{_currents_text(cur)}; "
              f"lines end at the edge of the computed box{clip_note}", font_size=11)
    _fit_camera(p, _axes(p), elevation_deg=12.0)
    return p


def _section_lines(pv, design, blocks, view: Literal["xz", "xy"], height_m, z_low_m):
    """Outlines of the coils in the slice views, mm."""
    if view == "xz":
        cut = blocks["windings"].slice(normal="y", origin=(0, 0, 0))
        if "cores" in blocks.keys():
            cut = cut.merge(blocks["cores"].slice(normal="y", origin=(0, 0, 0)))
        cut = cut.clip(normal=(0, 0, 1), origin=(0, 0, z_low_m), invert=False)
        return _mm(cut)
    circles = []
    for x, y, _ in design.coil_centres_m():
        for r in (design.coil.inner_radius_m, design.coil.outer_radius_m):
            circles.append(pv.Circle(radius=r, resolution=72)
                           .translate((x, y, height_m + 1e-4)).extract_feature_edges())
    return _mm(pv.merge(circles))


def inside_solids(design: "Design", points) -> np.ndarray:
    """Boolean mask (n,): the points (m) that lie inside a core or a winding of the array."""
    p, _ = v.points(points)
    c = design.coil
    inside = np.zeros(len(p), dtype=bool)
    for x, y, zc in design.coil_centres_m():
        rho = np.hypot(p[:, 0] - x, p[:, 1] - y)
        dz = p[:, 2] - zc
        inside |= (rho >= c.inner_radius_m) & (rho <= c.outer_radius_m) & \
            (np.abs(dz) <= c.length_m / 2)
        if design.core is not None:
            k = design.core
            inside |= (rho <= k.radius_m) & (np.abs(dz - k.offset_m) <= k.length_m / 2)
    return inside


def _drop_solids(mesh):
    """The slice without the cells that touch a point inside a solid (a structured grid)."""
    solid = np.asarray(mesh[IN_SOLID], dtype=bool) if IN_SOLID in mesh.point_data.keys() \
        else np.zeros(mesh.n_points, dtype=bool)
    if not solid.any():
        return mesh
    return mesh.extract_points(~solid, adjacent_cells=False)


def plot_slices(design: "Design", currents: Sequence[float] | None = None, *,
                quantity: Literal["B", "F"] = "B", moment=None, height_m: float | None = None,
                quality: Quality = "full", window_size=(1500, 640), data=None,
                blocks=None) -> "pyvista.Plotter":
    """Magnitude of B (mT) or of the force on the magnet (mN) on the vertical slice y = 0 (left)
    and on a horizontal slice at the design height (right); one log colour scale shared by both,
    the coils' outlines and, for the force, the contour of the human threshold (0.8 mN)."""
    pv = _pv()
    if quantity not in ("B", "F"):
        raise BadInputError("quantity", "'B' or 'F'", quantity)
    cur = resolve_currents(design, currents)
    h = design.optimize.height_m if height_m is None else height_m
    vert, horiz = (slice_data(design, cur, moment=moment, height_m=h, quality=quality)
                   if data is None else data)
    blocks = scene_meshes(design, cur) if blocks is None else blocks
    name = B_MT if quantity == "B" else F_MN
    # points inside a core or a winding are not in air: they are left out of the picture
    vert, horiz = (_drop_solids(mesh) for mesh in (vert, horiz))
    values = np.r_[np.asarray(vert[name]), np.asarray(horiz[name])]
    # the colour range is the data range (log scale: the near-singular values over a core's
    # rim stay visible); only a floor 4 decades down is clipped, and then the title says so
    hi = float(values.max()) if values.size else 1.0
    hi = hi if hi > 0 else 1.0
    lo = max(float(values.min()), 1e-9)
    clip_note = ""
    if lo < hi * 1e-4:
        lo = hi * 1e-4
        clip_note = f"; colours below {lo:.2g} {'mT' if quantity == 'B' else 'mN'} clipped"
    label = "B (mT)" if quantity == "B" else "F (mN)"
    threshold_mn = design.render.threshold_n * 1e3
    z_low_m = -0.25 * design.coil.length_m  # show the top quarter of the coils
    head = ("Magnitude of B" if quantity == "B"
            else f"Magnitude of the force on the magnet ({_magnet_text(design, moment)})")
    p = _plotter(pv, window_size, shape=(1, 2))
    for col, (mesh, view) in enumerate(((vert, "xz"), (horiz, "xy"))):
        p.subplot(0, col)
        mm = _mm(mesh)
        p.add_mesh(mm, scalars=name, cmap="inferno", log_scale=True, clim=(lo, hi),
                   name=f"slice-{view}", show_scalar_bar=(col == 1),
                   scalar_bar_args=_bar(label, fmt=_log_fmt(lo, hi), position_x=0.88,
                                        width=0.045))
        notes = [_currents_text(cur), "cyan dot: design point" + clip_note]
        if quantity == "F" and lo < threshold_mn < hi:
            iso = mm.contour([threshold_mn], scalars=name)
            if iso.n_points:
                p.add_mesh(iso, color="cyan", line_width=3, name=f"threshold-{view}")
                notes.append(f"cyan line: {threshold_mn:g} mN")
        p.add_mesh(_section_lines(pv, design, blocks, view, h, z_low_m), color="black",
                   line_width=2)
        dp = np.asarray(design.design_point_m) * 1e3
        dot = dp + ((0.0, -1.0, 0.0) if view == "xz" else (0.0, 0.0, 0.5))
        p.add_mesh(pv.PolyData(dot[None, :]), color="cyan", point_size=12,
                   render_points_as_spheres=True)
        bounds = list(mm.bounds)
        if view == "xz":
            where = "vertical slice y = 0 (coils in outline below; blank: inside iron)"
            bounds[4] = z_low_m * 1e3
            p.view_xz()
        else:
            where = f"horizontal slice z = {h * 1e3:.0f} mm"
            p.view_xy()
        _title(p, f"{head}\n{where}\n" + "; ".join(notes), font_size=10)
        bounds, counts = _nice_bounds(bounds)
        p.show_bounds(bounds=bounds, xtitle="x (mm)", ytitle="y (mm)", ztitle="z (mm)",
                      color="black", font_size=9, grid=False, location="front",
                      ticks="outside", show_yaxis=(view == "xy"), show_zaxis=(view == "xz"),
                      fmt="%g", **counts)
        p.enable_parallel_projection()
        p.reset_camera(bounds=bounds)
        p.camera.zoom(0.95 if view == "xz" else 0.9)  # room for the axis titles
        if view == "xy":
            # leave room for the colour bar on the right
            p.camera.position = tuple(np.asarray(p.camera.position) + (12.0, 0.0, 0.0))
            p.camera.focal_point = tuple(np.asarray(p.camera.focal_point) + (12.0, 0.0, 0.0))
    return p


def plot_force_map(design: "Design", currents: Sequence[float] | None = None, *,
                   moment=None, height_m: float | None = None, quality: Quality = "full",
                   window_size=(1024, 768), data=None, blocks=None) -> "pyvista.Plotter":
    """Arrows of the force on the magnet over a grid at one height, coloured by its magnitude
    (mN, log scale); arrow length grows as the square root of the magnitude."""
    pv = _pv()
    cur = resolve_currents(design, currents)
    h = design.optimize.height_m if height_m is None else height_m
    cloud = (force_map_data(design, cur, moment=moment, height_m=h, quality=quality)
             if data is None else data)
    blocks = scene_meshes(design, cur) if blocks is None else blocks
    p = _plotter(pv, window_size)
    # see-through coils: opaque ones hide the arrows behind them in the oblique view
    _add_device(p, design, blocks, opacity=0.25, magnet=False, workspace=True)
    f = np.asarray(cloud[F_N])
    fmag = np.linalg.norm(f, axis=1)
    fmax = float(fmag.max()) if fmag.size else 0.0
    n = int(round(math.sqrt(cloud.n_points))) or 1
    spacing_mm = 2e3 * design.workspace.half_width_m / max(n - 1, 1)
    mm = _mm(cloud)
    if fmax > 0:
        # Length ~ sqrt(|F|): the force over a core is orders of magnitude above that at the
        # workspace's edge; a linear scale would show one arrow and dots.
        unit = f / np.where(fmag > 0, fmag, 1.0)[:, None]
        # at least MIN_ARROW of the spacing, so that the weak-force arrows stay visible
        mm["arrow"] = unit * np.maximum(np.sqrt(fmag / fmax), MIN_ARROW)[:, None]
        glyphs = mm.glyph(orient="arrow", scale="arrow", factor=0.95 * spacing_mm,
                          geom=pv.Arrow(tip_length=0.35, tip_radius=0.15, shaft_radius=0.05))
        lo = max(fmax * 1e-3, float(fmag.min()) * 1e3, 1e-9)
        p.add_mesh(glyphs, scalars=F_MN, cmap="plasma", log_scale=True,
                   clim=(lo, fmax * 1e3), name="force-arrows",
                   scalar_bar_args=_bar("F (mN)", fmt=_log_fmt(lo, fmax * 1e3)))
    plane = pv.Plane(center=(0, 0, h * 1e3), i_size=2e3 * design.workspace.half_width_m,
                     j_size=2e3 * design.workspace.half_width_m)
    p.add_mesh(plane, color="#dddddd", opacity=0.25)
    _title(p, f"Force on the magnet ({_magnet_text(design, moment)}) at z = {h * 1e3:.0f} mm\n"
              f"largest: {fmax * 1e3:.4g} mN; {_currents_text(cur)}\n"
              f"arrow length ~ square root of the force (at least {MIN_ARROW:g} of the "
              f"largest)", font_size=11)
    _fit_camera(p, _axes(p), elevation_deg=50.0)
    return p


def plot_force_isosurface(design: "Design", currents: Sequence[float] | None = None, *,
                          moment=None, level_n: float | None = None, quality: Quality = "full",
                          window_size=(1024, 768), data=None, blocks=None) -> "pyvista.Plotter":
    """Surfaces Fz = +level (push, red) and Fz = -level (pull, blue) above the array; level
    defaults to the human threshold 0.8 mN."""
    pv = _pv()
    cur = resolve_currents(design, currents)
    vol, surface, level = (force_isosurface_data(design, cur, moment=moment, level_n=level_n,
                                                 quality=quality) if data is None else data)
    blocks = scene_meshes(design, cur) if blocks is None else blocks
    p = _plotter(pv, window_size)
    _add_device(p, design, blocks, opacity=1.0, magnet=True, workspace=True)
    lmn = level * 1e3
    if surface.n_points:
        p.add_mesh(_mm(surface), scalars=FZ_MN, cmap=["#2166ac", "#b2182b"], clim=(-lmn, lmn),
                   opacity=0.5, smooth_shading=True, name="isosurface",
                   scalar_bar_args=_bar("Fz (mN)", n_labels=2, fmt="%+.2g"))
    else:
        p.add_text(f"the vertical force stays below {lmn:g} mN everywhere in the box",
                   position="lower_left", color="black", font_size=11)
    p.add_mesh(_mm(vol.outline()), color="grey", line_width=1)
    b = np.asarray(vol.bounds) * 1e3
    reach = (f"; on the coil axes the vertical force passes {lmn:g} mN up to z = "
             f"{float(vol.field_data[REACH_M][0]) * 1e3:.0f} mm" if REACH_M in vol.field_data
             else "")
    _title(p, f"Where the magnet ({_magnet_text(design, moment)}) feels Fz = +{lmn:g} mN "
              f"(red, push up) and -{lmn:g} mN (blue, pull down); {_currents_text(cur)}\n"
              f"the force is larger between the surfaces and the coils{reach}\n"
              f"surfaces cut flat by the grey box: at z = {b[4]:.0f} mm (bottom of the "
              f"workspace), z = {b[5]:.0f} mm and x, y = +-{b[1]:.0f} mm", font_size=10)
    _fit_camera(p, _axes(p, b), elevation_deg=16.0, margin=1.12)
    return p


# ----------------------------------------------------------------------------- output
def save_png(plotter: "pyvista.Plotter", path: str | Path) -> Path:
    """Render the plotter off-screen and write a PNG atomically; returns the path."""
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise BadInputError("path", "a file name ending in .png", str(path))
    _clear_bar_titles(plotter)
    with atomic_path(path, suffix=".png") as tmp:
        plotter.screenshot(str(tmp))
    return path


def bar_label_values(lo: float, hi: float, log: bool) -> list[float]:
    """Round label values for a colour bar over [lo, hi]: 1, 2, 5 x 10^k on a log bar (fewer
    per decade when the range spans many), the ticks of :func:`nice_ticks` inside the range on
    a linear one."""
    if not (hi > lo):
        return [lo]
    if log and lo > 0:
        for mants in ((1, 2, 5), (1, 3), (1,)):
            vals = [m * 10.0 ** e for e in range(math.floor(math.log10(lo)),
                                                math.ceil(math.log10(hi)) + 1) for m in mants]
            vals = [x for x in vals if lo * (1 - 1e-9) <= x <= hi * (1 + 1e-9)]  # lo > 0 here
            if len(vals) <= 7:
                break
        return vals if len(vals) >= 2 else [lo, hi]
    a, b, step = nice_ticks(lo, hi)
    vals = [a + k * step for k in range(int(round((b - a) / step)) + 1)]
    return [x for x in vals if lo - 1e-9 * step <= x <= hi + 1e-9 * step]


def _clear_bar_titles(plotter) -> None:
    """Colour bars on round label values (:func:`bar_label_values`), their title lifted above
    the top label (VTK draws them overlapping)."""
    from vtkmodules.vtkCommonCore import vtkDoubleArray

    for bar in plotter.scalar_bars.values():
        size = bar.GetLabelTextProperty().GetFontSize()
        bar.SetVerticalTitleSeparation(max(int(size), 12))
        lut = bar.GetLookupTable()
        if lut is None or bar.GetNumberOfLabels() <= 2:
            continue  # two labels are the range's ends, e.g. -0.8 / +0.8 mN: round already
        lo, hi = lut.GetRange()
        labels = vtkDoubleArray()
        for x in bar_label_values(lo, hi, bool(lut.GetScale())):
            labels.InsertNextValue(x)
        bar.SetUseCustomLabels(True)
        bar.SetCustomLabels(labels)
        bar.SetLabelFormat("%g")


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
    _pv()
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
                not isinstance(mesh, _pv().PolyData):
            mesh = mesh.extract_surface()
        written[name] = _write_vtk(mesh, out / name)
    return written
