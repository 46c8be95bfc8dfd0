"""Magnetic keys of a design file in the wrong unit are refused at once, with the unit they
were probably given in: Br in tesla for M (a report of F = 0.004 mN otherwise), mu in H/m for
mu_r, millitesla for tesla."""

from __future__ import annotations

import pytest

from designkit.cli import main
from designkit.constants import MU0
from designkit.design import load_design
from designkit.errors import BadInputError


@pytest.mark.parametrize("table,key,value,says", [
    ("magnet", "magnetization_a_per_m", "1.4",
     ["[10000, 2e+06] A/m", "Br in tesla", f"{1.4 / MU0:.4g} A/m"]),
    ("magnet", "magnetization_a_per_m", "1.4e7", ["[10000, 2e+06] A/m"]),
    ("core", "relative_permeability", "1.2566e-3", ["[1, 1e+06]", "H/m", "mu_r 1000"]),
    ("core", "saturation_t", "1500", ["[0.1, 3] T", "1500 mT is 1.5 T"]),
    ("sensors", "range_t", "130", ["[0.0001, 10] T", "130 mT is 0.13 T"]),
    ("sensors", "lsb_t", "0.098", ["0.098 mT is 9.8e-05 T"]),
])
def test_a_magnetic_key_in_the_wrong_unit_is_refused_with_the_hint(tmp_path, table, key,
                                                                      value, says):
    f = tmp_path / "d.toml"
    f.write_text(f"[{table}]\n{key} = {value}\n")
    with pytest.raises(BadInputError) as exc:
        load_design(f)
    msg = str(exc.value)
    assert f"{table}.{key}" in msg and "\n" not in msg
    for word in says:
        assert word in msg, msg


def test_the_command_says_it_in_one_line_and_exits_1(tmp_path, capsys):
    f = tmp_path / "d.toml"
    f.write_text("[magnet]\nmagnetization_a_per_m = 1.4\n")
    assert main(["check", "--design", str(f)]) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and "magnet.magnetization_a_per_m" in err[0] and "tesla" in err[0]


@pytest.mark.parametrize("table,key,value", [
    ("magnet", "magnetization_a_per_m", "3.2e5"),  # a ferrite magnet (Br 0.4 T)
    ("magnet", "magnetization_a_per_m", "1.19e6"),  # N55
    ("core", "relative_permeability", "4000"),
    ("core", "saturation_t", "2.1"),  # cobalt iron
    ("sensors", "range_t", "0.1"),
])
def test_real_materials_and_sensors_are_accepted(tmp_path, table, key, value):
    f = tmp_path / "d.toml"
    f.write_text(f"[{table}]\n{key} = {value}\n")
    assert getattr(getattr(load_design(f), table), key) == float(value)
