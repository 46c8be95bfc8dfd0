"""Regression tests of what was fixed in the figures: nothing cut at the canvas edges, round
tick values, colour-bar titles clear of the ticks, slice colours over the data range with
solids left out, visible force arrows, an isosurface box sized to the array with its cuts
stated."""

from __future__ import annotations

import math

import numpy as np
import pytest
import pyvista as pv  # noqa: F401  (a required dependency)
from matplotlib.image import imread

from designkit import default_design, viz

DESIGN = default_design()
SIZE = {"slice-B": (960, 420), "slice-F": (960, 420)}


def _texts(plotter) -> str:
    out = []
    for renderer in plotter.renderers:
        for actor in renderer.actors.values():
            if hasattr(actor, "GetText"):
                for i in range(8):
                    try:
                        out.append(actor.GetText(i) or "")
                    except TypeError:
                        out.append(actor.GetText() or "")
                        break
            elif hasattr(actor, "GetInput") and isinstance(actor.GetInput(), str):
                out.append(actor.GetInput())
    return "\n".join(out)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    out = tmp_path_factory.mktemp("figures")
    figs = {}
    for kind in viz.KINDS:
        p = viz.render(kind, DESIGN, quality="quick", window_size=SIZE.get(kind, (640, 480)))
        path = viz.save_png(p, out / f"{kind}.png")
        figs[kind] = (p, imread(path))
    yield figs
    for p, _ in figs.values():
        p.close()


