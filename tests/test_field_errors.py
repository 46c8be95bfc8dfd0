"""Bad input: a ValueError subclass whose message names the parameter, valid range and value."""

import pickle

import numpy as np
import pytest

from designkit import Coil
from designkit.errors import BadInputError
from designkit.field import dipole_field, loop_field, magnetized_cylinder_field, winding_field

GOOD = dict(inner_radius=0.012, outer_radius=0.019, length=0.1, turns=1429, current=1.0)


def _winding(**kw):
    args = {**GOOD, **kw}
    p = args.pop("points", [0.0, 0.0, 0.1])
    return winding_field(p, args["inner_radius"], args["outer_radius"], args["length"],
                         args["turns"], args["current"], rtol=args.get("rtol", 1e-10))


def _check(exc, name, value):
    assert isinstance(exc.value, ValueError) and isinstance(exc.value, BadInputError)
    msg = str(exc.value)
    assert name in msg and repr(value)[:12] in msg and "must be" in msg
    assert pickle.loads(pickle.dumps(exc.value)).name == exc.value.name


def test_negative_inner_radius():
    with pytest.raises(BadInputError) as e:
        _winding(inner_radius=-0.012)
    _check(e, "inner_radius", -0.012)
    assert "> 0" in str(e.value)


def test_zero_outer_radius():
    with pytest.raises(BadInputError) as e:
        _winding(outer_radius=0.0)
    _check(e, "outer_radius", 0.0)


def test_outer_not_greater_than_inner():
    with pytest.raises(BadInputError) as e:
        _winding(outer_radius=0.012)
    _check(e, "outer_radius", 0.012)
    assert "inner_radius" in str(e.value)


def test_zero_loop_radius():
    with pytest.raises(BadInputError) as e:
        loop_field([0, 0, 1.0], 0.0, 1.0)
    _check(e, "radius", 0.0)


def test_negative_cylinder_radius():
    with pytest.raises(BadInputError) as e:
        magnetized_cylinder_field([0, 0, 1.0], -1.0, 0.01, 1e6)
    _check(e, "radius", -1.0)


def test_zero_length():
    with pytest.raises(BadInputError) as e:
        _winding(length=0)
    _check(e, "length", 0)


def test_zero_turns():
    with pytest.raises(BadInputError) as e:
        _winding(turns=0)
    _check(e, "turns", 0)
    with pytest.raises(BadInputError) as e:
        Coil(inner_radius=0.012, outer_radius=0.019, length=0.1, turns=0)
    _check(e, "turns", 0)


def test_nonfinite_point():
    with pytest.raises(BadInputError) as e:
        _winding(points=[[0, 0, 0.1], [0, np.nan, 0]])
    assert "points" in str(e.value) and "nan" in str(e.value) and "finite" in str(e.value)
    with pytest.raises(BadInputError):
        loop_field([np.inf, 0, 0], 0.01, 1.0)


def test_wrong_shape_points():
    with pytest.raises(BadInputError) as e:
        loop_field(np.zeros((4, 2)), 0.01, 1.0)
    assert "points" in str(e.value) and "(n, 3)" in str(e.value) and "(4, 2)" in str(e.value)


def test_bad_rtol_and_current_and_moment():
    with pytest.raises(BadInputError) as e:
        _winding(rtol=0.5)
    _check(e, "rtol", 0.5)
    with pytest.raises(BadInputError) as e:
        _winding(current=float("inf"))
    assert "current" in str(e.value)
    with pytest.raises(BadInputError) as e:
        dipole_field([1, 0, 0], [0, 0])
    assert "moment" in str(e.value)
