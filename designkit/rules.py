"""The rule book: every buildability rule of a design, defined once, as pure functions of it.

Input: a :class:`designkit.design.Design` (SI, m). Output: :func:`rules` -> a list of
:class:`Rule` (value, limit, unit, which side is allowed, the design keys that fix it and a
sentence with the fix). The optimizer bounds its variables by :func:`pitch_clearance_m` and
:func:`max_core_protrusion_m` so its optima satisfy these rules; ``designkit check`` prints
them, ``report`` lists them with the device constraints, ``cad`` refuses a design that
violates one. :func:`layout` is the assembly's derived geometry (flanges, frame pockets,
footprint, fixings, sensor mount), which cad/params.py converts to millimetres.

Conventions: coil top faces at z = 0; "reach" is how far the coil stack rises above a
winding end plane. Rationale of each rule: docs/rules.md.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from .design import Design
from .model import electrical as el
from .model.array import CoilArray
from .sensing.sites import headroom

TOLERANCE_M = 1e-9
"""Round-off allowed on a geometric rule, m (a rule met with equality holds)."""


@dataclass(frozen=True)
class Rule:
    """One rule evaluated on a design: ``value <= limit`` (kind 'upper') or ``>=`` ('lower')."""

    name: str
    value: float
    limit: float
    unit: str
    kind: str
    keys: tuple[str, ...]
    """Design keys (``section.field``) that change the outcome."""
    what: str
    fix: str
    """The sentence that says how to fix a violation."""
    tolerance: float = TOLERANCE_M
    group: str = "cad"
    """'cad': a rule of the printed assembly (``cad`` refuses the design); 'device': of the
    device's electrics and workspace (reported, not a reason to refuse printing)."""

    @property
    def margin(self) -> float:
        """limit - value ('upper') or value - limit ('lower'); >= 0 when met, in ``unit``."""
        return self.limit - self.value if self.kind == "upper" else self.value - self.limit

    @property
    def met(self) -> bool:
        return bool(self.margin >= -self.tolerance)

    @property
    def message(self) -> str:
        """``what`` with the numbers and the fix (lengths in mm)."""
        scale, unit = (1e3, "mm") if self.unit == "m" else (1.0, self.unit)
        rel = ">" if self.kind == "upper" else "<"
        return (f"{self.what}: {self.value * scale:.4g} {unit} {rel} the limit "
                f"{self.limit * scale:.4g} {unit}; {self.fix}.")

    def as_dict(self) -> dict:
        """The row of a constraint table (as :meth:`DeviceProblem.constraint_table`)."""
        return {"value": float(self.value), "limit": float(self.limit), "unit": self.unit,
                "kind": self.kind, "margin": float(self.margin), "met": self.met,
                "note": self.what, "keys": list(self.keys), "group": self.group}


@dataclass(frozen=True)
class Layout:
    """The assembly's geometry derived from a design, m (cad/params.py: the same in mm)."""

    mandrel: str
    """'printed_tube' or 'core' (``cad.mandrel`` with 'auto' resolved)."""
    bore_radius_m: float
    flange_radius_m: float
    pocket_radius_m: float
    footprint_x_m: float
    footprint_y_m: float
    fixing_xy_m: tuple[tuple[float, float], ...]
    centres_xy_m: tuple[tuple[float, float], ...]
    sensor_mount_bottom_m: float
    """Underside of the upper sensor mount above the coil tops, m."""
    reach_upper_m: tuple[float, str]
    """How far the coil stack rises above the winding's top plane, m, and what reaches."""
    reach_lower_m: tuple[float, str]


def board_top_m(design: Design) -> float:
    """Top face of the upper Hall-sensor board above the coil tops, m."""
    return design.sensors.offset_m + design.cad.board_thickness_m / 2


def reachable_height_m(design: Design) -> float:
    """Lowest magnet-centre height above the coil tops: board top + magnet half length, m."""
    return board_top_m(design) + design.magnet.length_m / 2


