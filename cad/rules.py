"""Design-rule checks on the part parameters, run before any part is built or file written.

Each rule is arithmetic on :class:`cad.params.CadParams` (no build123d), so a bad design
fails at once with a message that names the numbers (mm) and the fix. :data:`RULES` lists
them in the order their messages appear; the rationale of each is in docs/cad.md. The
geometric interference check of the built assembly (:func:`cad.assembly.interferences`)
backs these rules up.
"""

from __future__ import annotations

import itertools
import math

from designkit.errors import DesignRuleError

from .params import CadParams


def _wall(p: CadParams, what: str, value: float, fix: str) -> list[str]:
    """A message when the wall ``value`` (mm) is thinner than the printer's minimum wall."""
    w = p.printer.min_wall_mm
    if not value >= w:
        return [f"{what} is {value:.3g} mm, thinner than the printer minimum wall "
                f"{w:g} mm: {fix}."]
    return []


def coils_at_pitch(p: CadParams) -> list[str]:
    """The closest two coils: windings, then flanges, then the frame web between pockets."""
    b, f, g, w = p.bobbin, p.frame, p.grid, p.printer.min_wall_mm
    pairs = [(i, j) for i, j in itertools.combinations(range(len(g.centres_xy_mm)), 2)]
    if not pairs:
        return []
    i, j, dist = min(((i, j, math.dist(g.centres_xy_mm[i], g.centres_xy_mm[j]))
                      for i, j in pairs), key=lambda t: t[2])
    if 2 * b.winding_outer_radius_mm > dist:
        return [f"coils {i} and {j} overlap: 2 x winding outer radius "
                f"{2 * b.winding_outer_radius_mm:.4g} mm > pitch {dist:.4g} mm; increase "
                f"array.pitch_m or reduce coil.outer_radius_m."]
    if 2 * b.flange_radius_mm > dist:
        return [f"bobbin flanges of coils {i} and {j} overlap: 2 x flange radius "
                f"{2 * b.flange_radius_mm:.4g} mm > pitch {dist:.4g} mm; increase "
                f"array.pitch_m to >= {2 * b.flange_radius_mm / 1000:.4g} m or reduce "
                f"flange_lip_mm / coil.outer_radius_m."]
    return _wall(p, "frame web between neighbouring pockets", dist - 2 * f.pocket_radius_mm,
                 f"increase array.pitch_m to >= {(2 * f.pocket_radius_mm + w) / 1000:.4g} m "
                 "or reduce coil.outer_radius_m / flange_lip_mm")


def bobbin_walls(p: CadParams) -> list[str]:
    """Tube wall, flange thickness and lip, bore against core, wire slot against bore."""
    b, w = p.bobbin, p.printer.min_wall_mm
    out: list[str] = []
    if b.mandrel == "printed_tube":
        if p.core is not None:
            fix = (f"reduce core.radius_m to <= {(b.winding_inner_radius_mm - w - (b.bore_radius_mm - p.core.radius_mm)) / 1000:.4g} m, "
                   "increase coil.inner_radius_m, or use mandrel 'core' (wind on the insulated core)")
        else:
            fix = "increase air_core_tube_wall_mm"
        out += _wall(p, "bobbin tube wall (winding inner radius - bore)", b.tube_wall_mm, fix)
    out += _wall(p, "bobbin flange thickness", b.flange_thickness_mm,
                 "increase flange_thickness_mm")
    out += _wall(p, "bobbin flange lip (flange radius - winding outer radius)",
                 b.flange_radius_mm - b.winding_outer_radius_mm, "increase flange_lip_mm")
    if p.core is not None and b.bore_radius_mm < p.core.radius_mm:
        out.append(f"bobbin bore radius {b.bore_radius_mm:.4g} mm is smaller than the core radius "
                   f"{p.core.radius_mm:.4g} mm: set core_clearance_mm >= 0.")
    if b.slot_width_mm >= 2 * b.bore_radius_mm:
        out.append(f"wire slot {b.slot_width_mm:.3g} mm is wider than the bore: check wire.insulated_diameter_m.")
    return out


