"""The 3-D FEM's output stage (designkit.fem.fem3d: the cores' field from their tetrahedra's
magnetization) against independent answers, without GetDP: the conical product rule against
the closed-form moments of a tetrahedron, and a uniformly magnetized cuboid cut into
tetrahedra (one quarter, mirrored like the symmetric models) against magpylib's exact
cuboid field and its finite-difference gradient."""

import math

import numpy as np
import pytest

from designkit.constants import MU0


def _kuhn_tets(lo, hi, n):
    """Tetrahedra (e, 4, 3) filling the box lo..hi: n^3 cubes of six (Kuhn) tetrahedra each."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    h = (hi - lo) / n
    paths = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    out = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                base = lo + h * np.array([i, j, k])
                for path in paths:
                    v = [np.zeros(3)]
                    for ax in path:
                        nxt = v[-1].copy()
                        nxt[ax] = 1.0
                        v.append(nxt)
                    out.append(base + np.array(v) * h)
    return np.array(out)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_conical_rule_integrates_monomials_exactly(n):
    """int over the unit tetrahedron of x^a y^b z^c = a! b! c! / (a + b + c + 3)!, for every
    total degree <= 2n - 1; the weights are fractions of the volume 1/6."""
    from designkit.fem.fem3d import conical_rule

    bary, w = conical_rule(n)
    assert w.sum() == pytest.approx(1.0, rel=1e-14)
    assert np.all(bary >= 0) and np.allclose(bary.sum(axis=1), 1.0)
    x, y, z = bary[:, 1], bary[:, 2], bary[:, 3]
    for d in range(2 * n):
        for a in range(d + 1):
            for b in range(d + 1 - a):
                c = d - a - b
                exact = math.factorial(a) * math.factorial(b) * math.factorial(c) / \
                    math.factorial(d + 3)
                got = np.sum(w * x ** a * y ** b * z ** c) / 6.0
                assert got == pytest.approx(exact, rel=1e-12, abs=1e-16)


@pytest.mark.parametrize("symmetry", ["none", "half", "quarter"])
def test_uniform_cuboid_from_tetrahedra_matches_magpylib(symmetry):
    """A 20 x 16 x 30 mm cuboid, M = (0, 0, 8e5) A/m (b = mu0 M / (1 - 1/mu_r) given at the
    vertices), only the modelled part meshed and the rest mirrored: B and grad B at points
    10-40 mm outside its corners within 2e-5 and 1e-4 (relative, per point) of magpylib's
    (grad B: a 1 um central difference of it)."""
    import magpylib as magpy
    from designkit.fem.fem3d import core_dipoles, dipoles_field

    half = np.array([0.010, 0.008, 0.015])
    lo = -half.copy()
    if symmetry in ("half", "quarter"):
        lo[1] = 0.0
    if symmetry == "quarter":
        lo[0] = 0.0
    tets = _kuhn_tets(lo, half, 3)
    mu_r, mz = 500.0, 8e5
    b_vert = np.zeros(tets.shape)
    b_vert[..., 2] = MU0 * mz / (1.0 - 1.0 / mu_r)
    pos, mom = core_dipoles(tets, b_vert, mu_r, symmetry)
    rng = np.random.default_rng(3)
    d = rng.normal(size=(12, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    pts = d * rng.uniform(0.03, 0.06, (12, 1))  # the box's corners are 20 mm out
    b, g = dipoles_field(pts, pos, mom)
    cube = magpy.magnet.Cuboid(dimension=2 * half, polarization=(0.0, 0.0, MU0 * mz))
    ref = cube.getB(pts)
    eb = np.linalg.norm(b - ref, axis=1) / np.linalg.norm(ref, axis=1)
    assert eb.max() < 2e-5, eb  # measured <= 4.4e-6
    h = 1e-6
    gref = np.stack([(cube.getB(pts + h * e) - cube.getB(pts - h * e)) / (2 * h)
                     for e in np.eye(3)], axis=-1)
    eg = np.linalg.norm(g - gref, axis=(1, 2)) / np.linalg.norm(gref, axis=(1, 2))
    assert eg.max() < 1e-4, eg  # measured <= 1.9e-5
