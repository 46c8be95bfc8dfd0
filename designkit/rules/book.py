"""The rules of a design, in report order: device, array, bobbins (per coil type), standoffs,
sensors (per coil type), magnet holder."""

from __future__ import annotations

from ..design import Design
from ..model import electrical as el
from .geometry import MAX_OVERHANG_DEG, Assembly, CoilType, assembly
from .clearance import board_rules, pair_rules, standoff_rule
from .driver import driver_rules
from .reach import design_point_floor_m, reachable_height_m
from .rule import Rule, wall


def _named(name: str, t: CoilType, several: bool) -> str:
    """A per-type rule's name: plain for the design's own coil, ``name@groups[g]`` for a
    group's when the design has several types."""
    return name if not (several and t.where) else f"{name}@{t.where.rstrip('.')}"


def device_rules(d: Design, asm: Assembly) -> list[Rule]:
    """Winding fit (per type), the driver's ratings, the magnet above the boards."""
    w = d.wire
    several = len(asm.types) > 1
    out = []
    for t in asm.types:
        c = t.coil
        fit = el.turns_from_geometry(c.inner_radius_m, c.outer_radius_m, c.length_m,
                                     w.insulated_diameter_m, w.packing)
        out.append(Rule(_named("turns", t, several), c.turns, fit, "turns", "upper",
                        (t.key("coil.turns"), "wire.insulated_diameter_m"),
                        f"turns in the winding section ({w.packing} packing)",
                        f"reduce {t.key('coil.turns')} to <= {fit} or enlarge the winding "
                        "section", 0.0, "device"))
    point, floor = design_point_floor_m(d), reachable_height_m(d)
    return out + [
        *driver_rules(d),
        Rule("magnet_at_design_height", d.optimize.height_m, point, "m", "lower",
             ("optimize.height_m", "sensors.offset_m"),
             "design height vs the lowest magnet centre above the sensor boards and frame there",
             f"increase optimize.height_m to >= {point:.4g} m", group="device"),
        Rule("workspace_z_min_m", d.workspace.z_min_m, floor, "m", "lower",
             ("workspace.z_min_m", "sensors.offset_m"),
             "workspace floor vs the lowest magnet centre above the sensor boards and frame "
             "anywhere over the workspace",
             f"increase workspace.z_min_m to >= {floor:.4g} m", group="device"),
    ]


def _bobbin_rules(d: Design, t: CoilType, several: bool) -> list[Rule]:
    """Tube wall (a printed-tube mandrel), frame lip, core clearance of one coil type."""
    c = d.cad
    out = []
    if t.mandrel == "printed_tube":
        most = t.coil.inner_radius_m - c.min_wall_m - c.core_clearance_m
        fix = ("increase cad.air_core_tube_wall_m" if t.core is None else
               f"reduce {t.key('core.radius_m')} to <= {most:.4g} m, increase "
               f"{t.key('coil.inner_radius_m')}, or set cad.mandrel = 'core' (wind on the "
               "insulated core)")
        out.append(wall(_named("bobbin_tube_wall", t, several),
                        "bobbin tube wall (winding inner radius - bore)",
                        t.coil.inner_radius_m - t.bore_radius_m, c.min_wall_m,
                        (t.key("core.radius_m"), t.key("coil.inner_radius_m"), "cad.mandrel"),
                        fix))
    return out