def frame_plates(p: CadParams) -> list[str]:
    """Plate above the pocket, lip holding the flange, edge beside the outer pockets."""
    f, g = p.frame, p.grid
    out = _wall(p, "frame plate above the flange pocket", f.thickness_mm - f.pocket_depth_mm,
                "increase plate_thickness_mm or reduce flange_thickness_mm")
    out += _wall(p, "frame lip holding the flange (pocket radius - through hole)",
                 f.pocket_radius_mm - f.through_radius_mm,
                 "increase flange_lip_mm; the flange must be wider than the core hole")
    xs = [c[0] for c in g.centres_xy_mm]
    ys = [c[1] for c in g.centres_xy_mm]
    out += _wall(p, "frame edge beside the outer pockets",
                 min(g.footprint_x_mm / 2 - max(map(abs, xs)),
                     g.footprint_y_mm / 2 - max(map(abs, ys)))
                 - f.pocket_radius_mm, "the footprint grows automatically; check pocket_clearance_mm")
    return out


def standoffs(p: CadParams) -> list[str]:
    """Standoff wall, plate edge beside the fixing holes, room to the nearest flange pocket."""
    f, g, w = p.frame, p.grid, p.printer.min_wall_mm
    out = _wall(p, "standoff wall (outer radius - M3 hole)",
                p.standoff.outer_radius_mm - p.standoff.hole_radius_mm,
                "increase standoff_outer_radius_mm")
    out += _wall(p, "plate edge beside the fixing holes",
                 g.fixing_inset_mm - p.standoff.outer_radius_mm,
                 "increase fixing_inset_mm or reduce standoff_outer_radius_mm")
    for k, (fx, fy) in enumerate(g.fixing_xy_mm):
        near = min(math.dist((fx, fy), c) for c in g.centres_xy_mm)
        gap = near - p.standoff.outer_radius_mm - f.pocket_radius_mm
        if not gap >= w:
            out.append(f"standoff {k} at ({fx:.4g}, {fy:.4g}) mm leaves {gap:.3g} mm to the nearest "
                       f"flange pocket (minimum wall {w:g} mm): reduce fixing_inset_mm or "
                       "standoff_outer_radius_mm, or increase array.pitch_m.")
    return out


def _coil_stack_reach(p: CadParams) -> dict[str, tuple[float, str]]:
    """How far the coil stack reaches beyond each winding end plane (mm) and what reaches."""
    b, f = p.bobbin, p.frame
    reach = {"upper": (f.pocket_depth_mm, "top bobbin flange"),
             "lower": (f.pocket_depth_mm, "bottom bobbin flange")}
    if p.core is not None:
        core_up = p.core.top_z_mm
        core_down = -b.winding_length_mm - p.core.bottom_z_mm
        if core_up > reach["upper"][0]:
            reach["upper"] = (core_up, "core top")
        if core_down > reach["lower"][0]:
            reach["lower"] = (core_down, "core bottom")
    return reach


def sensor_height(p: CadParams) -> list[str]:
    """Both sensor arrays above the bobbin/core, and their mount plate above the frame."""
    s, f = p.sensor_mount, p.frame
    reach = _coil_stack_reach(p)
    half_board = s.board_thickness_mm / 2
    out: list[str] = []
    for side, (level, what) in reach.items():
        if s.sensor_z_mm - half_board < level:
            out.append(f"{side} sensors at {s.sensor_z_mm:.4g} mm from the coil end would sit inside "
                       f"the bobbin/core (the {what} reaches {level:.4g} mm): increase "
                       f"sensors.offset_m to >= {(level + half_board) / 1000:.4g} m or shorten the core.")
    obstacle = max(f.thickness_mm, reach["upper"][0], reach["lower"][0])
    if not out and s.bottom_z_mm < obstacle:
        need = (obstacle + s.floor_thickness_mm + half_board) / 1000
        out.append(f"sensor mount plate (underside {s.bottom_z_mm:.4g} mm from the coil end) would "
                   f"cut into the frame plate/core (up to {obstacle:.4g} mm): increase "
                   f"sensors.offset_m to >= {need:.4g} m, or reduce plate_thickness_mm / mount_floor_mm.")
    return out


