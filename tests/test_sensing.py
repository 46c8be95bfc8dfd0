"""sensors.range_t and sensors.lsb_t are read: the coil field at a sensor against the range,
the magnet's field in counts; checked against closed forms."""

import math

import numpy as np
import pytest

from designkit import default_design
from designkit.constants import MU0
from designkit.model.sensor_headroom import sensor_headroom


def _thick_solenoid_axis_bz(ri, ro, length, turns, current, z):
    """Closed form on the axis of a uniform thick winding, z from its centre, T."""
    j = turns * current / (length * (ro - ri))

    def f(u):
        return u * math.log((ro + math.hypot(ro, u)) / (ri + math.hypot(ri, u)))

    return MU0 * j / 2 * (f(z + length / 2) - f(z - length / 2))


@pytest.mark.parametrize("seed", range(3))
def test_air_coil_field_and_magnet_counts_match_closed_forms(seed):
    rng = np.random.default_rng(seed)
    d = default_design().replace(core=None, **{
        "sensors.offset_m": rng.uniform(0.005, 0.02), "drive.max_current_a": rng.uniform(1, 6),
        "optimize.height_m": rng.uniform(0.03, 0.06)})
    res = sensor_headroom(d)
    c, s = d.coil, d.sensors
    bz = _thick_solenoid_axis_bz(c.inner_radius_m, c.outer_radius_m, c.length_m, c.turns,
                                 d.drive.max_current_a, c.length_m / 2 + s.offset_m)
    assert res["coil_field_t"][2] == pytest.approx(bz, rel=1e-9)
    assert res["coil_field_fraction_of_range"] == pytest.approx(abs(bz) / s.range_t, rel=1e-9)
    dist = d.optimize.height_m - s.offset_m
    # on the dipole's axis the field is mu0 m / (2 pi r^3) along the moment (signed)
    b_mag = MU0 * d.magnet.moment_vector_a_m2[2] / (2 * math.pi * dist**3)
    assert res["magnet_field_t"][2] == pytest.approx(b_mag, rel=1e-12)
    assert res["magnet_field_counts"] == pytest.approx(abs(b_mag) / s.lsb_t, rel=1e-12)


def test_clipping_follows_the_sensor_range():
    d = default_design()
    res = sensor_headroom(d)
    b = abs(res["coil_field_t"][2])
    assert sensor_headroom(d.replace(**{"sensors.range_t": 0.9 * b}))["clips"]
    assert not sensor_headroom(d.replace(**{"sensors.range_t": 1.1 * b}))["clips"]


def test_tilted_sensors_read_in_their_own_frames():
    # a ring of 6 air coils tilted 40 degrees: each default sensor sits on its coil's axis in
    # its coil's frame, so the coil under it reads the closed-form axial field on the chip's z
    # axis whatever the tilt (a chip frame applied as R instead of R^T spreads it over x, z)
    import tomllib

    from designkit.design import design_from_dict

    d = design_from_dict(tomllib.loads('[array]\nlayout = "ring"\ncount = 6\nradius_m = 0.09\n'
                                       'tilt_deg = 40\n[core]\nenabled = false\n'))
    res = sensor_headroom(d)
    c, s = d.coil, d.sensors
    bz = _thick_solenoid_axis_bz(c.inner_radius_m, c.outer_radius_m, c.length_m, c.turns,
                                 d.drive.max_current_a, c.length_m / 2 + s.offset_m)
    assert res["coil_index"] == res["sensor_index"] % 6  # its own coil drives it hardest
    assert res["coil_field_fraction_of_range"] == pytest.approx(abs(bz) / s.range_t, rel=1e-6)
    assert len(res["fraction_of_range_per_sensor"]) == 12
