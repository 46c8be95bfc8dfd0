"""Several finger magnets in a design file: ``[[magnets]]`` (the first is ``[magnet]``)."""

import tomllib

import pytest

from designkit.design import Design, design_from_dict, design_to_toml
from designkit.errors import BadInputError


def _design(toml: str) -> Design:
    return design_from_dict(tomllib.loads(toml))


def test_magnets_list_round_trips_and_the_first_is_the_magnet():
    d = _design('[[magnets]]\nname = "index"\n[[magnets]]\nname = "thumb"\n'
                'direction = [0, 0, 1]\nradius_m = 0.004\n')
    assert [m.name for m in d.magnets] == ["index", "thumb"]
    assert d.magnet.name == "index" and d.magnets[1].radius_m == 0.004
    # the thumb's moment points up: the sign is the design's, not a default
    assert d.magnets[1].moment_vector_a_m2[2] > 0 > d.magnet.moment_vector_a_m2[2]
    assert design_from_dict(tomllib.loads(design_to_toml(d))) == d
    # one magnet stays the default and [magnet] keeps working
    assert len(Design().magnets) == 1
    assert _design('[magnet]\nradius_m = 0.004\n').magnets[0].radius_m == 0.004


@pytest.mark.parametrize("toml, match", [
    ('[[magnets]]\nname = "a"\n[[magnets]]\nname = "a"\n', r"magnets\[1\].name"),
    ('[array]\nrows = 1\ncolumns = 3\n[[magnets]]\nname = "a"\n[[magnets]]\nname = "b"\n',
     "at most 1 magnet"),
    ('[magnet]\nname = "x"\n[[magnets]]\nname = "a"\n', r"\[magnet\] and \[\[magnets\]\]"),
    ('[[magnets]]\nname = "a"\n[[magnets]]\nname = "b"\nradius_m = -1\n',
     r"magnets\[1\].radius_m"),
])
def test_bad_magnet_lists_are_refused_naming_the_key(toml, match):
    with pytest.raises(BadInputError, match=match):
        _design(toml)


def test_nine_coils_serve_three_magnets_not_four():
    three = "".join(f'[[magnets]]\nname = "m{k}"\n' for k in range(3))
    assert len(_design(three).magnets) == 3
    with pytest.raises(BadInputError, match="at most 3 magnet"):
        _design(three + '[[magnets]]\nname = "m3"\n')