def sensor_mount(p: CadParams) -> list[str]:
    """Mount floor and the web between neighbouring board pockets."""
    s, g = p.sensor_mount, p.grid
    out = _wall(p, "sensor mount floor", s.floor_thickness_mm, "increase mount_floor_mm")
    pocket_half = max(s.board_size_mm) / 2 + s.pocket_clearance_mm
    if len(g.centres_xy_mm) > 1:
        out += _wall(p, "sensor mount web between board pockets", g.pitch_mm - 2 * pocket_half,
                     "use a smaller sensor board (board_size_mm) or increase array.pitch_m")
    return out


def magnet_holder(p: CadParams) -> list[str]:
    """Magnet pocket, boss, floor and ring walls, ring width, finger diameter."""
    h = p.magnet_holder
    out: list[str] = []
    if h.pocket_radius_mm < h.magnet_radius_mm or h.pocket_depth_mm < h.magnet_length_mm:
        out.append(f"magnet pocket ({2 * h.pocket_radius_mm:.4g} mm diameter x {h.pocket_depth_mm:.4g} mm) "
                   f"is smaller than the magnet ({2 * h.magnet_radius_mm:.4g} x {h.magnet_length_mm:.4g} mm): "
                   "set press_fit_clearance_mm >= 0 (0.05 mm is a press fit on FDM printers, whose "
                   "holes print undersize).")
    out += _wall(p, "magnet boss wall", h.boss_wall_mm, "increase boss_wall_mm")
    out += _wall(p, "magnet holder floor (between magnet and finger)", h.floor_thickness_mm,
                 "increase holder_floor_mm")
    out += _wall(p, "finger ring wall", h.ring_wall_mm, "increase ring_wall_mm")
    if h.ring_width_mm < 2 * h.boss_radius_mm:
        out.append(f"finger ring width {h.ring_width_mm:.4g} mm is narrower than the magnet boss "
                   f"({2 * h.boss_radius_mm:.4g} mm): increase ring_width_mm to >= "
                   f"{2 * h.boss_radius_mm:.4g}.")
    if not h.finger_diameter_mm > 0:
        out.append(f"finger_diameter_mm must be > 0; instead received {h.finger_diameter_mm!r}.")
    return out


RULES = (coils_at_pitch, bobbin_walls, frame_plates, standoffs, sensor_height, sensor_mount,
         magnet_holder)
"""Every rule: ``rule(p) -> list of messages`` (empty: the rule holds), in report order."""


def violations(p: CadParams) -> list[str]:
    """Every violated rule as a sentence that suggests the fix (empty list: all good)."""
    return [message for rule in RULES for message in rule(p)]


def check_rules(p: CadParams) -> None:
    """Raise :class:`DesignRuleError` listing every violated rule (with its fix), or return."""
    bad = violations(p)
    if bad:
        raise DesignRuleError(f"{len(bad)} design rule(s) violated for '{p.design_name}':\n  - "
                              + "\n  - ".join(bad))


def fit_in_build_volume(size_mm: tuple[float, float, float],
                        build_mm: tuple[float, float, float]) -> tuple[int, int, int] | None:
    """An axis order that fits the part's box in the build volume, or None.

    Parts may be laid down in any of the 6 axis-aligned orientations; rotations about z
    by other angles are not tried (conservative).

    Returns
    -------
    tuple of int or None
        ``order`` such that ``size_mm[order[k]] <= build_mm[k]`` for k = 0, 1, 2.
    """
    for order in itertools.permutations(range(3)):
        if all(size_mm[order[k]] <= build_mm[k] for k in range(3)):
            return order
    return None
