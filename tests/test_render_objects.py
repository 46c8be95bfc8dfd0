"""designkit.render objects and force laws against independent geometry.

References: brute-force distances to densely sampled surfaces (parametric, not the SDF code),
the sphere's closed form, VTK's exact point-to-mesh distance for meshes, Colgate-Brown's bound.
"""

from __future__ import annotations

import numpy as np
import pytest

from designkit.errors import BadInputError
from designkit.render import (ConstraintLaw, HalfCylinder, Hemisphere, MeshSurface,
                              PenetrationLaw, Plane, Wedge)


def _surface_samples(obj, n=120):
    """Dense points on the whole boundary of each solid (parametric), m."""
    t = np.linspace(0, 1, n)
    if isinstance(obj, Plane):
        s, h = obj.size_m / 2, obj.height_m
        a, b = np.meshgrid(np.linspace(-s, s, n), np.linspace(-s, s, n))
        c = np.meshgrid(np.linspace(-s, s, n), np.linspace(0, h, n // 2))
        faces = [np.c_[a.ravel(), b.ravel(), np.full(a.size, h)],
                 np.c_[a.ravel(), b.ravel(), np.zeros(a.size)]]
        for sign in (-1, 1):
            faces.append(np.c_[np.full(c[0].size, sign * s), c[0].ravel(), c[1].ravel()])
            faces.append(np.c_[c[0].ravel(), np.full(c[0].size, sign * s), c[1].ravel()])
        return np.vstack(faces)
    if isinstance(obj, Hemisphere):
        r = obj.diameter_m / 2
        th, ph = np.meshgrid(np.linspace(0, np.pi / 2, n), np.linspace(0, 2 * np.pi, 2 * n))
        cap = np.c_[(r * np.sin(th) * np.cos(ph)).ravel(), (r * np.sin(th) * np.sin(ph)).ravel(),
                    (r * np.cos(th)).ravel()]
        rr, pp = np.meshgrid(np.linspace(0, r, n), np.linspace(0, 2 * np.pi, 2 * n))
        base = np.c_[(rr * np.cos(pp)).ravel(), (rr * np.sin(pp)).ravel(), np.zeros(rr.size)]
        return np.vstack([cap, base])
    if isinstance(obj, (HalfCylinder, Wedge)):
        L = obj.length_m / 2
        ys = np.linspace(-L, L, n)
        if isinstance(obj, HalfCylinder):
            r = obj.diameter_m / 2
            a = np.linspace(0, np.pi, 2 * n)
            prof = np.c_[r * np.cos(a), r * np.sin(a)]
            fill = [np.c_[x, z] for x in np.linspace(-r, r, n) for z in np.linspace(0, r, n // 2)
                    if x * x + z * z <= r * r]
        else:
            w, h = obj.width_m / 2, obj.height_m
            prof = np.vstack([np.c_[-w + (w) * t, h * t], np.c_[w * t, h * (1 - t)]])
            fill = [np.c_[x, z] for x in np.linspace(-w, w, n) for z in np.linspace(0, h, n // 2)
                    if z <= h * (1 - abs(x) / w)]
        fill = np.vstack(fill)
        side = np.c_[np.repeat(prof[:, 0], n), np.tile(ys, len(prof)), np.repeat(prof[:, 1], n)]
        bottom_x = np.linspace(prof[:, 0].min(), prof[:, 0].max(), n)
        bottom = np.c_[np.repeat(bottom_x, n), np.tile(ys, n), np.zeros(n * n)]
        caps = [np.c_[fill[:, 0], np.full(len(fill), sgn * L), fill[:, 1]] for sgn in (-1, 1)]
        return np.vstack([side, bottom] + caps)
    raise AssertionError


@pytest.mark.parametrize("obj", [Plane(), Hemisphere(), HalfCylinder(), Wedge()],
                             ids=lambda o: type(o).__name__)
def test_signed_distance_matches_brute_force(obj):
    from scipy.spatial import cKDTree

    surf = _surface_samples(obj)
    tree = cKDTree(surf)
    rng = np.random.default_rng(1)
    q = rng.uniform([-0.08, -0.08, -0.02], [0.08, 0.08, 0.09], (3000, 3))
    g = obj.signed_distance(q)
    dist, _ = tree.query(q)
    spacing = 0.1 / 120 * 2  # sample spacing bound, m
    assert np.all(np.abs(np.abs(g) - dist) <= spacing)
    # sign: inside iff below the top surface within the footprint and above the base
    inside = (q[:, 2] > 0) & (q[:, 2] < obj.height(q))
    clear = np.abs(g) > spacing
    assert np.all((g[clear] < 0) == inside[clear])


def test_hemisphere_closed_form_and_normals():
    o = Hemisphere(diameter_m=0.1)
    rng = np.random.default_rng(2)
    d = rng.normal(size=(500, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.2
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = rng.uniform(0.06, 0.2, 500)
    p = d * r[:, None]
    np.testing.assert_allclose(o.signed_distance(p), r - 0.05, atol=1e-15)
    np.testing.assert_allclose(o.normal(p), d, atol=1e-8)
    xy = rng.uniform(-0.035, 0.035, (200, 2))
    np.testing.assert_allclose(o.height(np.c_[xy, np.zeros(200)]),
                               np.sqrt(0.05**2 - (xy**2).sum(1)), atol=1e-15)


def test_surface_points_thesis_discretization():
    pts, nrm = Plane().surface_points(61)
    assert len(pts) == 3721  # thesis Fig. 4.5: 3721 points
    np.testing.assert_allclose(pts[:, 2], 0.05)
    np.testing.assert_allclose(nrm, np.tile([0, 0, 1.0], (3721, 1)), atol=1e-3)  # rim: edge
    pts, nrm = Wedge().surface_points(21)
    # roof normals: (+-h, 0, w/2) normalized
    w, h = 0.05, 0.05
    expect = np.c_[np.sign(pts[:, 0]) * h, np.zeros(len(pts)), np.full(len(pts), w)]
    expect /= np.linalg.norm(expect, axis=1, keepdims=True)
    off = np.abs(pts[:, 0]) > 1e-3
    np.testing.assert_allclose(nrm[off], expect[off], atol=1e-3)  # 1e-3: end-cap rims


def test_constraint_law_thesis_numbers():
    """lambda = 6 N/m on the 50 mm flat surface: 0.3 N up (thesis 4.2.1); none outside."""
    law = ConstraintLaw(6.0)
    f = law.force(Plane(), [[0.01, -0.02, 0.0499], [0.0, 0.0, 0.0501], [0.07, 0.0, 0.03]])
    np.testing.assert_allclose(f, [[0, 0, 0.3], [0, 0, 0], [0, 0, 0]], atol=1e-12)
    # hemisphere: lambda h n at the top surface point above
    p = np.array([[0.03, 0.0, 0.035]])
    top = np.array([0.03, 0.0, 0.04])
    f = ConstraintLaw(6.0).force(Hemisphere(), p)
    # normal taken 10 um above the surface: direction error <= 1e-5 / R = 2e-4
    np.testing.assert_allclose(f[0], 6.0 * 0.04 * top / 0.05, rtol=3e-4, atol=3e-5)


def test_penetration_law_and_passivity_clamp():
    law = PenetrationLaw(stiffness_n_per_m=1e4, damping_n_s_per_m=0.2, loop_period_s=0.004,
                         position_noise_m=1e-5, finger_damping_n_s_per_m=1.0)
    # Colgate-Brown: K < 2 (b - B) / T = 2 * 0.8 / 0.004 = 400 N/m; noise: 0.8 mN / 10 um = 80
    assert law.bound() == (pytest.approx(80.0), "position noise")
    law2 = PenetrationLaw(stiffness_n_per_m=1e4, damping_n_s_per_m=0.2, loop_period_s=0.004,
                          position_noise_m=1e-6, finger_damping_n_s_per_m=1.0)
    assert law2.bound() == (pytest.approx(400.0), "passivity")
    k = law2.effective_stiffness_n_per_m
    f = law2.force(Plane(), [[0.0, 0.0, 0.048]], velocities=[[0.0, 0.0, -0.1]])
    np.testing.assert_allclose(f[0], [0, 0, k * 0.002 + 0.2 * 0.1], rtol=1e-9)
    # moving out fast: damping would pull; the wall never pulls
    f = law2.force(Plane(), [[0.0, 0.0, 0.0499]], velocities=[[0.0, 0.0, 10.0]])
    np.testing.assert_allclose(f, 0.0)
    # deep near the base: pushed out through the top, not the base
    f = law2.force(Plane(), [[0.0, 0.0, 0.005]])
    assert f[0, 2] == pytest.approx(k * 0.045)


@pytest.fixture(scope="module")
def sphere_stl(tmp_path_factory):
    import pyvista as pv

    path = tmp_path_factory.mktemp("mesh") / "ball.stl"
    pv.Sphere(radius=40.0, center=(0, 0, 0), theta_resolution=60,
              phi_resolution=60).save(str(path))  # millimetres
    return path


def test_mesh_grid_against_exact_distance(sphere_stl):
    m = MeshSurface.from_file(sphere_stl, spacing_m=0.002, position_m=(0, 0, 0.0))
    err = m.grid_error(n_samples=3000)
    assert err["near_max_m"] < 0.5e-3 and err["rms_m"] < 0.3e-3
    # against the analytic sphere of the same size (centre 40 mm up): facetting < 0.2 mm
    rng = np.random.default_rng(3)
    r, a = 0.03 * np.sqrt(rng.random(500)), rng.uniform(0, 2 * np.pi, 500)
    p = np.c_[r * np.cos(a), r * np.sin(a)]
    h = m.height(np.c_[p, np.zeros(500)])
    np.testing.assert_allclose(h, 0.04 + np.sqrt(0.04**2 - (p**2).sum(1)), atol=0.5e-3)
    pts, nrm = m.surface_points(21)
    assert np.all(nrm[:, 2] > -1e-6)  # upper side only


def test_mesh_bad_input(tmp_path):
    import pyvista as pv

    open_mesh = tmp_path / "open.stl"
    pv.Plane().triangulate().save(str(open_mesh))
    with pytest.raises(BadInputError, match="closed"):
        MeshSurface.from_file(open_mesh)
    junk = tmp_path / "junk.stl"
    junk.write_bytes(b"not a mesh")
    with pytest.raises(BadInputError, match="mesh"):
        MeshSurface.from_file(junk)
    with pytest.raises(BadInputError, match="mesh"):
        MeshSurface.from_file(tmp_path / "missing.ply")


def test_object_bad_input():
    with pytest.raises(BadInputError, match="diameter_m"):
        Hemisphere(diameter_m=-0.1)
    with pytest.raises(BadInputError, match="points"):
        Plane().signed_distance([[0.0, np.nan, 0.0]])