def printed_rules(d: Design, asm: Assembly) -> list[Rule]:
    """Bobbins of every type, flanges, frame plate and lip, core clearance; the overhang of
    tilted seats."""
    c = d.cad
    several = len(asm.types) > 1
    out = []
    for t in asm.types:
        out += _bobbin_rules(d, t, several)
    out += [
        wall("flange_thickness", "bobbin flange thickness", c.flange_thickness_m, c.min_wall_m,
             ("cad.flange_thickness_m",), "increase cad.flange_thickness_m"),
        wall("flange_lip", "bobbin flange lip (flange radius - winding outer radius)",
             c.flange_lip_m, c.min_wall_m, ("cad.flange_lip_m",), "increase cad.flange_lip_m"),
        wall("frame_plate_above_pocket", "frame plate above the flange pocket",
             c.plate_thickness_m - c.flange_thickness_m, c.min_wall_m,
             ("cad.plate_thickness_m", "cad.flange_thickness_m"),
             "increase cad.plate_thickness_m or reduce cad.flange_thickness_m"),
    ]
    for t in asm.types:
        out.append(wall(_named("frame_lip", t, several),
                        "frame lip holding the flange (pocket radius - core hole)",
                        t.pocket_radius_m - t.bore_radius_m, c.min_wall_m, ("cad.flange_lip_m",),
                        "increase cad.flange_lip_m; the flange must be wider than the core "
                        "hole"))
    for t in asm.types:
        if t.core is not None:
            out.append(Rule(_named("core_clearance", t, several), t.bore_radius_m,
                            t.core.radius_m, "m", "lower", ("cad.core_clearance_m",),
                            "bobbin bore radius around the core", "set cad.core_clearance_m >= 0"))
    if asm.max_tilt_deg > 0.0:
        tilt_keys = {"ring": ("array.tilt_deg",), "free": ("array.axes",)}.get(
            d.array.kind, ())
        out.append(Rule("seat_overhang", asm.max_tilt_deg, MAX_OVERHANG_DEG, "deg", "upper",
                        tilt_keys, "tilt of the frame plates' bores (printed pockets up, a bore "
                        "overhangs by its coil's tilt)",
                        f"tilt the coils by at most {MAX_OVERHANG_DEG:g} deg "
                        f"({' / '.join(tilt_keys) or 'array'}): an FDM printer makes steeper "
                        "overhangs only with support", 1e-9))
    return out


def standoff_rules(d: Design, asm: Assembly) -> list[Rule]:
    """Standoff wall, plate edge beside the fixing holes, room to the nearest flange pocket."""
    c = d.cad
    return [
        wall("standoff_wall", "standoff wall (outer radius - fixing hole)",
             c.standoff_outer_radius_m - c.fixing_hole_radius_m, c.min_wall_m,
             ("cad.standoff_outer_radius_m", "cad.fixing_hole_radius_m"),
             "increase cad.standoff_outer_radius_m"),
        wall("fixing_edge", "plate edge beside the fixing holes",
             c.fixing_inset_m - c.standoff_outer_radius_m, c.min_wall_m,
             ("cad.fixing_inset_m", "cad.standoff_outer_radius_m"),
             "increase cad.fixing_inset_m or reduce cad.standoff_outer_radius_m"),
        standoff_rule(d, asm),
    ]