def pitch_clearance_m(design: Design) -> float:
    """Smallest pitch - 2 x winding outer radius that leaves a frame web of the minimum wall
    between the flange pockets of neighbouring coils, m."""
    c = design.cad
    return c.min_wall_m + 2 * (c.flange_lip_m + c.pocket_clearance_m)


def max_core_protrusion_m(design: Design) -> float:
    """Highest core top above the winding's top plane under the upper sensor mount, m."""
    c = design.cad
    return design.sensors.offset_m - c.board_thickness_m / 2 - c.mount_floor_m


def _mandrel(design: Design, bore: float) -> str:
    c = design.cad
    if design.core is None:
        return "printed_tube"
    if c.mandrel == "auto":
        room = design.coil.inner_radius_m - bore
        return "printed_tube" if room >= c.min_wall_m - TOLERANCE_M else "core"
    return c.mandrel


def layout(design: Design) -> Layout:
    """The derived geometry of the assembly (see :class:`Layout`), m."""
    c, coil, core, arr = design.cad, design.coil, design.core, design.array
    bore = (coil.inner_radius_m - c.air_core_tube_wall_m if core is None
            else core.radius_m + c.core_clearance_m)
    flange = coil.outer_radius_m + c.flange_lip_m
    pocket = flange + c.pocket_clearance_m
    # the footprint is rows x pitch unless the outer pockets would break out or the corner
    # standoffs (on the diagonal) would not clear the corner pockets by the minimum wall
    corner = (pocket + c.min_wall_m + c.standoff_outer_radius_m) / math.sqrt(2) + c.fixing_inset_m
    edge = max(pocket + c.min_wall_m, corner)
    # (a grid's footprint is rows x pitch: the old rule, for any layout its own outline)
    tops, outline = arr.top_centres_m(), arr.footprint_m()
    fx = max(float(np.ptp(outline[:, 0])), float(np.ptp(tops[:, 0])) + 2 * edge)
    fy = max(float(np.ptp(outline[:, 1])), float(np.ptp(tops[:, 1])) + 2 * edge)
    hx, hy = fx / 2 - c.fixing_inset_m, fy / 2 - c.fixing_inset_m
    up = (c.flange_thickness_m, "top bobbin flange")
    down = (c.flange_thickness_m, "bottom bobbin flange")
    if core is not None:
        top = core.offset_m + core.length_m / 2 - coil.length_m / 2
        bottom = -core.offset_m + core.length_m / 2 - coil.length_m / 2
        up = max(up, (top, "core top"))
        down = max(down, (bottom, "core bottom"))
    return Layout(
        mandrel=_mandrel(design, bore), bore_radius_m=bore, flange_radius_m=flange,
        pocket_radius_m=pocket, footprint_x_m=fx, footprint_y_m=fy,
        fixing_xy_m=((-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)),
        centres_xy_m=tuple((x, y) for x, y, _ in design.coil_centres_m()),
        sensor_mount_bottom_m=board_top_m(design) - c.board_thickness_m - c.mount_floor_m,
        reach_upper_m=up, reach_lower_m=down)


def _wall(name: str, what: str, value: float, design: Design, keys, fix: str) -> Rule:
    return Rule(name, value, design.cad.min_wall_m, "m", "lower", tuple(keys) + ("cad.min_wall_m",),
                f"{what} (printer minimum wall)", fix)


