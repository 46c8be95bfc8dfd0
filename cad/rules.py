"""Design-rule checks on the part parameters, run before any part is built or file written.

Each rule is arithmetic on :class:`cad.params.CadParams` (no build123d), so a bad design
fails in microseconds with a message that names the numbers and the fix. The geometric
interference check of the built assembly (:func:`cad.assembly.interferences`) backs these
rules up.
"""

from __future__ import annotations

import itertools
import math

from designkit.errors import DesignRuleError

from .params import CadParams


def violations(p: CadParams) -> list[str]:
    """Every violated rule as a sentence that suggests the fix (empty list: all good)."""
    out: list[str] = []
    w = p.printer.min_wall_mm
    b, f, g, s, h = p.bobbin, p.frame, p.grid, p.sensor_mount, p.magnet_holder

    def wall(what: str, value: float, fix: str) -> None:
        if not value >= w:
            out.append(f"{what} is {value:.3g} mm, thinner than the printer minimum wall "
                        f"{w:g} mm: {fix}.")

    # -- coils and bobbins at the pitch ---------------------------------------------------
    pairs = [(i, j) for i, j in itertools.combinations(range(len(g.centres_xy_mm)), 2)]
    if pairs:
        i, j, dist = min(((i, j, math.dist(g.centres_xy_mm[i], g.centres_xy_mm[j]))
                          for i, j in pairs), key=lambda t: t[2])
        if 2 * b.winding_outer_radius_mm > dist:
            out.append(f"coils {i} and {j} overlap: 2 x winding outer radius "
                       f"{2 * b.winding_outer_radius_mm:.4g} mm > pitch {dist:.4g} mm; increase "
                       f"array.pitch_m or reduce coil.outer_radius_m.")
        elif 2 * b.flange_radius_mm > dist:
            out.append(f"bobbin flanges of coils {i} and {j} overlap: 2 x flange radius "
                       f"{2 * b.flange_radius_mm:.4g} mm > pitch {dist:.4g} mm; increase "
                       f"array.pitch_m to >= {2 * b.flange_radius_mm / 1000:.4g} m or reduce "
                       f"flange_lip_mm / coil.outer_radius_m.")
        else:
            wall("frame web between neighbouring pockets", dist - 2 * f.pocket_radius_mm,
                 f"increase array.pitch_m to >= {(2 * f.pocket_radius_mm + w) / 1000:.4g} m "
                 "or reduce coil.outer_radius_m / flange_lip_mm")

    # -- bobbin walls -----------------------------------------------------------------------
    if b.mandrel == "printed_tube":
        if p.core is not None:
            fix = (f"reduce core.radius_m to <= {(b.winding_inner_radius_mm - w - (b.bore_radius_mm - p.core.radius_mm)) / 1000:.4g} m, "
                   "increase coil.inner_radius_m, or use mandrel 'core' (wind on the insulated core)")
        else:
            fix = "increase air_core_tube_wall_mm"
        wall("bobbin tube wall (winding inner radius - bore)", b.tube_wall_mm, fix)
    wall("bobbin flange thickness", b.flange_thickness_mm, "increase flange_thickness_mm")
    wall("bobbin flange lip (flange radius - winding outer radius)",
         b.flange_radius_mm - b.winding_outer_radius_mm, "increase flange_lip_mm")
    if p.core is not None and b.bore_radius_mm < p.core.radius_mm:
        out.append(f"bobbin bore radius {b.bore_radius_mm:.4g} mm is smaller than the core radius "
                   f"{p.core.radius_mm:.4g} mm: set core_clearance_mm >= 0.")
    if b.slot_width_mm >= 2 * b.bore_radius_mm:
        out.append(f"wire slot {b.slot_width_mm:.3g} mm is wider than the bore: check wire.insulated_diameter_m.")

    # -- frame plates ---------------------------------------------------------------------
    wall("frame plate above the flange pocket", f.thickness_mm - f.pocket_depth_mm,
         "increase plate_thickness_mm or reduce flange_thickness_mm")
    wall("frame lip holding the flange (pocket radius - through hole)",
         f.pocket_radius_mm - f.through_radius_mm,
         "increase flange_lip_mm; the flange must be wider than the core hole")
    xs = [c[0] for c in g.centres_xy_mm]
    ys = [c[1] for c in g.centres_xy_mm]
    wall("frame edge beside the outer pockets",
         min(g.footprint_x_mm / 2 - max(map(abs, xs)), g.footprint_y_mm / 2 - max(map(abs, ys)))
         - f.pocket_radius_mm, "the footprint grows automatically; check pocket_clearance_mm")
    wall("standoff wall (outer radius - M3 hole)",
         p.standoff.outer_radius_mm - p.standoff.hole_radius_mm, "increase standoff_outer_radius_mm")
    wall("plate edge beside the fixing holes", g.fixing_inset_mm - p.standoff.outer_radius_mm,
         "increase fixing_inset_mm or reduce standoff_outer_radius_mm")
    for k, (fx, fy) in enumerate(g.fixing_xy_mm):
        near = min(math.dist((fx, fy), c) for c in g.centres_xy_mm)
        gap = near - p.standoff.outer_radius_mm - f.pocket_radius_mm
        if not gap >= w:
            out.append(f"standoff {k} at ({fx:.4g}, {fy:.4g}) mm leaves {gap:.3g} mm to the nearest "
                       f"flange pocket (minimum wall {w:g} mm): reduce fixing_inset_mm or "
                       "standoff_outer_radius_mm, or increase array.pitch_m.")

    # -- sensors: above the bobbin/core and the frame, for both arrays -----------------------
    # How far the coil stack reaches beyond each winding end plane, mm.
    reach = {"upper": (f.pocket_depth_mm, "top bobbin flange"),
             "lower": (f.pocket_depth_mm, "bottom bobbin flange")}
    if p.core is not None:
        core_up = p.core.top_z_mm
        core_down = -b.winding_length_mm - p.core.bottom_z_mm
        if core_up > reach["upper"][0]:
            reach["upper"] = (core_up, "core top")
        if core_down > reach["lower"][0]:
            reach["lower"] = (core_down, "core bottom")
    half_board = s.board_thickness_mm / 2
    inside = False
    for side, (level, what) in reach.items():
        if s.sensor_z_mm - half_board < level:
            inside = True
            out.append(f"{side} sensors at {s.sensor_z_mm:.4g} mm from the coil end would sit inside "
                       f"the bobbin/core (the {what} reaches {level:.4g} mm): increase "
                       f"sensors.offset_m to >= {(level + half_board) / 1000:.4g} m or shorten the core.")
    obstacle = max(f.thickness_mm, reach["upper"][0], reach["lower"][0])
    if not inside and s.bottom_z_mm < obstacle:
        need = (obstacle + s.floor_thickness_mm + half_board) / 1000
        out.append(f"sensor mount plate (underside {s.bottom_z_mm:.4g} mm from the coil end) would "
                   f"cut into the frame plate/core (up to {obstacle:.4g} mm): increase "
                   f"sensors.offset_m to >= {need:.4g} m, or reduce plate_thickness_mm / mount_floor_mm.")
    wall("sensor mount floor", s.floor_thickness_mm, "increase mount_floor_mm")
    pocket_half = max(s.board_size_mm) / 2 + s.pocket_clearance_mm
    if len(g.centres_xy_mm) > 1:
        wall("sensor mount web between board pockets", g.pitch_mm - 2 * pocket_half,
             "use a smaller sensor board (board_size_mm) or increase array.pitch_m")

    # -- magnet holder ------------------------------------------------------------------------
    if h.pocket_radius_mm < h.magnet_radius_mm or h.pocket_depth_mm < h.magnet_length_mm:
        out.append(f"magnet pocket ({2 * h.pocket_radius_mm:.4g} mm diameter x {h.pocket_depth_mm:.4g} mm) "
                   f"is smaller than the magnet ({2 * h.magnet_radius_mm:.4g} x {h.magnet_length_mm:.4g} mm): "
                   "set press_fit_clearance_mm >= 0 (0.05 mm is a press fit on FDM printers, whose "
                   "holes print undersize).")
    wall("magnet boss wall", h.boss_wall_mm, "increase boss_wall_mm")
    wall("magnet holder floor (between magnet and finger)", h.floor_thickness_mm,
         "increase holder_floor_mm")
    wall("finger ring wall", h.ring_wall_mm, "increase ring_wall_mm")
    if h.ring_width_mm < 2 * h.boss_radius_mm:
        out.append(f"finger ring width {h.ring_width_mm:.4g} mm is narrower than the magnet boss "
                   f"({2 * h.boss_radius_mm:.4g} mm): increase ring_width_mm to >= "
                   f"{2 * h.boss_radius_mm:.4g}.")
    if not h.finger_diameter_mm > 0:
        out.append(f"finger_diameter_mm must be > 0; instead received {h.finger_diameter_mm!r}.")
    return out


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
