"""studies/bench_map.py: its quick run (air coils, small box); the scene floor vs a closed form."""

import numpy as np
from conftest import load_study
from scipy.integrate import quad

from designkit.render import Hemisphere


def test_bench_map_quick(tmp_path):
    res = load_study("bench_map").run(tmp_path, quick=True)["air_quick"]
    assert (tmp_path / "bench_map.json").is_file()
    assert not list(tmp_path.glob("*.npz"))  # the study cleans up its map
    # air coils: the tables carry everything; within the 1e-3 target
    assert 0 < res["max_rel"] < 1e-3
    assert res["bias_force_max_rel"] == 0 and res["sensor_induced_max_rel"] == 0
    assert 0 < res["file_mb"] and res["t_1_us_shape3"][0] > 0 and res["t_1e4_ms"][0] > 0


def test_density_floor_of_a_centred_hemisphere_is_the_closed_form_integral():
    """The floor's midpoint-rule integral against scipy's quadrature of the exact disc areas:
    int pi (R^2 - z^2) (z - z_top)^-3 dz over int A_box (z - z_top)^-3 dz, R the radius plus
    the margin (the box holds every disc); a floor that dropped the weight, the margin or the
    dome's shape fails."""
    floor = load_study("bench_map").density_floor
    lo, hi, z_top = np.array([-0.065, -0.058, 0.02]), np.array([0.065, 0.058, 0.07]), 0.004
    for diameter, margin in ((0.1, 0.005), (0.08, 0.0)):
        r = diameter / 2 + margin
        num = quad(lambda z: np.pi * (r * r - z * z) / (z - z_top) ** 3, lo[2], min(r, hi[2]))[0]
        den = quad(lambda z: 0.13 * 0.116 / (z - z_top) ** 3, lo[2], hi[2])[0]
        got = floor([Hemisphere(diameter_m=diameter)], 0.0, margin, lo, hi, z_top, 5e-4)
        assert abs(got - num / den) < 2e-3 * num / den