def _array_rules(d: Design, g: Layout) -> list[Rule]:
    """No overlap at the pitch: windings, flanges, the frame web, the sensor-board web."""
    if len(g.centres_xy_m) < 2:
        return []
    c = d.cad
    pitch = min(math.dist(a, b) for a, b in itertools.combinations(g.centres_xy_m, 2))
    keys = ("array.pitch_m", "coil.outer_radius_m")
    return [
        Rule("coils_overlap", 2 * d.coil.outer_radius_m, pitch, "m", "upper", keys,
             "2 x winding outer radius at the pitch (windings overlap above it)",
             "increase array.pitch_m or reduce coil.outer_radius_m"),
        Rule("flanges_overlap", 2 * g.flange_radius_m, pitch, "m", "upper",
             keys + ("cad.flange_lip_m",),
             "2 x bobbin flange radius at the pitch (flanges overlap above it)",
             f"increase array.pitch_m to >= {2 * g.flange_radius_m:.4g} m or reduce "
             "cad.flange_lip_m / coil.outer_radius_m"),
        _wall("frame_web", "frame web between neighbouring flange pockets",
              pitch - 2 * g.pocket_radius_m, d, keys + ("cad.flange_lip_m",
                                                       "cad.pocket_clearance_m"),
              f"increase array.pitch_m to >= {2 * g.pocket_radius_m + c.min_wall_m:.4g} m or "
              "reduce coil.outer_radius_m / cad.flange_lip_m / cad.pocket_clearance_m"),
        _wall("sensor_board_web", "sensor mount web between board pockets",
              pitch - c.board_width_m - 2 * c.board_clearance_m, d,
              ("array.pitch_m", "cad.board_width_m"),
              "use a smaller sensor board (cad.board_width_m) or increase array.pitch_m"),
    ]


def _bobbin_rules(d: Design, g: Layout) -> list[Rule]:
    """Tube wall, flange thickness and lip, frame plate above the pocket and its lip."""
    c = d.cad
    out = []
    if g.mandrel == "printed_tube":
        most = d.coil.inner_radius_m - c.min_wall_m - c.core_clearance_m
        fix = ("increase cad.air_core_tube_wall_m" if d.core is None else
               f"reduce core.radius_m to <= {most:.4g} m, increase coil.inner_radius_m, or set "
               "cad.mandrel = 'core' (wind on the insulated core)")
        out.append(_wall("bobbin_tube_wall", "bobbin tube wall (winding inner radius - bore)",
                         d.coil.inner_radius_m - g.bore_radius_m, d,
                         ("core.radius_m", "coil.inner_radius_m", "cad.mandrel"), fix))
    out += [
        _wall("flange_thickness", "bobbin flange thickness", c.flange_thickness_m, d,
              ("cad.flange_thickness_m",), "increase cad.flange_thickness_m"),
        _wall("flange_lip", "bobbin flange lip (flange radius - winding outer radius)",
              c.flange_lip_m, d, ("cad.flange_lip_m",), "increase cad.flange_lip_m"),
        _wall("frame_plate_above_pocket", "frame plate above the flange pocket",
              c.plate_thickness_m - c.flange_thickness_m, d,
              ("cad.plate_thickness_m", "cad.flange_thickness_m"),
              "increase cad.plate_thickness_m or reduce cad.flange_thickness_m"),
        _wall("frame_lip", "frame lip holding the flange (pocket radius - core hole)",
              g.pocket_radius_m - g.bore_radius_m, d, ("cad.flange_lip_m",),
              "increase cad.flange_lip_m; the flange must be wider than the core hole"),
    ]
    if d.core is not None:
        out.append(Rule("core_clearance", g.bore_radius_m, d.core.radius_m, "m", "lower",
                        ("cad.core_clearance_m",), "bobbin bore radius around the core",
                        "set cad.core_clearance_m >= 0"))
    return out


def _standoff_rules(d: Design, g: Layout) -> list[Rule]:
    """Standoff wall, plate edge beside the fixing holes, room to the nearest flange pocket."""
    c = d.cad
    gap = min(math.dist(f, q) for f in g.fixing_xy_m for q in g.centres_xy_m) \
        - c.standoff_outer_radius_m - g.pocket_radius_m
    return [
        _wall("standoff_wall", "standoff wall (outer radius - fixing hole)",
              c.standoff_outer_radius_m - c.fixing_hole_radius_m, d,
              ("cad.standoff_outer_radius_m", "cad.fixing_hole_radius_m"),
              "increase cad.standoff_outer_radius_m"),
        _wall("fixing_edge", "plate edge beside the fixing holes",
              c.fixing_inset_m - c.standoff_outer_radius_m, d,
              ("cad.fixing_inset_m", "cad.standoff_outer_radius_m"),
              "increase cad.fixing_inset_m or reduce cad.standoff_outer_radius_m"),
        _wall("standoff_to_pocket", "standoff to the nearest flange pocket", gap, d,
              ("cad.fixing_inset_m", "cad.standoff_outer_radius_m", "array.pitch_m"),
              "reduce cad.fixing_inset_m or cad.standoff_outer_radius_m, or increase "
              "array.pitch_m"),
    ]


