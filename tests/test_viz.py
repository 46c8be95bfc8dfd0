"""designkit.viz: off-screen figures are not blank and their data equal the field engine's.

Reference: :meth:`designkit.model.array.CoilArray.field` of the whole (coupled) array evaluated
directly (not through viz), with all cores solved together;
the force is F_j = sum_i m_i dB_i/dx_j.
"""

import numpy as np
import pytest

import pyvista as pv  # a required dependency: no skip

from designkit import Coil, default_design  # noqa: E402
from designkit import viz  # noqa: E402
from designkit.model.array import array_for_design  # noqa: E402
from designkit.cli import main  # noqa: E402
from designkit.errors import BadInputError  # noqa: E402
from designkit.viz.physics import FIELDLINE_TOLERANCE  # noqa: E402

DESIGN = default_design()
# Two energized coils of opposite sign (centre and a corner), so superposition and the skipping
# of coils at 0 A are both exercised.
CURRENTS = np.zeros(9)
CURRENTS[4], CURRENTS[0] = 2.0, -1.5


_ARRAY = array_for_design(DESIGN)


def direct_field(points):
    """The coupled array model evaluated directly (the VTK data must carry exactly this)."""
    b, g = _ARRAY.field(points, CURRENTS)
    m = np.array(DESIGN.magnet.moment_vector_a_m2)
    f = np.array([gi.T @ m for gi in g])
    return b, g, f


def sample(mesh, k=6, seed=0):
    idx = np.random.default_rng(seed).choice(mesh.n_points, size=min(k, mesh.n_points),
                                             replace=False)
    return idx, np.asarray(mesh.points)[idx]


def check_arrays(mesh, with_force=True, k=6, tolerance=None):
    """``tolerance``: the data were evaluated at it (relative to the mesh's largest |B|)."""
    idx, pts = sample(mesh, k)
    b, g, f = direct_field(pts)
    scale_b = np.abs(b).max()
    if tolerance is None:
        np.testing.assert_allclose(np.asarray(mesh[viz.B_T])[idx], b, rtol=1e-9,
                                   atol=1e-9 * scale_b)
    else:
        big = np.linalg.norm(np.asarray(mesh[viz.B_T]), axis=1).max()
        assert np.abs(np.asarray(mesh[viz.B_T])[idx] - b).max() <= tolerance * big
        b = np.asarray(mesh[viz.B_T])[idx]
    np.testing.assert_allclose(np.asarray(mesh[viz.B_MT])[idx], np.linalg.norm(b, axis=1) * 1e3,
                               rtol=1e-9)
    if with_force:
        scale_f = np.abs(f).max()
        np.testing.assert_allclose(np.asarray(mesh[viz.F_N])[idx], f, rtol=1e-9,
                                   atol=1e-9 * scale_f)
        np.testing.assert_allclose(np.asarray(mesh[viz.FZ_MN])[idx], f[:, 2] * 1e3, rtol=1e-9,
                                   atol=1e-9 * scale_f * 1e3)


def not_blank(plotter, min_colours=30, min_fraction=0.05):
    img = plotter.screenshot(return_img=True)
    plotter.close()
    flat = img.reshape(-1, img.shape[-1])[:, :3]
    colours = len(np.unique(flat, axis=0))
    non_white = np.mean(np.any(flat < 245, axis=1))
    assert colours >= min_colours, f"only {colours} distinct colours"
    assert non_white >= min_fraction, f"only {non_white:.3f} of the pixels are not background"
    return img