def sensor_rules(d: Design, asm: Assembly) -> list[Rule]:
    """Both sensor boards clear of each type's flanges/core; the holder clear of the frame
    plate and cores (a mount plate) or a cap tall and wide enough (caps)."""
    if asm.sensor_holder == "none":
        return []
    c = d.cad
    hb = c.board_thickness_m / 2
    several = len(asm.types) > 1
    out = []
    for t in asm.types:
        for side, (level, what) in (("upper", t.reach_upper_m), ("lower", t.reach_lower_m)):
            out.append(Rule(_named(f"{side}_sensor_board", t, several), d.sensors.offset_m,
                            level + hb, "m", "lower",
                            ("sensors.offset_m", t.key("core.length_m"), t.key("core.offset_m")),
                            f"{side} sensor board above the bobbin/core (the {what} reaches "
                            f"{level * 1e3:.4g} mm)", f"increase sensors.offset_m to >= "
                            f"{level + hb:.4g} m or shorten the core"))
    for t in asm.types:
        keys = ("sensors.offset_m", "cad.mount_floor_m", t.key("core.length_m"),
                t.key("core.offset_m"))
        if asm.sensor_holder == "mount":
            obstacle, what = max((c.plate_thickness_m, "frame plate"), t.reach_upper_m,
                                 t.reach_lower_m)
            keys = keys[:1] + ("cad.plate_thickness_m",) + keys[1:]
            where = "sensor mount plate above the"
        else:
            obstacle, what = max(t.reach_upper_m, t.reach_lower_m)
            where = "sensor cap (board pocket and floor) above the"
        need = obstacle + c.mount_floor_m + hb
        out.append(Rule(_named("sensor_mount", t, several), d.sensors.offset_m, need, "m",
                        "lower", keys, f"{where} {what} (up to {obstacle * 1e3:.4g} mm)",
                        f"increase sensors.offset_m to >= {need:.4g} m, reduce the core's "
                        "protrusion, or reduce "
                        + ("cad.plate_thickness_m / " if asm.sensor_holder == "mount" else "")
                        + "cad.mount_floor_m"))
    out.append(wall("sensor_mount_floor", "sensor mount floor", c.mount_floor_m, c.min_wall_m,
                    ("cad.mount_floor_m",), "increase cad.mount_floor_m"))
    if asm.sensor_holder == "caps":
        half_diagonal = 2 ** 0.5 * (c.board_width_m / 2 + c.board_clearance_m)
        for t in asm.types:
            out.append(wall(_named("sensor_cap_wall", t, several),
                            "sensor cap wall around the board pocket (cap radius = bore - "
                            "press fit)", t.bore_radius_m - c.press_fit_clearance_m
                            - half_diagonal, c.min_wall_m,
                            ("cad.board_width_m", "cad.board_clearance_m",
                             t.key("core.radius_m")),
                            "use a smaller sensor board (cad.board_width_m) or a wider core "
                            "bore"))
    return out


def holder_rules(d: Design) -> list[Rule]:
    """Magnet pocket, boss, floor and ring walls, ring width of the finger splint."""
    c = d.cad
    boss = d.magnet.radius_m + c.press_fit_clearance_m + c.boss_wall_m
    return [
        Rule("magnet_pocket", c.press_fit_clearance_m, 0.0, "m", "lower",
             ("cad.press_fit_clearance_m",), "magnet pocket oversize (pocket smaller than the "
             "magnet when < 0)", "set cad.press_fit_clearance_m >= 0 (0.05 mm is a press fit "
             "on FDM printers, whose holes print undersize)"),
        wall("magnet_boss_wall", "magnet boss wall", c.boss_wall_m, c.min_wall_m,
             ("cad.boss_wall_m",), "increase cad.boss_wall_m"),
        wall("magnet_holder_floor", "magnet holder floor (between magnet and finger)",
             c.holder_floor_m, c.min_wall_m, ("cad.holder_floor_m",),
             "increase cad.holder_floor_m"),
        wall("finger_ring_wall", "finger ring wall", c.ring_wall_m, c.min_wall_m,
             ("cad.ring_wall_m",), "increase cad.ring_wall_m"),
        Rule("finger_ring_width", c.ring_width_m, 2 * boss, "m", "lower", ("cad.ring_width_m",),
             "finger ring width around the magnet boss",
             f"increase cad.ring_width_m to >= {2 * boss:.4g} m"),
    ]


def rules(design: Design) -> list[Rule]:
    """Every buildability rule of ``design``, in report order (device, array, bobbins,
    standoffs, sensors, magnet holder)."""
    asm = assembly(design)
    return (device_rules(design, asm) + pair_rules(design, asm) + board_rules(design, asm)
            + printed_rules(design, asm) + standoff_rules(design, asm)
            + sensor_rules(design, asm) + holder_rules(design))


def violations(design: Design, group: str | None = None) -> list[Rule]:
    """The rules ``design`` violates (of ``group`` 'cad' or 'device'; None: all)."""
    return [r for r in rules(design) if not r.met and group in (None, r.group)]