def _sensor_rules(d: Design, g: Layout) -> list[Rule]:
    """Both sensor boards clear of the flanges/core; the mount clear of the frame plate/core."""
    c = d.cad
    hb = c.board_thickness_m / 2
    out = []
    for side, (level, what) in (("upper", g.reach_upper_m), ("lower", g.reach_lower_m)):
        out.append(Rule(f"{side}_sensor_board", d.sensors.offset_m, level + hb, "m", "lower",
                        ("sensors.offset_m", "core.length_m", "core.offset_m"),
                        f"{side} sensor board above the bobbin/core (the {what} reaches "
                        f"{level * 1e3:.4g} mm)", f"increase sensors.offset_m to >= "
                        f"{level + hb:.4g} m or shorten the core"))
    obstacle, what = max((c.plate_thickness_m, "frame plate"), g.reach_upper_m, g.reach_lower_m)
    need = obstacle + c.mount_floor_m + hb
    out.append(Rule("sensor_mount", d.sensors.offset_m, need, "m", "lower",
                    ("sensors.offset_m", "cad.plate_thickness_m", "cad.mount_floor_m",
                     "core.length_m", "core.offset_m"),
                    f"sensor mount plate above the {what} (up to {obstacle * 1e3:.4g} mm)",
                    f"increase sensors.offset_m to >= {need:.4g} m, reduce the core's "
                    "protrusion, or reduce cad.plate_thickness_m / cad.mount_floor_m"))
    out.append(_wall("sensor_mount_floor", "sensor mount floor", c.mount_floor_m, d,
                     ("cad.mount_floor_m",), "increase cad.mount_floor_m"))
    return out


def _holder_rules(d: Design) -> list[Rule]:
    """Magnet pocket, boss, floor and ring walls, ring width of the finger splint."""
    c = d.cad
    boss = d.magnet.radius_m + c.press_fit_clearance_m + c.boss_wall_m
    return [
        Rule("magnet_pocket", c.press_fit_clearance_m, 0.0, "m", "lower",
             ("cad.press_fit_clearance_m",), "magnet pocket oversize (pocket smaller than the "
             "magnet when < 0)", "set cad.press_fit_clearance_m >= 0 (0.05 mm is a press fit "
             "on FDM printers, whose holes print undersize)"),
        _wall("magnet_boss_wall", "magnet boss wall", c.boss_wall_m, d, ("cad.boss_wall_m",),
              "increase cad.boss_wall_m"),
        _wall("magnet_holder_floor", "magnet holder floor (between magnet and finger)",
              c.holder_floor_m, d, ("cad.holder_floor_m",), "increase cad.holder_floor_m"),
        _wall("finger_ring_wall", "finger ring wall", c.ring_wall_m, d, ("cad.ring_wall_m",),
              "increase cad.ring_wall_m"),
        Rule("finger_ring_width", c.ring_width_m, 2 * boss, "m", "lower", ("cad.ring_width_m",),
             "finger ring width around the magnet boss",
             f"increase cad.ring_width_m to >= {2 * boss:.4g} m"),
    ]


