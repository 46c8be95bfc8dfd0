"""viz.array_field at a picture's tolerance (windings through the skipping evaluator, coupled
cores exact) against the coupled model itself (CoilArray.field, the field engine at 1e-10)."""

from __future__ import annotations

import numpy as np
import pytest

from designkit.model.array import array_for_design
from designkit.design import default_design
from designkit.errors import BadInputError
from designkit.viz.physics import PICTURE_TOLERANCE, array_field, resolve_currents

DESIGN = default_design()


@pytest.mark.parametrize("currents", [None, np.linspace(-3.0, 6.0, 9)])
def test_picture_tolerance_field_is_the_coupled_model_within_it(currents):
    rng = np.random.default_rng(4)
    pts = np.c_[rng.uniform(-0.07, 0.07, (40, 2)), rng.uniform(0.004, 0.08, 40)]
    cur = resolve_currents(DESIGN, currents)
    ref_b, ref_g = array_for_design(DESIGN).field(pts, cur)
    b, g = array_field(DESIGN, pts, currents, tolerance=PICTURE_TOLERANCE)
    assert np.max(np.abs(b - ref_b)) <= PICTURE_TOLERANCE * np.max(np.abs(ref_b))
    assert np.max(np.abs(g - ref_g)) <= PICTURE_TOLERANCE * np.max(np.abs(ref_g))
    # without the gradient: the same B
    b1 = array_field(DESIGN, pts, currents, gradient=False, tolerance=1e-3)
    assert np.max(np.abs(b1 - ref_b)) <= 1e-3 * np.max(np.abs(ref_b))
    # a coarse tolerance really skips: far windings left out, still within it
    b2 = array_field(DESIGN, pts, currents, gradient=False, tolerance=0.05)
    assert np.max(np.abs(b2 - ref_b)) <= 0.05 * np.max(np.abs(ref_b))


def test_picture_tolerance_bad_input():
    with pytest.raises(BadInputError, match="tolerance"):
        array_field(DESIGN, np.zeros((1, 3)) + 0.03, None, tolerance=0.5)
    with pytest.raises(BadInputError, match="tolerance"):
        array_field(DESIGN, np.zeros((1, 3)) + 0.03, None, tolerance=float("nan"))
