"""Electrical and thermal model of a coil: turns, wire length, resistance, inductance, heating.

Pure functions of SI numbers (the ``*_from_geometry`` kernels) and, one layer up, functions of
a coil (:class:`designkit.geometry.winding.CoilLike`: a :class:`designkit.Coil`) and a
:class:`designkit.design.WireSpec` / :class:`Design`. Inputs in m, A, V, deg C; outputs in ohm,
H, s, kg, W.

Models (assumptions and derivations: docs/electrical.md):

- turns: ``layered`` (square) or ``orthocyclic`` packing of the insulated wire, whole turns
  by layer counts, a continuous count (section area / d_ins^2 / packing) for the optimizer;
- resistance: R = rho(T) l / (pi d^2 / 4), l = turns x 2 pi x mean radius (leads ignored),
  rho(T) linear in T (IEC 60028 annealed copper by default);
- air-core inductance: exact for a uniform current density over the rectangular section, by
  the Fourier-Bessel integral (Dodd & Deeds 1968; Conway, IEEE Trans. Magn. 46, 75 (2010));
- iron core: ``coil.core.extra_inductance(coil)`` (:mod:`designkit.cores`);
- thermal: lumped and adiabatic at a constant current (conservative).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.special import j1, sici

from firmware_io.hw.driver import DriverRating
from firmware_io.mapfile.drive import DriveRecord

from ..constants import MU0
from ..design import Design, DriveSpec, OptimizeSpec, WireSpec
from ..errors import BadInputError
from ..field.fourier_bessel import int_x_j1, quarter_period_panels
from ..geometry.winding import CoilLike, WindingGeometry
from ..support import validate as v

Packing = Literal["layered", "orthocyclic"]
PACKINGS: tuple[str, ...] = ("layered", "orthocyclic")

COPPER_DENSITY_KG_M3 = 8960.0
COPPER_SPECIFIC_HEAT_J_KG_K = 385.0
DEFAULT_MAX_TEMPERATURE_C = 100.0
"""Winding temperature limit of the thermal estimate (assumed: class-130 enamel with margin)."""

_ORTHO_PITCH = math.sqrt(3.0) / 2.0
_EPS = 1e-9  # geometric counts: 7 mm / 0.7 mm must give 10 layers, not 9.999999


# ====================================================================== turns and wire
def packing_factor(packing: str) -> float:
    """Section area per turn in units of d_ins^2: 1 (layered) or sqrt(3)/2 (orthocyclic)."""
    if packing == "layered":
        return 1.0
    if packing == "orthocyclic":
        return _ORTHO_PITCH
    raise BadInputError("packing", "'layered' or 'orthocyclic'", packing)


def turns_continuous(inner_radius: float, outer_radius: float, length: float,
                     insulated_diameter: float, packing: str = "layered") -> float:
    """Turns of a fully packed section as a real number: w h / (d_ins^2 p), p = packing factor.

    What the optimizer uses (smooth in the geometry); equals the layer count in the limit of
    many turns. Units: m in, turns out.
    """
    return ((outer_radius - inner_radius) * length
            / (insulated_diameter ** 2 * packing_factor(packing)))


def turns_from_geometry(inner_radius: float, outer_radius: float, length: float,
                        insulated_diameter: float, packing: str = "layered") -> int:
    """Whole turns that fit in the section (layers x turns per layer), checked inputs.

    Parameters
    ----------
    inner_radius, outer_radius, length : float, m
    insulated_diameter : float, m
        Wire diameter over the enamel.
    packing : {'layered', 'orthocyclic'}

    Returns
    -------
    int
        Number of turns (0 if not even one turn fits).
    """
    ri = v.positive("inner_radius", inner_radius)
    ro = v.positive("outer_radius", outer_radius)
    if ro <= ri:
        raise BadInputError("outer_radius", f"> inner_radius ({ri} m)", outer_radius)
    h = v.positive("length", length)
    d = v.positive("insulated_diameter", insulated_diameter)
    packing_factor(packing)
    depth = ro - ri
    per_layer = int(math.floor(h / d + _EPS))
    if depth + _EPS * d < d or per_layer == 0:
        return 0
    if packing == "layered":
        return int(math.floor(depth / d + _EPS)) * per_layer
    layers = 1 + int(math.floor((depth - d) / (d * _ORTHO_PITCH) + _EPS))
    # nested layers sit half a pitch over: they lose a turn unless half a pitch is left spare
    nested = per_layer if h + _EPS * d >= (per_layer + 0.5) * d else per_layer - 1
    return (layers + 1) // 2 * per_layer + layers // 2 * nested


def wire_length_from_geometry(inner_radius: float, outer_radius: float, turns: float) -> float:
    """Winding wire length, m: turns x 2 pi x mean radius (leads not included)."""
    return turns * math.pi * (inner_radius + outer_radius)


def resistivity(wire: WireSpec, temperature_c: float | None = None) -> float:
    """Resistivity at ``temperature_c`` (default: the wire's operating temperature), ohm m."""
    t = wire.operating_temperature_c if temperature_c is None else v.finite(
        "temperature_c", temperature_c, "C")
    rho = wire.resistivity_ohm_m * (1.0 + wire.temperature_coefficient_per_k
                                    * (t - wire.reference_temperature_c))
    if rho <= 0:
        raise BadInputError("temperature_c", "above the temperature where the linear "
                            "resistivity law reaches zero", t)
    return rho


def resistance_from_geometry(inner_radius: float, outer_radius: float, turns: float,
                             wire_diameter: float, resistivity_ohm_m: float) -> float:
    """DC resistance rho l / (pi d^2 / 4), ohm (unchecked kernel, SI)."""
    area = math.pi * wire_diameter ** 2 / 4.0
    return resistivity_ohm_m * wire_length_from_geometry(inner_radius, outer_radius, turns) / area


def _check_wire(wire: WireSpec) -> WireSpec:
    v.positive("wire.diameter_m", wire.diameter_m)
    v.positive("wire.insulated_diameter_m", wire.insulated_diameter_m)
    if wire.insulated_diameter_m < wire.diameter_m * (1 - 1e-12):
        raise BadInputError("wire.insulated_diameter_m", f">= wire.diameter_m ({wire.diameter_m} m)",
                            wire.insulated_diameter_m)
    v.positive("wire.resistivity_ohm_m", wire.resistivity_ohm_m, "ohm m")
    packing_factor(wire.packing)
    return wire


def resistance(coil: WindingGeometry, wire: WireSpec | None = None,
               temperature_c: float | None = None) -> float:
    """DC resistance of the coil's winding, ohm.

    Parameters
    ----------
    coil : WindingGeometry or Coil
        The winding (m, turns).
    wire : WireSpec, optional
        Default: ``WireSpec()`` (0.7 mm bare copper at 20 C).
    temperature_c : float, optional
        Winding temperature, deg C (default: ``wire.operating_temperature_c``).
    """
    wire = _check_wire(WireSpec() if wire is None else wire)
    return resistance_from_geometry(coil.inner_radius, coil.outer_radius, coil.turns,
                                    wire.diameter_m, resistivity(wire, temperature_c))


# ====================================================================== inductance
def _tail(rho_i: float, h: float, t_max: float) -> float:
    """int_T^inf of the Bessel integrand in mean: with x J0(x) ~ sqrt(2x/pi) cos(x - pi/4),
    S^2 averages to (t/pi) (1 + rho - 2 sqrt(rho) cos((1 - rho) t)) and g(t h) ~ t h, so the
    tail is h/pi [(1 + rho)/(3 T^3) - 2 sqrt(rho) delta^3 C4(delta T)], delta = 1 - rho,
    C4(x) = int_x^inf cos(u)/u^4 du (by parts down to Ci, Si). The cos term matters for thin
    windings, where the two Bessel oscillations stay in phase far out."""
    delta = 1.0 - rho_i
    x = delta * t_max
    if x < 1e-3:  # C4 ~ 1/(3x^3) - 1/(2x) + ...: the tail is (1 - sqrt(rho))^2 h / (3 pi T^3)
        return (1.0 - math.sqrt(rho_i)) ** 2 * h / (3.0 * math.pi * t_max ** 3) + (
            math.sqrt(rho_i) * h * delta ** 2 / (math.pi * t_max))
    si, ci = sici(x)
    s1 = 0.5 * math.pi - si
    c2 = math.cos(x) / x - s1
    s3 = math.sin(x) / (2 * x * x) + c2 / 2
    c4 = math.cos(x) / (3 * x ** 3) - s3 / 3
    return h / math.pi * ((1.0 + rho_i) / (3.0 * t_max ** 3) - 2.0 * math.sqrt(rho_i) * delta ** 3 * c4)


def _reduced_inductance(rho_i: float, h: float, t_max: float) -> tuple[float, ...]:
    """Dimensionless integral Q(rho_i, h) and its derivatives dQ/drho_i, dQ/dh, dQ/dro-scaling.

    In units of ro (rho_i = ri/ro, h = length/ro):
    Q = int_0^inf S(t)^2 g(t h) / t^6 dt, g(u) = u + exp(-u) - 1, S = [int x J1]_{rho_i t}^{t}.
    Then L = 2 pi mu0 N^2 ro^5 Q / (w^2 length^2) with w = ro - ri.
    """
    t, wt = quarter_period_panels(t_max)
    s = int_x_j1(t) - int_x_j1(rho_i * t)
    u = t * h
    g = u + np.expm1(-u)
    t6 = t ** 6
    q = float(np.sum(wt * s * s * g / t6))
    tail = _tail(rho_i, h, t_max)
    q += tail
    # derivatives (analytic, same nodes): dS/drho_i = -t * (rho_i t) J1(rho_i t); dg/dh = t(1 - e^-u)
    ds = -t * (rho_i * t) * j1(rho_i * t)
    eps = 1e-7 * max(rho_i, 1e-3)
    dtail = (_tail(rho_i + eps, h, t_max) - _tail(rho_i - eps, h, t_max)) / (2 * eps)
    dq_drho = float(np.sum(wt * 2.0 * s * ds * g / t6)) + dtail
    dq_dh = float(np.sum(wt * s * s * t * (-np.expm1(-u)) / t6)) + tail / h
    return q, dq_drho, dq_dh


def air_inductance_from_geometry(inner_radius: float, outer_radius: float, length: float,
                                 turns: float, *, t_max: float = 400.0,
                                 gradient: bool = False):
    """Self-inductance of a thick winding with uniform current density, air core, H.

    Parameters
    ----------
    inner_radius, outer_radius, length : float, m
    turns : float
    t_max : float
        Truncation of the Bessel integral in t = k outer_radius (the tail beyond is added in
        mean); its measured accuracy is in docs/electrical.md.
    gradient : bool
        Also return (dL/d inner_radius, dL/d outer_radius, dL/d length) at *fixed turns*, H/m.

    Returns
    -------
    float, H  [, tuple of 3 floats, H/m]
    """
    ro = outer_radius
    rho_i = inner_radius / ro
    hh = length / ro
    w = outer_radius - inner_radius
    q, dq_drho, dq_dh = _reduced_inductance(rho_i, hh, t_max)
    pref = 2.0 * math.pi * MU0 * turns ** 2 * ro ** 5 / (w * w * length * length)
    ell = pref * q
    if not gradient:
        return ell
    # chain rule through (rho_i, h, ro) and the prefactor's w and length
    d_ri = pref * dq_drho / ro + ell * 2.0 / w
    d_ro = (pref * (dq_drho * (-inner_radius / ro ** 2) + dq_dh * (-length / ro ** 2))
            + ell * (5.0 / ro - 2.0 / w))
    d_len = pref * dq_dh / ro - ell * 2.0 / length
    return ell, (d_ri, d_ro, d_len)


def wheeler_inductance(inner_radius: float, outer_radius: float, length: float,
                       turns: float) -> float:
    """Wheeler's multilayer formula, H (a sanity check; ~1 % when 6a, 9l, 10c are comparable).

    L[uH] = 0.8 a^2 N^2 / (6 a + 9 l + 10 c) with a the mean radius, l the length, c the
    depth, all in inches (H. A. Wheeler, Proc. IRE 16, 1398 (1928)).
    """
    inch = 0.0254
    a = 0.5 * (inner_radius + outer_radius) / inch
    c = (outer_radius - inner_radius) / inch
    ell = length / inch
    return 0.8e-6 * a * a * turns ** 2 / (6 * a + 9 * ell + 10 * c)


def air_inductance(coil: WindingGeometry) -> float:
    """Air-core self-inductance of the coil's winding, H (uniform current density model)."""
    return air_inductance_from_geometry(coil.inner_radius, coil.outer_radius, coil.length,
                                        coil.turns)


def inductance(coil: CoilLike, wire: WireSpec | None = None) -> float:
    """Self-inductance of the coil, H: air-core winding plus the core's extra inductance.

    ``wire`` is accepted for symmetry with :func:`resistance`; the uniform-current-density
    model does not depend on it (Rosa's round-wire correction, ~0.1 %, is neglected).
    """
    if wire is not None:
        _check_wire(wire)
    ell = air_inductance(coil)
    if coil.core is not None:
        ell += float(coil.core.extra_inductance(coil))
    return ell


# ====================================================================== drive and heat
def steady_current(resistance_ohm: float, drive: DriveSpec) -> tuple[float, bool]:
    """Steady current V / R capped by the driver's continuous rating, A, and whether capped."""
    i = drive.supply_voltage_v / resistance_ohm
    cap = drive.driver_continuous_current_a
    return (min(i, cap), i > cap)


def copper_mass(inner_radius: float, outer_radius: float, turns: float,
                wire_diameter: float) -> float:
    """Copper mass of the winding, kg (8960 kg/m^3)."""
    return (COPPER_DENSITY_KG_M3 * wire_length_from_geometry(inner_radius, outer_radius, turns)
            * math.pi * wire_diameter ** 2 / 4.0)


def time_to_temperature(mass_kg: float, current_a: float, resistance_ohm: float,
                        wire: WireSpec, start_c: float, max_c: float) -> float:
    """Adiabatic time to heat the winding from ``start_c`` to ``max_c`` at constant current, s.

    m c dT/dt = I^2 R0 (1 + a (T - T0)), R0 = R(start), a = alpha / (1 + alpha (T0 - Tref)):
    t = m c ln(1 + a (Tmax - T0)) / (I^2 R0 a). Zero current or resistance: BadInputError
    (the winding never heats).
    """
    if max_c <= start_c:
        return 0.0
    v.positive("current_a", abs(current_a), "A")
    v.positive("resistance_ohm", resistance_ohm, "ohm")
    alpha = wire.temperature_coefficient_per_k
    a = alpha / (1.0 + alpha * (start_c - wire.reference_temperature_c))
    heat = mass_kg * COPPER_SPECIFIC_HEAT_J_KG_K
    p0 = current_a ** 2 * resistance_ohm
    if a <= 0:
        return heat * (max_c - start_c) / p0
    return heat * math.log1p(a * (max_c - start_c)) / (p0 * a)


@dataclass(frozen=True)
class ElectricalReport:
    """Electrical and thermal numbers of one coil on one drive, with design-rule violations.

    All SI: ohm, H, s, A, W, kg, m. ``violations`` are sentences; empty when all rules pass.
    """

    turns: int
    turns_that_fit: int
    packing: str
    wire_length_m: float
    resistance_ohm: float
    inductance_air_h: float
    inductance_core_h: float
    inductance_h: float
    time_constant_s: float
    settling_time_s: float
    current_a: float
    current_capped: bool
    voltage_v: float
    power_w: float
    copper_mass_kg: float
    fill_factor: float
    time_to_max_temperature_s: float
    max_temperature_c: float
    violations: tuple[str, ...]
    pwm_frequency_hz: float = 0.0
    pwm_ripple_a: float = 0.0
    """Worst-case (50 % duty) peak-to-peak current ripple of the PWM drive, A."""

    def as_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["violations"] = list(self.violations)
        return d


def pwm_ripple(voltage_v: float, resistance_ohm: float, time_constant_s: float,
               frequency_hz: float) -> float:
    """Peak-to-peak current ripple of an RL load on a PWM bridge at 50 % duty (the worst duty),
    A: (V/R) tanh(1 / (4 f tau)), the periodic steady state of the two exponential halves."""
    return voltage_v / resistance_ohm * math.tanh(1.0 / (4.0 * frequency_hz * time_constant_s))


def design_rule_violations(*, resistance_ohm: float, settling_time_s: float, turns: int,
                           turns_that_fit: int, packing: str, drive: DriveSpec,
                           limits: OptimizeSpec) -> list[str]:
    """The design rules of the thesis' device, as sentences (empty list = all pass)."""
    out = []
    supply = driver_rating(drive).supply_violation(drive.supply_voltage_v)
    if supply:
        out.append(supply)
    i_free = drive.supply_voltage_v / resistance_ohm
    if i_free > drive.driver_continuous_current_a:
        out.append(f"V/R = {i_free:.3g} A exceeds the driver's continuous "
                   f"{drive.driver_continuous_current_a:g} A")
    if resistance_ohm > limits.max_resistance_ohm:
        out.append(f"resistance {resistance_ohm:.4g} ohm exceeds the limit "
                   f"{limits.max_resistance_ohm:g} ohm")
    if settling_time_s > limits.max_settling_time_s:
        out.append(f"5 L/R = {settling_time_s * 1e3:.4g} ms exceeds the limit "
                   f"{limits.max_settling_time_s * 1e3:g} ms")
    if turns > turns_that_fit:
        out.append(f"{turns} turns do not fit the winding section: at most {turns_that_fit} "
                   f"with {packing} packing of the insulated wire (fill factor impossible)")
    return out


def electrical_report(design: Design, coil: CoilLike, *,
                      max_temperature_c: float = DEFAULT_MAX_TEMPERATURE_C) -> ElectricalReport:
    """Everything electrical and thermal about ``coil`` (``Coil.from_design(design)`` for the
    design's own: this module sits below designkit.model.coil and does not build coils).

    Resistance at the wire's operating temperature; current = V/R capped by the driver's
    continuous rating; thermal estimate at that current from the operating temperature.
    """
    wire = _check_wire(design.wire)
    r = resistance(coil, wire)
    l_air = air_inductance(coil)
    l_total = inductance(coil, wire)
    tau = l_total / r
    i, capped = steady_current(r, design.drive)
    mass = copper_mass(coil.inner_radius, coil.outer_radius, coil.turns, wire.diameter_m)
    fit = turns_from_geometry(coil.inner_radius, coil.outer_radius, coil.length,
                              wire.insulated_diameter_m, wire.packing)
    section = (coil.outer_radius - coil.inner_radius) * coil.length
    fill = coil.turns * math.pi * wire.diameter_m ** 2 / 4.0 / section
    t_hot = time_to_temperature(mass, i, r, wire, wire.operating_temperature_c, max_temperature_c)
    violations = design_rule_violations(
        resistance_ohm=r, settling_time_s=5 * tau, turns=coil.turns, turns_that_fit=fit,
        packing=wire.packing, drive=design.drive, limits=design.optimize)
    return ElectricalReport(
        turns=int(coil.turns), turns_that_fit=fit, packing=wire.packing,
        wire_length_m=wire_length_from_geometry(coil.inner_radius, coil.outer_radius, coil.turns),
        resistance_ohm=r, inductance_air_h=l_air, inductance_core_h=l_total - l_air,
        inductance_h=l_total, time_constant_s=tau, settling_time_s=5 * tau, current_a=i,
        current_capped=capped, voltage_v=design.drive.supply_voltage_v, power_w=i * i * r,
        copper_mass_kg=mass, fill_factor=fill, time_to_max_temperature_s=t_hot,
        max_temperature_c=max_temperature_c, violations=tuple(violations),
        pwm_frequency_hz=design.drive.pwm_frequency_hz,
        pwm_ripple_a=pwm_ripple(design.drive.supply_voltage_v, r, tau,
                                design.drive.pwm_frequency_hz))


# ---------------------------------------------------------------------------------------------
# the runner's drive record (firmware_io.mapfile.drive: written into the map file, read by
# firmware_io.runner.config_from_map)

COIL_SURFACE_HEAT_TRANSFER_W_M2_K = 10.0
"""Natural convection from the winding's outer surface and end faces (assumed), W/(m^2 K): sets
the winding's cooling time constant m c / (h A) of the runner's I^2 t guard."""


def driver_rating(drive: DriveSpec) -> DriverRating:
    """The driver the design names, by its ratings (``drive.driver*`` keys)."""
    return DriverRating(drive.driver, float(drive.driver_min_voltage_v),
                        float(drive.driver_max_voltage_v),
                        float(drive.driver_continuous_current_a),
                        float(drive.driver_max_pwm_frequency_hz))


def drive_data(design, coils) -> DriveRecord:
    """The runner's drive record (SI) for ``design``'s coils ``coils`` (designkit Coil objects,
    one per channel, in the array's order): per coil R at the wire's reference temperature (the
    resistance model: alpha, the operating and the hot temperature) and L (with the core); the
    design's supply and driver; the current bounds (the per-coil limit at most what the supply
    pushes through the largest R and the driver's continuous rating) and the I^2 t budget
    (adiabatic heating from the operating temperature to 100 C at the current limit, cooled
    with the time constant m c / (h A)), from the winding in ``design``.

    The coils come from the caller (this layer sits below designkit.model.coil): fieldmap passes the
    map's array, plant the design's coil."""
    w, dr = design.wire, design.drive
    r_ref = [float(resistance(c, w, w.reference_temperature_c)) for c in coils]
    r_all = [float(c.resistance(w)) for c in coils]
    once = {id(c): c for c in coils}  # the same coil object: one inductance solve
    ind_of = {k: float(c.inductance(w)) for k, c in once.items()}
    ind = [ind_of[id(c)] for c in coils]
    r = max(r_all)  # the bounds must hold for every channel
    mass = copper_mass(design.coil.inner_radius_m, design.coil.outer_radius_m,
                       design.coil.turns, w.diameter_m)
    driver = driver_rating(dr)
    limit = min(dr.max_current_a, driver.max_current_a(dr.supply_voltage_v, r))
    t_max = time_to_temperature(mass, limit, r, w, w.operating_temperature_c,
                                DEFAULT_MAX_TEMPERATURE_C)
    budget = limit ** 2 * t_max
    c = design.coil
    area = 2 * math.pi * c.outer_radius_m * c.length_m + 2 * math.pi * (
        c.outer_radius_m ** 2 - c.inner_radius_m ** 2)
    tau = mass * COPPER_SPECIFIC_HEAT_J_KG_K / (COIL_SURFACE_HEAT_TRANSFER_W_M2_K * area)
    return DriveRecord(
        resistance_ref_ohm=tuple(r_ref), inductance_h=tuple(ind),
        supply_voltage_v=float(dr.supply_voltage_v), current_limit_a=float(limit),
        total_current_a=float(dr.total_current_a), driver=driver,
        pwm_frequency_hz=float(dr.pwm_frequency_hz),
        reference_temperature_c=float(w.reference_temperature_c),
        temperature_coefficient_per_k=float(w.temperature_coefficient_per_k),
        operating_temperature_c=float(w.operating_temperature_c),
        hot_temperature_c=DEFAULT_MAX_TEMPERATURE_C,
        thermal_continuous_current_a=math.sqrt(budget / tau), thermal_time_constant_s=tau)
