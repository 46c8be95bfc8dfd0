"""Figures of any layout: the design point above the coil nearest the layout's centre, the
sections through it, the coils drawn in their poses, the solids cut out exactly, the default
currents on the coil nearest the design point and colour ranges fixed by the design.

References are independent of designkit.viz: the layouts' coil positions written out by hand
(4 x 4 grid rows from +y, a ring from +x counter-clockwise with axes leaning inwards), and a
point-in-cylinder test written from the coil's axis and top face, not from its Pose. Air-core
variants keep the field cheap; the iron-core report of the gallery's designs is the slow test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from designkit import viz
from designkit.design import FreeLayout, GridLayout, RingLayout, default_design

TILT_DEG = 30.0
GRID = default_design().replace(array=GridLayout(4, 4, 0.05), core=None)
RING = default_design().replace(array=RingLayout(6, 0.075, TILT_DEG), core=None,
                                **{"workspace.z_min_m": 0.025})
RING_IRON = default_design().replace(array=RingLayout(6, 0.075, TILT_DEG),
                                     **{"workspace.z_min_m": 0.025})


def ring_axis(k: int, n: int = 6, tilt_deg: float = TILT_DEG) -> np.ndarray:
    """Coil k's axis in a ring: leaning from +z towards the array's axis by the tilt."""
    phi, t = 2 * math.pi * k / n, math.radians(tilt_deg)
    return np.array([-math.sin(t) * math.cos(phi), -math.sin(t) * math.sin(phi), math.cos(t)])


def _texts(plotter) -> str:
    """Every title of the plotter (corner annotations keep one text per corner)."""
    out = []
    for renderer in plotter.renderers:
        for actor in renderer.actors.values():
            if hasattr(actor, "GetText"):
                out += [actor.GetText(i) or "" for i in range(4)]
    return "\n".join(out)


def test_design_point_is_above_the_coil_nearest_the_layouts_centre():
    # 4 x 4 grid, rows from +y: the four middle coils are 5, 6, 9, 10; the first of them,
    # row 1 / column 1, sits at (-25, +25) mm
    assert GRID.design_coil == 5
    np.testing.assert_allclose(GRID.design_point_m, [-0.025, 0.025, 0.030], atol=1e-15)
    # a ring: every coil is as near; coil 0 on +x, the point on its leaning axis
    h = RING.optimize.height_m
    np.testing.assert_allclose(np.asarray(RING.design_point_m),
                               np.array([0.075, 0.0, 0.0]) + h * ring_axis(0), atol=1e-15)
    # the thesis device keeps its design point, (0, 0, h) above the centre coil
    np.testing.assert_allclose(default_design().design_point_m, [0, 0, 0.03], atol=1e-15)


def test_default_currents_drive_the_coil_nearest_the_design_point_not_the_middle_index():
    # coils at x = 200, 0, 50, 120 mm: the layout's centre is x = 92.5 mm, nearest coil 3
    # (120 mm); n // 2 = 2 and the coil at the origin (1) are the wrong answers
    free = default_design().replace(array=FreeLayout(((0.2, 0, 0), (0, 0, 0), (0.05, 0, 0),
                                                      (0.12, 0, 0))), core=None)
    for design, coil in ((free, 3), (GRID, 5)):
        cur = viz.resolve_currents(design)
        assert np.flatnonzero(cur).tolist() == [coil] and coil != design.n_coils // 2
        assert cur[coil] == design.drive.max_current_a


def test_sections_pass_through_the_design_point_and_are_not_empty():
    for design in (GRID, RING):
        dp = np.asarray(design.design_point_m)
        sec = viz.section_plane(design)
        k = design.design_coil
        axis = design.array.axes()[k]
        # the vertical plane holds the design point and the design coil's axis
        assert abs(sec.normal @ axis) < 1e-12 and abs(sec.normal[2]) == 0.0
        vert, horiz = viz.slice_data(design, quality="quick")
        pts = np.asarray(vert.points)
        np.testing.assert_allclose((pts - dp) @ sec.normal, 0.0, atol=1e-12)
        np.testing.assert_allclose(np.asarray(horiz.points)[:, 2], dp[2], atol=1e-15)
        # the design coil is cut by the section: air and solid points on it
        assert np.asarray(vert[viz.IN_SOLID]).any() and not np.asarray(vert[viz.IN_SOLID]).all()
        p = viz.plot_slices(design, quantity="F", data=(vert, horiz), window_size=(480, 220))
        try:
            actors = {k: a for r in p.renderers for k, a in r.actors.items()}
            for view in ("xz", "xy"):
                assert actors[f"slice-{view}"].mapper.dataset.n_points > 0
            # the coils cut by the vertical section are drawn: lines on the solids' surfaces,
            # in the drawing frame (s along x, the plane at y = 0) mapped back to the array's
            cut = np.asarray(actors["coils-xz"].mapper.dataset.points) * 1e-3
            back = np.linalg.inv(sec.to_plane())
            world = (np.c_[cut, np.ones(len(cut))] @ back.T)[:, :3]
            # a 64-gon's facets lie within r (1 - cos(pi / 64)) of the true cylinder
            tol = design.coil.outer_radius_m * (1 - math.cos(math.pi / 64)) + 1e-9
            assert np.abs(viz.solid_distance_m(design, world)).max() <= tol
            text = " ".join(_texts(p).split())
            assert "centre coil" not in text and "through the design point" in text
            assert f"coil {design.design_coil + 1} at" in text
        finally:
            p.close()


def test_the_scene_draws_each_coil_in_its_pose():
    blocks = viz.scene_meshes(RING_IRON)
    tol = RING_IRON.coil.outer_radius_m * (1 - math.cos(math.pi / 64)) + 1e-9
    for key in ("windings", "cores"):
        pts = np.asarray(blocks[key].points)
        # every vertex of the drawn solids lies on a solid's surface (upright cylinders at the
        # winding centres would not: the ring's coils lean 30 degrees)
        assert np.abs(viz.solid_distance_m(RING_IRON, pts)).max() <= tol


def _inside_by_hand(design, k, p):
    """Coil k of a ring: inside its winding or core, from its top-face centre and axis."""
    top = np.array(design.array.top_centres_m()[k])
    a = ring_axis(k)
    c, core = design.coil, design.core
    d = p - top
    s = d @ a                                      # along the axis, from the top face (<= 0)
    rho = np.linalg.norm(d - np.outer(s, a), axis=1)
    winding = (s <= 0) & (s >= -c.length_m) & (rho >= c.inner_radius_m) & \
        (rho <= c.outer_radius_m)
    centre = -c.length_m / 2 + core.offset_m        # the core's centre, along the axis
    iron = (np.abs(s - centre) <= core.length_m / 2) & (rho <= core.radius_m)
    return winding | iron, np.minimum.reduce([np.abs(s), np.abs(s + c.length_m),
                                              np.abs(rho - c.inner_radius_m),
                                              np.abs(rho - c.outer_radius_m),
                                              np.abs(np.abs(s - centre) - core.length_m / 2),
                                              np.abs(rho - core.radius_m)])


def test_inside_solids_matches_a_point_in_cylinder_test_for_a_tilted_coil():
    rng = np.random.default_rng(7)
    k = 2  # at 120 degrees: its axis leans along (-x, +y)
    top = np.array(RING_IRON.array.top_centres_m()[k])
    p = top + rng.uniform(-0.06, 0.06, (20000, 3)) + np.array([0.0, 0.0, -0.03])
    want, margin = _inside_by_hand(RING_IRON, k, p)
    near_k = np.linalg.norm(p - top, axis=1) < 0.05  # other coils are farther than 50 mm
    got = viz.inside_solids(RING_IRON, p)
    clear = near_k & (margin > 1e-9)
    assert want[clear].sum() > 500 and (~want[clear]).sum() > 500
    np.testing.assert_array_equal(got[clear], want[clear])
    # the signed distance agrees in sign and vanishes on the surface
    d = viz.solid_distance_m(RING_IRON, p[clear])
    assert np.all((d <= 0) == want[clear])


def test_colour_ranges_are_fixed_by_the_design_not_by_the_currents():
    design = default_design().replace(core=None)
    r = viz.colour_ranges(design)
    for other in (np.eye(9)[0] * 2.0, -np.eye(9)[4]):
        vol, lines = viz.field_line_data(design, other, quality="quick")
        p = viz.plot_field_lines(design, other, data=(vol, lines), window_size=(320, 240))
        try:
            actor = next(a for rr in p.renderers for key, a in rr.actors.items()
                         if key == "streamlines")
            assert tuple(actor.mapper.scalar_range) == pytest.approx(r.b_mt, rel=1e-12)
        finally:
            p.close()
    # the ranges' tops from the winding alone (an air coil): |B| 2 mm from its mouth, on the
    # axis and at the bore's rim, and the force on the magnet on the axis at the workspace
    # floor; each top is that value rounded up to 1, 2 or 5 x 10^k
    from designkit.field import winding_field

    c, u = design.coil, design.drive.max_current_a
    mouth = c.length_m / 2
    pts = np.array([[0.0, 0.0, mouth + 0.002], [c.inner_radius_m, 0.0, mouth + 0.002],
                    [c.inner_radius_m + 0.002, 0.0, mouth],
                    [0.0, 0.0, mouth + design.workspace.z_min_m]])
    b, g = winding_field(pts, c.inner_radius_m, c.outer_radius_m, c.length_m, c.turns, u,
                         gradient=True)
    b_top = np.linalg.norm(b[:3], axis=1).max() * 1e3
    f_top = np.linalg.norm(g[3].T @ np.array(design.magnet.moment_vector_a_m2)) * 1e3
    assert b_top <= r.b_mt[1] < 2.5 * b_top and f_top <= r.f_mn[1] < 2.5 * f_top
    assert r.b_mt[0] == pytest.approx(r.b_mt[1] * 1e-4) and r.current_a == (-u, u)


def test_run_figure_gives_each_of_16_coils_its_own_colour():
    from designkit.sim.loop import SimulationResult
    from designkit.sim.plot import coil_colours, run_figure

    assert len(set(coil_colours(16))) == 16 and len(set(coil_colours(40))) == 40
    t = np.arange(0.0, 0.2, 1e-3)
    n = len(t)
    cols = {"t_s": t, "state": np.full(n, "running"), "loop_s": np.full(n, 2e-4)}
    for key in ("x_m", "y_m", "z_m", "xe_m", "ye_m", "ze_m", "fz_obj_n", "fz_n", "fz_ref_n"):
        cols[key] = np.zeros(n)
    for k in range(16):
        cols[f"i{k + 1}_a"] = np.sin(t * (k + 1))
        cols[f"cmd{k + 1}_a"] = cols[f"i{k + 1}_a"]
    fig = run_figure(SimulationResult(cols, [], [], 1e-3))
    try:
        lines = [ln for ln in fig.axes[2].get_lines() if ln.get_label().startswith("coil ")]
        assert len(lines) == 16
        assert len({tuple(np.round(ln.get_color(), 6)) for ln in lines}) == 16
    finally:
        import matplotlib.pyplot as plt

        plt.close(fig)
