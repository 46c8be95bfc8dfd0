"""force_constant (thesis eq. 4.3) against independent references: the closed-form fractional
knapsack (Fz only) and a scipy linprog ray-shooting LP (3-D force)."""

from __future__ import annotations

import numpy as np
import pytest

from designkit.design import default_design
from designkit.errors import BadInputError
from designkit.render import ArrayActuation, Hemisphere, Plane, Wedge, force_constant
from designkit.render.constant import force_matrices


@pytest.fixture(scope="module")
def source(thesis_array):
    from designkit.fieldmap import default_box

    d = default_design()  # the session's coupled solve of the default array
    return ArrayActuation(thesis_array, d.magnet.moment_vector_a_m2, d.spec_hash(),
                          default_box(d))


def _knapsack(c, u, tl):
    c = np.sort(c)[::-1]
    best, left = 0.0, tl
    for ci in c:
        take = min(u, left)
        best += take * max(ci, 0.0)
        left -= take
    return best


@pytest.mark.parametrize("unipolar", [True, False])
def test_fz_rows_equal_knapsack(source, unipolar):
    res = force_constant(Hemisphere(), source, current_limit_a=6.0, total_current_a=20.0,
                         unipolar=unipolar, rows="fz", n_side=5, progress=False)
    fm = force_matrices(source, res.points_m, "fz")[:, 0, :]
    # the coils render lambda h - F0z (F0: the magnet's pull on the cores, coils off; direct
    # coupled model, not the code's path)
    f0z = source.array.bias_force(res.points_m, np.asarray(source.moment_a_m2))[:, 2]
    assert np.all(f0z < 0)
    for j in range(len(res.points_m)):
        c = fm[j] if unipolar else np.abs(fm[j])
        want = (_knapsack(c, 6.0, 20.0) + f0z[j]) / res.heights_m[j]
        assert res.lam_per_point[j] == pytest.approx(want, rel=2e-6)
    assert res.lam_n_per_m == res.lam_per_point.min()
    np.testing.assert_array_equal(res.limiting_point_m, res.points_m[res.limiting_index])


@pytest.mark.parametrize("unipolar", [True, False])
def test_force_rows_equal_linprog(source, unipolar):
    from scipy.optimize import linprog

    res = force_constant(Wedge(), source, current_limit_a=6.0, total_current_a=54.0,
                         unipolar=unipolar, rows="force", n_side=4, progress=False)
    fm = force_matrices(source, res.points_m, "force")
    f0 = source.array.bias_force(res.points_m, np.asarray(source.moment_a_m2))
    n = fm.shape[2]
    for j in range(len(res.points_m)):
        d = res.heights_m[j] * res.normals[j]
        # variables: I+ (n), I- (n), lambda; max lambda s.t. F (I+ - I-) = lambda d - F0
        a_eq = np.c_[fm[j], -fm[j], -d[:, None]]
        nvar = 2 * n + 1
        bounds = [(0, 6.0)] * n + [(0, 0.0 if unipolar else 6.0)] * n + [(0, None)]
        a_ub = np.r_[np.ones(2 * n), 0.0][None, :]
        lp = linprog(-np.eye(nvar)[-1], A_ub=a_ub, b_ub=[54.0], A_eq=a_eq, b_eq=-f0[j],
                     bounds=bounds, method="highs")
        assert lp.status == 0
        assert res.lam_per_point[j] == pytest.approx(lp.x[-1], rel=1e-5)


def test_plane_bounds_and_bad_input(source):
    with pytest.raises(BadInputError, match="rows"):
        force_constant(Plane(), source, current_limit_a=6.0, total_current_a=54.0, rows="x")
    with pytest.raises(BadInputError, match="current_limit_a"):
        force_constant(Plane(), source, current_limit_a=-1.0, total_current_a=54.0)
    with pytest.raises(BadInputError, match="fieldmap"):
        force_constant(Plane(), object(), current_limit_a=6.0, total_current_a=54.0)
    with pytest.raises(BadInputError, match="object"):
        force_constant(Plane(height_m=0.2), source, current_limit_a=6.0, total_current_a=54.0)


