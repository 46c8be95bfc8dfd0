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


@pytest.mark.parametrize("call,name,value,extra", [
    (lambda: _winding(inner_radius=-0.012), "inner_radius", -0.012, "> 0"),
    (lambda: _winding(outer_radius=0.0), "outer_radius", 0.0, ""),
    (lambda: _winding(outer_radius=0.012), "outer_radius", 0.012, "inner_radius"),
    (lambda: loop_field([0, 0, 1.0], 0.0, 1.0), "radius", 0.0, ""),
    (lambda: magnetized_cylinder_field([0, 0, 1.0], -1.0, 0.01, 1e6), "radius", -1.0, ""),
    (lambda: _winding(length=0), "length", 0, ""),
    (lambda: _winding(turns=0), "turns", 0, ""),
    (lambda: Coil(inner_radius=0.012, outer_radius=0.019, length=0.1, turns=0), "turns", 0, ""),
], ids=["negative inner radius", "zero outer radius", "outer not above inner",
        "zero loop radius", "negative cylinder radius", "zero length", "zero turns",
        "coil with zero turns"])
def test_bad_geometry_names_the_parameter(call, name, value, extra):
    with pytest.raises(BadInputError) as e:
        call()
    _check(e, name, value)
    assert extra in str(e.value)


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
