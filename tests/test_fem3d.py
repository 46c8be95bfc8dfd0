"""3-D GetDP reference (designkit.fem.fem3d) against independent answers: the axisymmetric
surface-current model of one coil with its core (itself within ~1 % of the axisymmetric GetDP
model, tests/test_fem.py), the image method for a magnet above a high-mu_r block, and the
exact field of the winding alone. Coarse meshes; the converged runs are in
studies/fem3d_array.py. Skipped when getdp is absent."""

import shutil

import numpy as np
import pytest

pytestmark = pytest.mark.skipif(shutil.which("getdp") is None,
                                reason="GetDP not installed (apt-get install getdp)")


def _model_single(points, mu_r=1000.0):
    from designkit.model.coil import Coil
    from designkit.cores.panel import Core
    from designkit.fem import fem3d
    from designkit.field import winding_field

    geo = fem3d.thesis_geometry()
    coil = Coil(geo["ri"], geo["ro"], geo["length"], geo["turns"],
                Core(geo["core_radius"], geo["core_length"], mu_r))
    loc = points - np.array([0.0, 0.0, -geo["length"] / 2])
    bw, gw = winding_field(loc, geo["ri"], geo["ro"], geo["length"], geo["turns"], 1.0,
                           gradient=True)
    bc, gc = coil.core.field_local(loc, coil, 1.0, gradient=True)
    return bw + bc, gw + gc


def test_single_core_3d_matches_axisymmetric_model_coarse():
    """Quarter model, coarse mesh (~6k tetrahedra): B and grad B from the iron's magnetization
    within 1.5 % at points on all sides (measured <= 0.8 %, 20 points)."""
    from designkit.fem import fem3d

    rng = np.random.default_rng(7)
    pts = np.column_stack([rng.uniform(-0.06, 0.06, 4), rng.uniform(-0.06, 0.06, 4),
                           rng.uniform(0.015, 0.07, 4)])
    b, g, res = fem3d.single_core_case(pts, level=-2)
    bm, gm = _model_single(pts)
    eb = np.linalg.norm(b - bm, axis=1) / np.linalg.norm(bm, axis=1)
    assert eb.max() < 0.015, eb
    eg = np.linalg.norm(g - gm, axis=(1, 2)) / np.linalg.norm(gm, axis=(1, 2))
    assert eg.max() < 0.015, eg
    # the mirror symmetry is applied: Bx changes sign with x like the model's
    assert np.all(np.sign(b[:, 0]) == np.sign(bm[:, 0]))


@pytest.mark.slow
def test_image_method_force_of_magnet_above_block():
    """F = int (M . grad) B_ind over the magnet, B_ind = B - B(block as air) on one mesh,
    against the image method (mu_r 1000, 10 mm gap) within 5 % on a coarse mesh."""
    from designkit.fem import fem3d

    r = fem3d.magnet_block_force(gap=0.010, mu_r=1000.0, level=-2)
    assert r["image_fz_n"] < 0  # attraction
    assert r["fem_fz_n"] == pytest.approx(r["image_fz_n"], rel=0.05)


def test_image_force_reference_matches_point_dipoles_far_away():
    """The image reference itself: far from the block the cylinders act as point dipoles,
    F = -3 mu0 k m^2 / (2 pi (2 d)^4)."""
    from designkit.design import MU0
    from designkit.fem.fem3d import image_force_z

    a, L, M = 0.005, 0.010, 1.1579e6
    m = M * np.pi * a * a * L
    gap = 0.3
    d = gap + L / 2
    k = 999.0 / 1001.0
    dip = -3 * MU0 * k * m * m / (2 * np.pi * (2 * d) ** 4)
    assert image_force_z(a, L, M, gap, 1000.0) == pytest.approx(dip, rel=2e-3)


def test_bad_symmetry_is_refused():
    from designkit.errors import BadInputError
    from designkit.fem import fem3d

    with pytest.raises(BadInputError, match="symmetry"):
        fem3d.solve([], np.zeros((1, 3)), symmetry="octant")


@pytest.mark.slow
def test_two_magnets_over_one_core_coarse():
    """magnets_case (one run per magnet, the other passive) against the coupled model's F0 and
    cross terms (designkit.model.magnets), two 10 x 10 mm magnets over one thesis core at
    level -2 (~7k tetrahedra): every entry 1.09-1.11 x the FEM's (the coarse FEM's common
    low factor; tests/test_model_magnets.py holds the cached level -1 array), within 3 % of
    each other, the same directions."""
    from designkit.design import default_design
    from designkit.fem.fem3d import magnets_case
    from designkit.model.array import CoilArray
    from firmware_io.cylinder_magnet import CylinderMagnet

    one = CoilArray((CoilArray.default().coils[4],))
    mag = default_design().magnet
    size = (mag.radius_m, mag.length_m)
    pos = np.array([[-0.015, 0.0, 0.025], [0.015, 0.0, 0.03]])
    mom = mag.moment_a_m2 * np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    res = magnets_case(one, [CylinderMagnet(p, m, *size) for p, m in zip(pos, mom)],
                       [[0.0, 0.0, 0.05]], level=-2)
    f, _ = one.bias_force_matrix(pos, mom, magnet_sizes_m=size)
    fe = res["force_n"]
    r = np.linalg.norm(f, axis=-1) / np.linalg.norm(fe, axis=-1)
    assert 1.0 < r.min() and r.max() < 1.15 and r.max() / r.min() < 1.03, r
    cos = (f * fe).sum(-1) / np.linalg.norm(f, axis=-1) / np.linalg.norm(fe, axis=-1)
    assert cos.min() > np.cos(np.radians(2.0))