def test_map_source_matches_array_and_cli_records_its_hash(tmp_path):
    """force_constant through a map file (interpolated A) agrees with the array directly, and
    `scene compile --map` records the map's design hash (air coils, small box: fast)."""
    from designkit import fieldmap
    from designkit.cli import main
    from firmware_io.scene import Scene

    # the box holds the CLI's default plane (100 mm wide at 50 mm): scene compile refuses an
    # object outside the map's box
    small = default_design().replace(**{"core": None, "workspace.shape": "box",
                                        "workspace.half_width_m": 0.055,
                                        "workspace.z_min_m": 0.01, "workspace.z_max_m": 0.055})
    path = tmp_path / "map.npz"
    fieldmap.write(path, fieldmap.build(small, spacing=0.003, progress=False))
    fm = fieldmap.load(path, small)
    plane = Plane(size_m=0.05, height_m=0.03)
    kw = dict(current_limit_a=6.0, total_current_a=54.0, n_side=5, progress=False)
    via_map = force_constant(plane, fm, **kw)
    direct = force_constant(plane, ArrayActuation.from_design(small), **kw)
    assert via_map.lam_n_per_m == pytest.approx(direct.lam_n_per_m, rel=5e-3)
    out = tmp_path / "s.npz"
    assert main(["scene", "compile", "plane", "--map", str(path), "--lambda", "1",
                 "--out", str(out)]) == 0
    assert Scene.load(out, expected_design_sha256=small.spec_hash()).lam_n_per_m == 1.0
    # the CLI wraps the map once and passes the wrapped source on: taken as is
    from designkit.render.constant import actuation_source

    src = actuation_source(fm)
    assert actuation_source(src) is src
    assert force_constant(plane, src, **kw).lam_n_per_m == via_map.lam_n_per_m


def test_direct_model_is_an_actuation_source(source):
    # the protocol the runner, force_constant and the localizer type against; a selection of
    # rows and coils is that part of the full matrix, in the order asked, and F0 keeps the shape
    from firmware_io.actuation import ActuationSource

    assert isinstance(source, ActuationSource)
    p = np.array([[0.0, 0.01, 0.03], [0.012, -0.02, 0.045]])
    full = source.actuation(p)
    assert full.shape == (2, 8, source.n_coils)
    sel = source.actuation(p, rows=(5, 3), coils=(4, 0))
    np.testing.assert_array_equal(sel, full[:, [5, 3]][:, :, [4, 0]])
    np.testing.assert_allclose(source.actuation(p[1]), full[1], rtol=0,
                               atol=1e-12 * np.abs(full[1]).max())
    assert source.bias_force(p[0]).shape == (3,)
    f0 = source.bias_force(p)[0]
    np.testing.assert_allclose(source.bias_force(p[0]), f0, rtol=0, atol=1e-12 * np.abs(f0).max())
    with pytest.raises(BadInputError, match="coils"):
        source.actuation(p, coils=(source.n_coils,))
    # the coils' field at the sensors: the direct model's A at the map's flat sensor list
    s = source.sensor_positions_m
    assert source.n_sensors == 18 and s.shape == (18, 3)
    np.testing.assert_allclose(s[:9, :2], source.array.positions()[:, :2], atol=1e-15)
    assert np.all(s[:9, 2] > 0) and np.all(s[9:, 2] < 0)   # upper array first, then the lower
    g = source.sensor_coil_field()
    assert g.shape == (18, 3, source.n_coils)
    np.testing.assert_array_equal(g, source.actuation(s)[:, :3])
    i = np.linspace(-1.0, 1.0, source.n_coils)
    np.testing.assert_allclose(source.sensor_coil_field(i), g @ i)
    with pytest.raises(BadInputError, match="fieldmap"):
        force_constant(Plane(), object(), current_limit_a=6.0, total_current_a=54.0,
                       progress=False)
