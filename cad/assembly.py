"""The set of parts of a design, where each instance goes, and the interference check.

:func:`build_parts` builds each distinct part once (the bobbin is the same for all nine
coils); :func:`placements` says where every instance goes (translation + rotation about x,
mm/degrees), and :func:`assembly` puts them together as one labelled compound for STEP
and the picture. :func:`interferences` intersects every pair whose boxes overlap.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from . import parts as P
from .params import CadParams

Material = Literal["PLA", "steel", "copper", "NdFeB"]
Kind = Literal["printed", "machined", "reference"]


@dataclass(frozen=True)
class PartInfo:
    """What a part is made of and how it is made."""

    material: Material
    kind: Kind
    """'printed' parts are exported and checked against the build volume; 'machined' parts
    (the core) are exported for drawings; 'reference' parts (winding, magnet) appear only
    in the assembly."""
    color: str
    description: str


PART_INFO: dict[str, PartInfo] = {
    "bobbin": PartInfo("PLA", "printed", "#f0a030", "bobbin: printed tube + two slotted flanges"),
    "bobbin_flange": PartInfo("PLA", "printed", "#f0a030",
                              "bobbin end flange (C-shaped, wire slot), slides on the core"),
    "core": PartInfo("steel", "machined", "#5a5e66", "low-carbon steel core"),
    "frame_upper": PartInfo("PLA", "printed", "#9fb8d8", "upper frame plate (flange seats)"),
    "frame_lower": PartInfo("PLA", "printed", "#9fb8d8", "lower frame plate (flange seats)"),
    "standoff": PartInfo("PLA", "printed", "#c8c8c8", "spacer between the plates, on an M3 rod"),
    "sensor_mount_upper": PartInfo("PLA", "printed", "#7cc47c", "upper TLV493D board mount"),
    "sensor_mount_lower": PartInfo("PLA", "printed", "#7cc47c", "lower TLV493D board mount"),
    "magnet_holder": PartInfo("PLA", "printed", "#b07cd0", "finger-splint magnet holder"),
    "winding": PartInfo("copper", "reference", "#c87533", "copper winding (reference)"),
    "magnet": PartInfo("NdFeB", "reference", "#d03030", "N52 magnet (bought)"),
}


@dataclass(frozen=True)
class Placement:
    """One instance: rotate the part by ``rot_x_deg`` about the x axis, then translate."""

    part: str
    offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rot_x_deg: float = 0.0

    @property
    def label(self) -> str:
        x, y, z = self.offset_mm
        return f"{self.part}@({x:g},{y:g},{z:g})" + (f"rx{self.rot_x_deg:g}" if self.rot_x_deg else "")

    def matrix(self) -> np.ndarray:
        """4x4 homogeneous transform of this placement, shape (4, 4), mm."""
        c, s = math.cos(math.radians(self.rot_x_deg)), math.sin(math.radians(self.rot_x_deg))
        m = np.eye(4)
        m[1:3, 1:3] = [[c, -s], [s, c]]
        m[:3, 3] = self.offset_mm
        return m

    def location(self):
        from build123d import Pos, Rot

        return Pos(*self.offset_mm) * Rot(self.rot_x_deg, 0, 0)


def part_names(p: CadParams, kind: Literal["all", "exported"] = "all") -> list[str]:
    """Distinct parts of this design, in build order."""
    names = ["bobbin" if p.bobbin.mandrel == "printed_tube" else "bobbin_flange"]
    if p.core is not None:
        names.append("core")
    names += ["frame_upper", "frame_lower", "standoff", "sensor_mount_upper",
              "sensor_mount_lower", "magnet_holder"]
    if kind == "all":
        names += ["winding", "magnet"]
    return names


def build_part(p: CadParams, name: str):
    """Build one named part (build123d Part) in its local frame."""
    builders = {
        "bobbin": lambda: P.bobbin(p.bobbin),
        "bobbin_flange": lambda: P.bobbin_flange(p.bobbin),
        "core": lambda: P.core(p.core),
        "frame_upper": lambda: P.frame_plate(p.frame, "upper"),
        "frame_lower": lambda: P.frame_plate(p.frame, "lower"),
        "standoff": lambda: P.standoff(p.standoff),
        "sensor_mount_upper": lambda: P.sensor_mount(p.sensor_mount, "upper"),
        "sensor_mount_lower": lambda: P.sensor_mount(p.sensor_mount, "lower"),
        "magnet_holder": lambda: P.magnet_holder(p.magnet_holder),
        "winding": lambda: P.winding(p.bobbin),
        "magnet": lambda: P.magnet(p.magnet_holder),
    }
    return builders[name]()


def build_parts(p: CadParams, kind: Literal["all", "exported"] = "all") -> dict:
    """Every distinct part, ``{name: Part}``."""
    return {name: build_part(p, name) for name in part_names(p, kind)}


def placements(p: CadParams) -> list[Placement]:
    """Where every instance of every part goes in the array frame."""
    L = p.bobbin.winding_length_mm
    out: list[Placement] = []
    for x, y in p.grid.centres_xy_mm:
        if p.bobbin.mandrel == "printed_tube":
            out.append(Placement("bobbin", (x, y, 0.0)))
        else:
            out.append(Placement("bobbin_flange", (x, y, 0.0)))
            out.append(Placement("bobbin_flange", (x, y, -L), 180.0))
        out.append(Placement("winding", (x, y, 0.0)))
        if p.core is not None:
            out.append(Placement("core", (x, y, 0.0)))
    for name in ["frame_upper", "frame_lower", "sensor_mount_upper", "sensor_mount_lower"]:
        out.append(Placement(name))
    for x, y in p.grid.fixing_xy_mm:
        out.append(Placement("standoff", (x, y, 0.0)))
    mx, my, mz = p.magnet_centre_mm
    lift = mz - p.magnet_holder.magnet_centre_z_mm
    out.append(Placement("magnet_holder", (mx, my, lift)))
    out.append(Placement("magnet", (mx, my, lift)))
    return out


def quantities(p: CadParams) -> dict[str, int]:
    q: dict[str, int] = {}
    for pl in placements(p):
        q[pl.part] = q.get(pl.part, 0) + 1
    return q


def placed_shapes(p: CadParams, parts: dict) -> list[tuple[Placement, object]]:
    """``(placement, located copy of the part)`` for every instance."""
    return [(pl, parts[pl.part].moved(pl.location())) for pl in placements(p)]


def assembly(p: CadParams, parts: dict | None = None):
    """All instances as one labelled build123d Compound (colours set for STEP viewers)."""
    from build123d import Color, Compound

    parts = parts if parts is not None else build_parts(p)
    children = []
    for pl, shape in placed_shapes(p, parts):
        shape.label = pl.label
        shape.color = Color(PART_INFO[pl.part].color)
        children.append(shape)
    comp = Compound(children=children)
    comp.label = f"designkit assembly: {p.design_name}"
    return comp


def interferences(p: CadParams, parts: dict | None = None,
                  min_volume_mm3: float = 1e-3) -> list[tuple[str, str, float]]:
    """Pairs of instances that share volume (touching faces do not count).

    Returns
    -------
    list of (label_a, label_b, volume_mm3)
    """
    parts = parts if parts is not None else build_parts(p)
    placed = placed_shapes(p, parts)
    boxes = []
    for _, shape in placed:
        bb = shape.bounding_box()
        boxes.append((np.array(tuple(bb.min)), np.array(tuple(bb.max))))
    hits = []
    for (i, (pa, sa)), (j, (pb, sb)) in itertools.combinations(enumerate(placed), 2):
        (lo_a, hi_a), (lo_b, hi_b) = boxes[i], boxes[j]
        # boxes that only touch cannot share volume
        if np.any(np.minimum(hi_a, hi_b) - np.maximum(lo_a, lo_b) <= 1e-9):
            continue
        common = sa & sb
        vol = common.volume if common is not None else 0.0
        if vol > min_volume_mm3:
            hits.append((pa.label, pb.label, float(vol)))
    return hits