def _driver_rules(d: Design) -> list[Rule]:
    """The supply and the PWM within the ratings of the driver the design names (the same
    limits :meth:`firmware_io.hw.driver.DriverRating.supply_violation` applies to the map's
    drive record, which the hardware runner refuses to drive past)."""
    drv = el.driver_rating(d.drive)
    vs = d.drive.supply_voltage_v
    name = f"the driver {drv.name!r}"
    return [
        Rule("design_supply_voltage_v", vs, drv.max_voltage_v, "V", "upper",
             ("drive.supply_voltage_v", "drive.driver_max_voltage_v"),
             f"supply vs the rating of {name}",
             f"reduce drive.supply_voltage_v to <= {drv.max_voltage_v:g} V or name a driver "
             "rated for it (drive.driver, drive.driver_max_voltage_v)", 0.0, "device"),
        Rule("design_supply_min_voltage_v", vs, drv.min_voltage_v, "V", "lower",
             ("drive.supply_voltage_v", "drive.driver_min_voltage_v"),
             f"supply vs the lowest supply {name} is rated for",
             f"raise drive.supply_voltage_v to >= {drv.min_voltage_v:g} V or name a driver "
             "rated for it", 0.0, "device"),
        Rule("pwm_frequency_hz", d.drive.pwm_frequency_hz, drv.max_pwm_frequency_hz, "Hz",
             "upper", ("drive.pwm_frequency_hz", "drive.driver_max_pwm_frequency_hz"),
             f"PWM frequency vs the PWM input limit of {name}",
             f"reduce drive.pwm_frequency_hz to <= {drv.max_pwm_frequency_hz:g} Hz", 0.0,
             "device"),
    ]


def _device_rules(d: Design) -> list[Rule]:
    """Winding fit, the driver's ratings, the magnet above the board, the workspace floor."""
    w, c = d.wire, d.coil
    fit = el.turns_from_geometry(c.inner_radius_m, c.outer_radius_m, c.length_m,
                                 w.insulated_diameter_m, w.packing)
    reach = reachable_height_m(d)
    return [
        Rule("turns", c.turns, fit, "turns", "upper", ("coil.turns", "wire.insulated_diameter_m"),
             f"turns in the winding section ({w.packing} packing)",
             f"reduce coil.turns to <= {fit} or enlarge the winding section", 0.0, "device"),
        *_driver_rules(d),
        Rule("magnet_at_design_height", d.optimize.height_m, reach, "m", "lower",
             ("optimize.height_m", "sensors.offset_m"),
             "design height vs the lowest magnet centre above the upper sensor board",
             f"increase optimize.height_m to >= {reach:.4g} m", group="device"),
        Rule("workspace_z_min_m", d.workspace.z_min_m, reach, "m", "lower",
             ("workspace.z_min_m", "sensors.offset_m"),
             "workspace floor vs the lowest magnet centre above the upper sensor board",
             f"increase workspace.z_min_m to >= {reach:.4g} m", group="device"),
    ]


def rules(design: Design) -> list[Rule]:
    """Every buildability rule of ``design``, in report order (device, array, bobbin,
    standoffs, sensors, magnet holder)."""
    g = layout(design)
    return (_device_rules(design) + _array_rules(design, g) + _bobbin_rules(design, g)
            + _standoff_rules(design, g) + _sensor_rules(design, g) + _holder_rules(design))


def violations(design: Design, group: str | None = None) -> list[Rule]:
    """The rules ``design`` violates (of ``group`` 'cad' or 'device'; None: all)."""
    return [r for r in rules(design) if not r.met and group in (None, r.group)]


def sensor_saturation(design: Design, array=None) -> list[dict]:
    """The coil currents that take each Hall sensor out of its linear range (the coils' field
    alone; the magnet's adds near it, and the runner predicts both).

    The coils' field at a sensor is linear in the currents: B_s = C_s I, C_s (3, n_coils) T/A
    at ``CoilArray.sensor_poses()``, on the chip's own axes (the coupled cores included). Per
    sensor: the smallest current one coil alone needs to put some axis at ``sensors.range_t``,
    range / max_axis,k |C_s[axis, k]|, and which coil; and the current that does it with every
    coil at the same magnitude and the worst signs, range / max_axis sum_k |C_s[axis, k]|.

    Returns
    -------
    list of dict, one per sensor in the map's order: ``sensor``, ``position_m`` (3,),
    ``one_coil_a`` (A), ``coil`` (its index), ``all_coils_a`` (A).
    """
    if array is None:
        array = CoilArray.from_design(design)
    pts, frames = array.sensor_poses()
    room = headroom(array, pts, frames, design.sensors.range_t)
    return [{"sensor": s, "position_m": pos.tolist(), "one_coil_a": float(room.one_coil_a[s]),
             "coil": int(max(room.coil[s], 0)), "all_coils_a": float(room.worst_signs_a[s])}
            for s, pos in enumerate(pts)]
