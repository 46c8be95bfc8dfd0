"""Electrical/thermal model against hand computations and independent inductance references."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.special import ellipe, ellipk

from designkit import Coil, default_design
from designkit.model import electrical as el
from designkit.design import MU0, WireSpec
from designkit.errors import BadInputError


def test_resistance_of_the_thesis_coil_by_hand():
    # 1429 turns x pi x (12 + 19) mm = 139.17 m of 0.7 mm copper at 20 C:
    # 1.7241e-8 * 1429 * 0.031 / (0.35e-3)^2 = 6.2348 ohm (hand, 5 digits)
    coil = Coil(0.012, 0.019, 0.100, 1429)
    assert coil.resistance() == pytest.approx(6.2348, rel=2e-5)
    # 70 C: x (1 + 0.00393 * 50) = 1.1965
    assert el.resistance(coil, WireSpec(), temperature_c=70.0) == pytest.approx(
        6.2348 * 1.1965, rel=2e-5)


def test_turns_from_geometry_by_hand():
    # 7 mm / 0.7 mm = 10 layers of floor(100 / 0.7) = 142 turns
    assert el.turns_from_geometry(0.012, 0.019, 0.1, 0.7e-3, "layered") == 1420
    # orthocyclic: 1 + floor(6.3 / 0.6062) = 11 layers; 100 mm >= 142.5 x 0.7 mm, so every
    # nested layer also holds 142
    assert el.turns_from_geometry(0.012, 0.019, 0.1, 0.7e-3, "orthocyclic") == 11 * 142
    # the thesis' 1429 is the continuous count 700 mm^2 / 0.49 mm^2
    assert el.turns_continuous(0.012, 0.019, 0.1, 0.7e-3) == pytest.approx(1428.571, rel=1e-6)
    with pytest.raises(BadInputError, match="insulated_diameter"):
        el.turns_from_geometry(0.012, 0.019, 0.1, -0.7e-3)


def _maxwell_mutual(a, b, dz):
    """Maxwell's mutual inductance of coaxial loops (elliptic integrals, scipy)."""
    m = 4 * a * b / ((a + b) ** 2 + dz ** 2)
    k = np.sqrt(m)
    return MU0 * np.sqrt(a * b) * ((2 / k - k) * ellipk(m) - 2 / k * ellipe(m))


def _cell_sum_inductance(ri, ro, length, nr, nz):
    """Uniform current density as nr x nz square cells: cell-centre filaments with Maxwell's
    formula for every pair, and for each cell's self term a loop of the square's geometric mean
    distance 0.44705 side (Grover): L_self = mu0 a (ln(8 a / g) - 2)."""
    side_r = (ro - ri) / nr
    side_z = length / nz
    assert abs(side_r - side_z) < 1e-12
    r = ri + side_r * (np.arange(nr) + 0.5)
    z = side_z * (np.arange(nz) + 0.5)
    R, Z = np.meshgrid(r, z, indexing="ij")
    R, Z = R.ravel(), Z.ravel()
    a, b = R[:, None], R[None, :]
    dz = Z[:, None] - Z[None, :]
    off = ~np.eye(len(R), dtype=bool)
    m = np.zeros_like(dz)
    m[off] = _maxwell_mutual(np.broadcast_to(a, dz.shape)[off],
                             np.broadcast_to(b, dz.shape)[off], dz[off])
    g = 0.44705 * side_r
    self_terms = MU0 * R * (np.log(8 * R / g) - 2.0)
    return m.sum() + self_terms.sum()  # per (turn per cell)^2


def test_air_inductance_matches_maxwell_filament_sum():
    ri, ro, length = 0.010, 0.016, 0.030
    nr, nz = 12, 60
    ref = _cell_sum_inductance(ri, ro, length, nr, nz)  # one turn per cell
    got = el.air_inductance_from_geometry(ri, ro, length, nr * nz)
    assert got == pytest.approx(ref, rel=1e-3)