def test_array_field_is_the_coupled_array_model():
    pts = np.array([[0.0, 0.0, 0.03], [0.02, -0.01, 0.05], [-0.06, 0.04, 0.012]])
    b, g = viz.array_field(DESIGN, pts, CURRENTS)
    rb, rg, _ = direct_field(pts)
    np.testing.assert_allclose(b, rb, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(g, rg, rtol=1e-9, atol=1e-10)
    # default currents: only the centre coil at the design's limit, with all nine cores present
    b0 = viz.array_field(DESIGN, pts, None, gradient=False)
    centre = np.zeros(len(DESIGN.coil_centres_m()))
    centre[len(centre) // 2] = DESIGN.drive.max_current_a
    ref, _ = _ARRAY.field(pts, centre)
    np.testing.assert_allclose(b0, ref, rtol=1e-9, atol=1e-12)
    # ... which is not the lone coil's field: the unpowered cores are magnetized too
    alone = Coil.from_design(DESIGN).field(pts, DESIGN.drive.max_current_a)
    assert np.max(np.abs(b0 - alone)) > 1e-3 * np.max(np.abs(alone))


def test_force_is_gradient_transpose_times_moment():
    # Independent check of F = (grad B)^T m: the closed-form force between two point dipoles
    # (e.g. Yung et al. 1998), F = 3 mu0/(4 pi r^5) [(m1.r) m2 + (m2.r) m1 + (m1.m2) r
    # - 5 (m1.r)(m2.r) r / r^2], on random dipoles and positions.
    from designkit.constants import MU0
    from designkit.field import dipole_field

    rng = np.random.default_rng(3)
    m1 = rng.normal(size=3)
    r = rng.normal(size=(20, 3)) * 0.05
    m2 = rng.normal(size=3)
    _, g = dipole_field(r, m1, gradient=True)
    f = viz.force_from_gradient(g, m2)
    rn = np.linalg.norm(r, axis=1)[:, None]
    a, b = r @ m1, r @ m2
    want = 3 * MU0 / (4 * np.pi * rn**5) * (a[:, None] * m2 + b[:, None] * m1
                                            + (m1 @ m2) * r - 5 * (a * b)[:, None] * r / rn**2)
    np.testing.assert_allclose(f, want, rtol=1e-10)


def test_bad_inputs_name_the_parameter():
    with pytest.raises(BadInputError, match="currents"):
        viz.resolve_currents(DESIGN, [1.0, 2.0])
    with pytest.raises(BadInputError, match="kind"):
        viz.render("nope", DESIGN)
    with pytest.raises(BadInputError, match="quality"):
        viz.slice_data(DESIGN, quality="medium")


def test_scene_renders_and_carries_the_currents():
    blocks = viz.scene_meshes(DESIGN, CURRENTS)
    w = blocks["windings"]
    assert set(np.unique(w[viz.CURRENT_A])) == {-1.5, 0.0, 2.0}
    # winding solid: hollow cylinder with the design's radii and length, tops at z = 0
    c = DESIGN.coil
    assert w.bounds[5] == pytest.approx(0.0, abs=1e-7)  # float32 points
    assert w.bounds[4] == pytest.approx(-c.length_m, abs=1e-7)
    not_blank(viz.plot_array_scene(DESIGN, CURRENTS, window_size=(240, 180), blocks=blocks))


def test_slices_match_the_field_engine_and_render():
    vert, horiz = viz.slice_data(DESIGN, CURRENTS, quality="quick")
    check_arrays(vert)
    check_arrays(horiz)
    assert np.allclose(np.asarray(horiz.points)[:, 2], DESIGN.optimize.height_m)
    assert np.allclose(np.asarray(vert.points)[:, 1], 0.0)
    for q in ("B", "F"):
        not_blank(viz.plot_slices(DESIGN, CURRENTS, quantity=q, window_size=(320, 140),
                                  data=(vert, horiz)))


def test_field_lines_match_the_field_engine_and_render():
    vol, lines = viz.field_line_data(DESIGN, CURRENTS, quality="quick")
    check_arrays(vol, with_force=False, tolerance=FIELDLINE_TOLERANCE)
    assert lines.n_points > 100
    # the streamline tracer interpolates B trilinearly; it must still point along B
    idx, pts = sample(lines, 20, seed=1)
    b, _, _ = direct_field(pts)
    traced = np.asarray(lines[viz.B_T])[idx]
    cos = np.sum(b * traced, axis=1) / (np.linalg.norm(b, axis=1) *
                                        np.linalg.norm(traced, axis=1))
    assert np.median(cos) > 0.9
    not_blank(viz.plot_field_lines(DESIGN, CURRENTS, window_size=(240, 180), data=(vol, lines)))


def test_force_map_matches_the_field_engine_and_renders():
    cloud = viz.force_map_data(DESIGN, CURRENTS, height_m=0.04, quality="quick")
    check_arrays(cloud)
    assert np.allclose(np.asarray(cloud.points)[:, 2], 0.04)
    not_blank(viz.plot_force_map(DESIGN, CURRENTS, height_m=0.04, window_size=(240, 180),
                                 data=cloud))


def test_isosurface_is_at_the_threshold_and_renders():
    vol, surface, level = viz.force_isosurface_data(DESIGN, CURRENTS, quality="quick")
    assert level == DESIGN.render.threshold_n
    check_arrays(vol)
    assert surface.n_points > 0
    fz = np.asarray(surface[viz.FZ_MN])
    assert np.all(np.isclose(np.abs(fz), 0.8, rtol=1e-6))
    # points on the surface away from the cores (z > 25 mm; near them the coarse quick grid
    # cannot follow the field), checked against the engine: half of them within 10 % of the
    # level (the quick grid's step is 27 mm)
    far = np.flatnonzero(np.asarray(surface.points)[:, 2] > 0.025)
    idx = np.random.default_rng(2).choice(far, size=min(60, len(far)), replace=False)
    _, _, f = direct_field(np.asarray(surface.points)[idx])
    ratio = f[:, 2] * 1e3 / fz[idx]
    assert np.median(np.abs(ratio - 1)) < 0.1
    not_blank(viz.plot_force_isosurface(DESIGN, CURRENTS, window_size=(240, 180),
                                        data=(vol, surface, level)))


def test_export_vtk_round_trips(tmp_path):
    data = {"slices": viz.slice_data(DESIGN, CURRENTS, quality="quick")}
    files = viz.export_vtk(DESIGN, tmp_path, CURRENTS, quality="quick", data=data)
    expected = {"coils.vtp", "cores.vtp", "magnet.vtp", "workspace.vtp", "field_volume.vts",
                "streamlines.vtp", "slice_vertical.vts", "slice_horizontal.vts",
                "force_map.vtp", "force_volume.vts", "fz_isosurface.vtp"}
    assert set(files) == expected
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp files left
    back = pv.read(tmp_path / "slice_horizontal.vts")
    check_arrays(back)
    back = pv.read(tmp_path / "force_map.vtp")
    check_arrays(back)


def test_save_png_is_atomic_and_checks_the_suffix(tmp_path):
    p = viz.plot_array_scene(DESIGN, window_size=(120, 90))
    with pytest.raises(BadInputError, match="png"):
        viz.save_png(p, tmp_path / "x.jpg")
    out = viz.save_png(p, tmp_path / "x.png")
    p.close()
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [q.name for q in tmp_path.iterdir()] == ["x.png"]


def test_cli_viz_renders_without_a_display(tmp_path):
    out = tmp_path / "f.png"
    assert main(["viz", "forcemap", "--out", str(out), "--size", "200x150",
                 "--quality", "quick", "--currents=" + ",".join(map(str, CURRENTS))]) == 0
    img = pv.read(out)
    assert img.dimensions[:2] == (200, 150)
    assert main(["viz", "scene", "--out", str(tmp_path / "s.png"), "--currents", "1,2"]) == 1