@pytest.mark.parametrize("kind", viz.KINDS)
def test_nothing_is_cut_at_the_canvas_edges(rendered, kind):
    _, img = rendered[kind]
    rgb = img[..., :3]
    h, w = rgb.shape[:2]
    frame = np.ones((h, w), dtype=bool)
    frame[2:-2, 2:-2] = False
    if kind.startswith("slice"):  # the separator line between the two panels
        frame[:, w // 2 - 3:w // 2 + 3] = False
    if kind == "scene":  # its panels: 3 : 2
        frame[:, 3 * w // 5 - 3:3 * w // 5 + 3] = False
    # the background is white: any dark pixel on the outer frame is a label or a mesh cut off
    assert rgb[frame].min() > 0.9, f"{kind}: drawing reaches the edge of the image"


def _round_step(step: float) -> bool:
    mant = step / 10 ** math.floor(math.log10(step))
    return min(abs(mant - m) for m in (1, 2, 2.5, 5, 10)) < 1e-6


@pytest.mark.parametrize("lo,hi", [(-75, 75), (-105, 80), (10, 490), (0.002, 0.0731),
                                   (-3e-4, 7e-4), (33.7, 385.2)])
def test_nice_ticks_are_round_and_cover_the_range(lo, hi):
    a, b, step = viz.nice_ticks(lo, hi)
    assert a <= lo and b >= hi and _round_step(step)
    n = math.floor((b - a) / step + 1e-9)
    assert 2 <= n <= 10
    for t in a + step * np.arange(n + 1):
        assert abs(t / step - round(t / step)) < 1e-6  # every tick is a multiple of the step


def test_random_ranges_get_round_ticks():
    rng = np.random.default_rng(7)
    for _ in range(200):
        lo = rng.normal() * 10 ** rng.uniform(-3, 3)
        hi = lo + 10 ** rng.uniform(-3, 3)
        a, b, step = viz.nice_ticks(lo, hi)
        assert a <= lo and b >= hi and (b - a) <= 5 * (hi - lo)
        assert abs(a / step - round(a / step)) < 1e-6


@pytest.mark.parametrize("kind", ["scene", "fieldlines", "forcemap", "isosurface", "slice-B"])
def test_axis_labels_are_round_values(rendered, kind):
    """The labels VTK actually draws (it overrides the requested count with its own ticks)."""
    p, _ = rendered[kind]
    for renderer in p.renderers:
        cube = renderer.cube_axes_actor
        if cube is None:
            continue
        for i in range(3):
            labels = cube.GetAxisLabels(i)
            vals = [labels.GetValue(j) for j in range(labels.GetNumberOfValues())]
            vals = [float(v) for v in vals if v.strip()]
            if len(vals) < 2:
                continue
            step = vals[1] - vals[0]
            assert _round_step(abs(step)), (kind, i, vals)
            assert np.allclose(np.diff(vals), step), (kind, i, vals)
            assert all(abs(v / step - round(v / step)) < 1e-6 for v in vals), (kind, i, vals)


@pytest.mark.parametrize("kind", viz.KINDS)
def test_colour_bar_titles_are_lifted_clear_of_the_top_tick(rendered, kind):
    p, _ = rendered[kind]
    for bar in p.scalar_bars.values():
        assert bar.GetVerticalTitleSeparation() >= bar.GetLabelTextProperty().GetFontSize()


@pytest.mark.parametrize("kind", viz.KINDS)
def test_colour_bar_labels_are_round_values_inside_the_range(rendered, kind):
    p, _ = rendered[kind]
    for bar in p.scalar_bars.values():
        lo, hi = bar.GetLookupTable().GetRange()
        if bar.GetNumberOfLabels() <= 2:
            continue
        assert bar.GetUseCustomLabels()
        labels = bar.GetCustomLabels()
        vals = [labels.GetValue(i) for i in range(labels.GetNumberOfValues())]
        assert 2 <= len(vals) <= 7
        for x in vals:
            tol = 1e-9 * (hi - lo)
            assert lo - tol <= x <= hi + tol
            if x != 0:
                mant = abs(x) / 10 ** math.floor(math.log10(abs(x)))
                assert min(abs(mant - m) for m in (1, 2, 3, 4, 5, 6, 8, 10)) < 1e-6, vals


@pytest.mark.parametrize("quantity", ["B", "F"])
def test_slice_colours_are_the_designs_range_and_leave_out_solids(quantity):
    vert, horiz = viz.slice_data(DESIGN, quality="quick")
    inside = viz.inside_solids(DESIGN, vert.points)
    # the cores and the windings' tops reach into the vertical section through the design point
    assert inside.any() and np.all(np.asarray(vert[viz.IN_SOLID], bool) == inside)
    # the air between the coils is drawn down to the section's bottom (it used to be left
    # blank below 2 mm as if it were iron)
    air_low = ~inside & (np.asarray(vert.points)[:, 2] < 0.0)
    assert air_low.sum() > 20
    p = viz.plot_slices(DESIGN, quantity=quantity, data=(vert, horiz), window_size=(640, 300))
    try:
        ranges = viz.colour_ranges(DESIGN)
        for view in ("xz", "xy"):
            actor = next(a for r in p.renderers for k, a in r.actors.items()
                         if k == f"slice-{view}")
            shown = actor.mapper.dataset
            # no point inside a core or a winding is drawn as field in air: the section is cut
            # along the solids' surfaces, where the signed distance interpolated along a cell's
            # edge vanishes (exact on a wall; across a solid's corner the distance bends, and
            # the cut lies within half a cell of it), not cell by cell
            world = np.asarray(shown.points) * 1e-3
            if view == "xz":
                back = np.linalg.inv(viz.section_plane(DESIGN).to_plane())
                world = (np.c_[world, np.ones(len(world))] @ back.T)[:, :3]
            grid = np.asarray(vert.points) if view == "xz" else np.asarray(horiz.points)
            cell = max(np.ptp(grid, axis=0)) / (viz.common.GRID_POINTS["quick"]["slice"][1] - 1)
            d = viz.solid_distance_m(DESIGN, world)
            assert d.min() > -0.5 * cell and np.mean(d < -1e-9) < 0.05
            # the design's fixed range, whatever the data
            want = ranges.b_mt if quantity == "B" else ranges.f_mn
            assert tuple(actor.mapper.scalar_range) == pytest.approx(want, rel=1e-12)
        if quantity == "B":
            # the air low between the coils is in the drawn section
            actor = next(a for r in p.renderers for k, a in r.actors.items() if k == "slice-xz")
            assert np.asarray(actor.mapper.dataset.points)[:, 2].min() < -10.0
    finally:
        p.close()


def test_force_arrows_are_not_hidden(rendered):
    p, _ = rendered["forcemap"]
    actors = {k: a for r in p.renderers for k, a in r.actors.items()}
    assert actors["windings"].prop.opacity < 0.5
    arrows = actors["force-arrows"].mapper.dataset
    cloud = viz.force_map_data(DESIGN, quality="quick")
    n = int(round(math.sqrt(cloud.n_points)))
    spacing_mm = 2e3 * DESIGN.workspace.half_width_m / (n - 1)
    # every glyph is at least MIN_ARROW of the longest: split the glyphs by their source point
    per = arrows.n_points // cloud.n_points
    pts = np.asarray(arrows.points).reshape(cloud.n_points, per, 3)
    lengths = np.linalg.norm(np.ptp(pts, axis=1), axis=1)  # bounding-box diagonal >= length
    assert lengths.min() >= 0.9 * viz.MIN_ARROW * 0.95 * spacing_mm


def test_isosurface_box_is_sized_to_the_array_and_the_cut_is_stated(rendered):
    p, _ = rendered["isosurface"]
    vol, _, _ = viz.force_isosurface_data(DESIGN, quality="quick")
    b = np.asarray(vol.bounds)
    foot = max(DESIGN.workspace.half_width_m,
               DESIGN.array.pitch_m + DESIGN.coil.outer_radius_m)
    assert b[1] <= 2 * foot * (1 + 1e-9) and b[5] <= max(4 * foot, DESIGN.workspace.z_max_m) + 1e-9
    text = _texts(p)
    assert f"z = {DESIGN.workspace.z_min_m * 1e3:.0f} mm (the workspace's floor)" in " ".join(
        text.split())
    assert "cut flat" in text and "up to z =" in text


def test_field_line_colours_are_the_designs_range(rendered):
    p, _ = rendered["fieldlines"]
    actor = next(a for r in p.renderers for k, a in r.actors.items() if k == "streamlines")
    assert tuple(actor.mapper.scalar_range) == pytest.approx(viz.colour_ranges(DESIGN).b_mt,
                                                             rel=1e-12)
    _, lines = viz.field_line_data(DESIGN, quality="quick")
    values = np.asarray(lines[viz.B_MT])
    lo, hi = actor.mapper.scalar_range
    # what the fixed range leaves out is said
    assert (values.max() > hi) == ("above" in _texts(p) and "clipped" in _texts(p))


@pytest.mark.parametrize("kind", viz.KINDS)
def test_every_figure_states_its_colour_scale(rendered, kind):
    p, _ = rendered[kind]
    text = " ".join(_texts(p).split())
    assert "colour" in text, text
    if kind in ("fieldlines", "forcemap", "slice-B", "slice-F"):
        assert "log scale" in text


# ----------------------------------------------------------------------------- issue: colour scales
def test_slice_panels_state_their_scale_and_the_force_is_where_the_magnet_can_be(tmp_path):
    vert, horiz = viz.slice_data(DESIGN, quality="quick")
    z_min = DESIGN.workspace.z_min_m
    p = viz.plot_slices(DESIGN, quantity="F", data=(vert, horiz), window_size=(640, 300))
    try:
        viz.save_png(p, tmp_path / "f.png")
        actor = next(a for r in p.renderers for k, a in r.actors.items() if k == "slice-xz")
        shown = np.asarray(actor.mapper.dataset.points) * 1e-3
        assert shown[:, 2].min() >= z_min - 1e-9
        lo, hi = actor.mapper.scalar_range
        # the range's top: a 1, 2, 5 x 10^k value (the design's, viz.colour_ranges)
        mant = hi / 10 ** math.floor(math.log10(hi) + 1e-12)
        assert min(abs(mant - m) for m in (1, 2, 5, 10)) < 1e-9
        # and the colour bar has a labelled tick there
        bar = next(iter(p.scalar_bars.values()))
        labels = bar.GetCustomLabels()
        assert max(labels.GetValue(i) for i in range(labels.GetNumberOfValues())) == \
            pytest.approx(hi, rel=1e-9)
        text = " ".join(_texts(p).split())
        assert text.count("one bar (right) for both panels") == 1
        assert "log scale" in text and f"below z = {z_min * 1e3:g} mm" in text
    finally:
        p.close()


def test_run_figure_names_the_off_spans_and_marks_each_injection():
    from designkit.sim.loop import SimulationResult
    from designkit.sim.plot import INJECTED_LABEL, OFF_LABEL, run_figure

    t = np.arange(0.0, 1.0, 1e-3)
    n = len(t)
    state = np.where((t > 0.3) & (t < 0.5), "sensor_dead", "running")
    cols = {"t_s": t, "state": state, "loop_s": np.full(n, 2e-4)}
    for k in ("x_m", "y_m", "z_m", "xe_m", "ye_m", "ze_m", "fz_obj_n", "fz_n", "fz_ref_n"):
        cols[k] = np.zeros(n)
    for k in range(9):
        cols[f"i{k + 1}_a"] = np.zeros(n)
        cols[f"cmd{k + 1}_a"] = np.zeros(n)
    res = SimulationResult(cols, [(0.3, "sensor_dead"), (0.7, "overrun")], [], 1e-3)
    fig = run_figure(res)
    try:
        for ax in fig.axes[1:]:
            names = [t.get_text() for t in ax.get_legend().get_texts()]
            assert OFF_LABEL in names and INJECTED_LABEL in names
            lines = [ln for ln in ax.get_lines() if ln.get_linestyle() == ":"]
            assert sorted(ln.get_xdata()[0] for ln in lines) == [0.3, 0.7]
            assert {"sensor_dead", "overrun"} <= {t.get_text().strip() for t in ax.texts}
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def test_fem_comparison_has_a_residual_row_in_percent():
    import dataclasses

    from designkit.model.coil import Coil
    from designkit.fem.compare import comparison_figure, model_field
    from designkit.fem.runner import FemResult, LineResult

    coil = dataclasses.replace(Coil.from_design(DESIGN), core=None)
    top = coil.length / 2
    z = np.linspace(top + 0.005, top + 0.11, 400)
    lines = []
    for r in (0.0, 0.01):
        bz, _ = model_field(coil, 6.0, r, z, None)
        # a stand-in FEM 0.2 % above the model: the residual row must show -0.2 %
        lines.append(LineResult(r, z, np.zeros_like(z), bz * 1.002))
    fem = FemResult(6.0, lines[0], lines[1], 1.0, 1.0, 0.0, 0.0, {})
    fig = comparison_figure(coil, fem)
    try:
        row = fig.axes[4:6]
        for ax in row:
            assert "%" in fig.axes[4].get_ylabel() and ax.get_yscale() == "symlog"
            bz_line = next(ln for ln in ax.get_lines() if ln.get_label().endswith(": Bz"))
            y = np.asarray(bz_line.get_ydata())
            np.testing.assert_allclose(y, (1 / 1.002 - 1) * 100, rtol=2e-3)
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


def test_sweep_figure_takes_a_first_title_line():
    from designkit.optimize.sweep import parse_param, run_sweep, sweep_figure

    result = run_sweep(DESIGN, [parse_param("inner_radius_m=0.008:0.012:3")], workers=1,
                       progress=False)
    fig = sweep_figure(result, subtitle="model surface-current, 6 A, 30 mm")
    try:
        assert fig.axes[0].get_title().split("\n")[0] == "model surface-current, 6 A, 30 mm"
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)


@pytest.mark.parametrize("kind", ["fieldlines", "forcemap", "slice-B", "slice-F"])
def test_log_colour_bars_have_a_labelled_tick_at_their_top(rendered, kind):
    p, _ = rendered[kind]
    for bar in p.scalar_bars.values():
        _, hi = bar.GetLookupTable().GetRange()
        labels = bar.GetCustomLabels()
        top = max(labels.GetValue(i) for i in range(labels.GetNumberOfValues()))
        assert top == pytest.approx(hi, rel=1e-9), (kind, top, hi)


def test_axis_labels_shrink_with_the_window_so_they_do_not_overlap():
    from designkit.viz.style import axis_font_size

    # VTK labels a 160 mm axis every 20 mm: 9 labels such as "-80"; at 0.6 font sizes per
    # character they fit along the ~40 % of the width the oblique axis takes
    for width in (640, 800, 1024):
        size = axis_font_size(width)
        assert 9 * (3 * 0.6 * size + 4) <= 0.4 * width, (width, size)
    assert axis_font_size(1024) == 10 and axis_font_size(4000) == 10


def _scene_in_title_box(p) -> int:
    """Dark pixels of everything but the title inside the title's box (2 px around it): the
    title box is where the picture changes when the title is hidden."""
    corner = [a for a in p.renderer.actors.values() if hasattr(a, "GetText")
              and hasattr(a, "GetMaximumFontSize") and (a.GetText(2) or "").strip()]
    assert len(corner) == 1
    full = np.asarray(p.screenshot(None, return_img=True), dtype=float)
    corner[0].SetVisibility(False)
    p.render()
    scene = np.asarray(p.screenshot(None, return_img=True), dtype=float)
    corner[0].SetVisibility(True)
    p.render()
    rows, cols = np.nonzero(np.abs(full - scene).max(axis=2) > 30)
    r0, r1 = max(rows.min() - 2, 0), rows.max() + 3
    c0, c1 = max(cols.min() - 2, 0), cols.max() + 3
    return int((scene[r0:r1, c0:c1].min(axis=2) < 150).sum())


@pytest.mark.parametrize("size", [(640, 480), (800, 600)])
@pytest.mark.parametrize("kind", ["forcemap", "isosurface"])
def test_3d_axis_labels_clear_of_the_title_and_of_each_other(kind, size):
    # at the default sizes the top y-axis labels ran into the title and, at the corner where
    # the y axis starts, its first label touched the last label of the x or z axis
    p = viz.render(kind, DESIGN, quality="quick", window_size=size)
    try:
        assert _scene_in_title_box(p) == 0, (kind, size)
        labels = p.renderer.cube_axes_actor.GetAxisLabels(1)
        assert labels.GetValue(0) == "" and all(
            labels.GetValue(i).strip() for i in range(1, labels.GetNumberOfValues()))
    finally:
        p.close()
