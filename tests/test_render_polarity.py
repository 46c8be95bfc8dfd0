"""Polarity is defined once (MagnetSpec.direction, Coil current sense) and means: positive coil
current repels the default magnet (pushes the finger up), as the thesis' unipolar drive does.

Expected signs are derived physically, not from designkit: a counter-clockwise loop (seen from
above) has Bz = mu0 I R^2 / (2 (R^2 + z^2)^1.5) > 0 above it, falling with z, so dBz/dz < 0;
a moment pointing down (m_z < 0) then feels F_z = m_z dBz/dz > 0.
"""

import math

import numpy as np
import pytest

from designkit import Coil
from designkit.model.array import force_matrix
from designkit.design import MU0, default_design, load_design
from designkit.errors import BadInputError


def test_default_moment_points_down_with_the_thesis_magnitude():
    d = default_design()
    m = np.array(d.magnet.moment_vector_a_m2)
    # N52, 10 x 10 mm, M = 1.1579e6 A/m: |m| = M pi r^2 L
    assert m == pytest.approx([0.0, 0.0, -1.1579e6 * math.pi * 0.005**2 * 0.010], rel=1e-12)


def test_positive_current_repels_the_default_magnet():
    d = default_design().replace(core=None)  # air coil: compare with the loop closed form
    coil = Coil.from_design(d)
    z = 0.03
    b, g = coil.field([0.0, 0.0, z], 6.0, gradient=True)
    assert b[2] > 0 and g[2, 2] < 0  # field up above the coil, falling with height
    m = np.array(d.magnet.moment_vector_a_m2)
    f = g.T @ m
    assert f[2] > 0
    # a single mid-radius loop at the winding's centre plane: same sign, same order of size
    r = 0.5 * (d.coil.inner_radius_m + d.coil.outer_radius_m)
    h = z + d.coil.length_m / 2
    dbz = -1.5 * MU0 * 6.0 * d.coil.turns * r * r * 2 * h / (2 * (r * r + h * h) ** 2.5)
    assert dbz < 0 and m[2] * dbz > 0


def test_with_core_the_array_pushes_up_at_30_mm(thesis_array):
    d = default_design()
    arr = thesis_array
    a = arr.actuation_matrix([0.0, 0.0, 0.03])
    cur = np.zeros(arr.n_coils)
    cur[arr.n_coils // 2] = 6.0
    f = force_matrix(d.magnet.moment_vector_a_m2) @ (a[3:] @ cur)
    assert f[2] > 1.0  # ~ +3.15 N with the linear core (README), now repulsive
    assert abs(f[0]) < 1e-9 and abs(f[1]) < 1e-9


def test_direction_round_trips_and_is_validated(tmp_path):
    from designkit.design import design_to_toml

    d = default_design().replace(**{"magnet.direction": [0.0, 0.0, 2.0]})
    assert d.magnet.moment_vector_a_m2[2] == pytest.approx(d.magnet.moment_a_m2)
    p = tmp_path / "d.toml"
    p.write_text(design_to_toml(d))
    assert load_design(p).magnet.direction == (0.0, 0.0, 2.0)
    for bad in ([0.0, 0.0, 0.0], [0.0, float("nan"), 1.0], [1.0, 2.0]):
        with pytest.raises(BadInputError, match="magnet.direction"):
            default_design().replace(**{"magnet.direction": bad})