def test_thin_winding_tends_to_lorenz_current_sheet():
    import mpmath

    a, length, n = 0.02, 0.05, 100
    k2 = 4 * a * a / (4 * a * a + length * length)
    mpmath.mp.dps = 30
    k = mpmath.sqrt(k2)
    # Nagaoka coefficient (Lorenz formula): L = K mu0 pi a^2 N^2 / l
    kn = 4 / (3 * mpmath.pi * mpmath.sqrt(1 - k2)) * (
        (1 - k2) / k2 * mpmath.ellipk(k2) - (1 - 2 * k2) / k2 * mpmath.ellipe(k2) - k)
    ref = float(kn) * MU0 * math.pi * a * a * n * n / length
    dev = {}
    for w in (1e-5, 1e-6, 1e-7):
        got = el.air_inductance_from_geometry(a - w / 2, a + w / 2, length, n)
        dev[w] = got / ref - 1
    assert abs(dev[1e-7]) < 5e-6
    # the approach is first order in the thickness (field energy inside the shell)
    assert dev[1e-5] / dev[1e-6] == pytest.approx(10.0, rel=0.02)


def test_wheeler_within_its_accuracy_for_the_thesis_coil():
    got = el.air_inductance_from_geometry(0.012, 0.019, 0.1, 1429)
    wheeler = el.wheeler_inductance(0.012, 0.019, 0.1, 1429)
    assert abs(got / wheeler - 1) < 0.01
    # the long-solenoid formula at the mean radius is far off (18-30 % for this coil)
    naive = MU0 * 1429 ** 2 * math.pi * 0.0155 ** 2 / 0.1
    assert abs(got / naive - 1) > 0.15


def test_inductance_gradient_matches_finite_differences():
    x = [0.011, 0.02, 0.06]
    _, grad = el.air_inductance_from_geometry(*x, 900, gradient=True)
    for k in range(3):
        h = 1e-7
        xp, xm = list(x), list(x)
        xp[k] += h
        xm[k] -= h
        fd = (el.air_inductance_from_geometry(*xp, 900)
              - el.air_inductance_from_geometry(*xm, 900)) / (2 * h)
        assert grad[k] == pytest.approx(fd, rel=1e-6)


def test_adiabatic_heating_matches_ode():
    wire = WireSpec()
    mass, i, r0 = 0.48, 5.8, 6.23
    got = el.time_to_temperature(mass, i, r0, wire, 20.0, 100.0)

    def rhs(t, y):
        return [i * i * r0 * (1 + wire.temperature_coefficient_per_k * (y[0] - 20.0))
                / (mass * el.COPPER_SPECIFIC_HEAT_J_KG_K)]

    sol = solve_ivp(rhs, (0, 2 * got), [20.0], events=lambda t, y: y[0] - 100.0,
                    rtol=1e-10, atol=1e-10)
    assert got == pytest.approx(sol.t_events[0][0], rel=1e-6)


def test_design_rules_are_reported_in_words_for_the_thesis_device():
    design = default_design()
    air = design.replace(core=None)
    rep = el.electrical_report(air, Coil.from_design(air))
    text = " ".join(rep.violations)
    assert ("drive.supply_voltage_v = 36 V is above the rating of the driver 'Cytron MD10C'"
            in text and "drive.driver_max_voltage_v" in text)
    assert "6.235 ohm exceeds" in text
    assert "do not fit" in text and "1420" in text
    assert rep.copper_mass_kg == pytest.approx(8960 * 139.169 * math.pi * 0.35e-3 ** 2, rel=1e-4)
    assert rep.current_a == pytest.approx(36 / 6.2348, rel=1e-4)
    # a 2 ohm coil on 36 V would draw 18 A > 13 A: capped and reported
    small = Coil(0.012, 0.019, 0.1, 460)
    rep2 = el.electrical_report(design.replace(core=None), small)
    assert rep2.current_capped and rep2.current_a == 13.0
    assert any("exceeds the driver's continuous 13 A" in s for s in rep2.violations)


def test_core_adds_inductance_and_breaks_the_tau_rule():
    design = default_design()  # mu_r 1000 core (designkit.cores's model)
    rep = el.electrical_report(design, Coil.from_design(design))
    assert rep.inductance_core_h > 3 * rep.inductance_air_h
    assert any("5 L/R" in s for s in rep.violations)


def test_bad_wire_is_rejected():
    coil = Coil(0.012, 0.019, 0.1, 1429)
    with pytest.raises(BadInputError, match="wire.diameter_m"):
        el.resistance(coil, WireSpec(diameter_m=-0.7e-3))
    with pytest.raises(BadInputError, match="insulated"):
        el.resistance(coil, WireSpec(diameter_m=0.7e-3, insulated_diameter_m=0.6e-3))
