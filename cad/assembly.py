"""The set of parts of a design, where each instance goes, and the interference check.

:func:`build_parts` builds each distinct part once (the bobbin of a coil type is the same for
all its coils); :func:`placements` says where every instance goes (a rotation, each coil's
frame for its parts, then a translation, mm), and :func:`assembly` puts them together as one
labelled compound for STEP and the picture. :func:`interferences` intersects every pair whose
boxes overlap.
"""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass
from typing import Literal

import numpy as np

from . import parts as P
from .params import CadParams, turn_about

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
    "frame_upper": PartInfo("PLA", "printed", "#9fb8d8",
                            "upper frame plate (flange seats; printed turned over)"),
    "frame_lower": PartInfo("PLA", "printed", "#9fb8d8", "lower frame plate (flange seats)"),
    "standoff": PartInfo("PLA", "printed", "#c8c8c8", "spacer between the plates, on an M3 rod"),
    "sensor_mount_upper": PartInfo("PLA", "printed", "#7cc47c", "upper TLV493D board mount"),
    "sensor_mount_lower": PartInfo("PLA", "printed", "#7cc47c", "lower TLV493D board mount"),
    "sensor_cap": PartInfo("PLA", "printed", "#7cc47c",
                           "TLV493D board cap on a coil end, pressed into the plate's bore"),
    "sensor_cap_upper": PartInfo("PLA", "printed", "#7cc47c",
                                 "TLV493D board cap on a coil's top end"),
    "sensor_cap_lower": PartInfo("PLA", "printed", "#7cc47c",
                                 "TLV493D board cap on a coil's bottom end"),
    "magnet_holder": PartInfo("PLA", "printed", "#b07cd0", "finger-splint magnet holder"),
    "winding": PartInfo("copper", "reference", "#c87533", "copper winding (reference)"),
    "magnet": PartInfo("NdFeB", "reference", "#d03030", "N52 magnet (bought)"),
}
"""What each kind of part is; a coil type's parts (``bobbin_t2``) and a plate's printed
segments (``frame_lower_s3``) are their kind's (:func:`part_info`)."""

_SUFFIX = re.compile(r"(_t\d+)?(_s\d+|_segment)?$")


def part_info(name: str) -> PartInfo:
    """The :class:`PartInfo` of a part name, its coil-type and segment suffixes aside."""
    return PART_INFO[_SUFFIX.sub("", name, count=1)]


@dataclass(frozen=True)
class Placement:
    """One instance: rotate the part by ``rotation`` (3 x 3, columns: the part's local axes in
    the array frame; None: the identity), then translate by ``offset_mm``."""

    part: str
    offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple | None = None

    @property
    def label(self) -> str:
        x, y, z = self.offset_mm
        tag = ""
        if self.rotation is not None:
            r = np.asarray(self.rotation)
            tag = "r" + ",".join(f"{q:.3g}" for q in r[:, 2]) + "/" + ",".join(
                f"{q:.3g}" for q in r[:, 0])
        return f"{self.part}@({x:g},{y:g},{z:g})" + tag

    def matrix(self) -> np.ndarray:
        """4x4 homogeneous transform of this placement, shape (4, 4), mm."""
        m = np.eye(4)
        if self.rotation is not None:
            m[:3, :3] = np.asarray(self.rotation, dtype=float)
        m[:3, 3] = self.offset_mm
        return m

    def location(self):
        from build123d import Location, Plane

        r = np.eye(3) if self.rotation is None else np.asarray(self.rotation, dtype=float)
        return Location(Plane(origin=tuple(map(float, self.offset_mm)), x_dir=tuple(r[:, 0]),
                              z_dir=tuple(r[:, 2])))


TURN_OVER = ((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0))
"""Rotation of 180 degrees about the local x axis: an upper part as the lower one."""


def _pieces(p: CadParams, name: str):
    """(base name, its plate or mount parameters) of a frame plate or sensor mount."""
    if name.startswith("frame_"):
        return name, (p.upper if name == "frame_upper" else p.lower)
    return name, p.sensor_mount


def _piece_names(p: CadParams, name: str) -> list[str]:
    """The parts of a frame plate or sensor mount: itself, its one segment printed n times,
    or each segment."""
    base, plate = _pieces(p, name)
    if plate.segments_identical:
        return [f"{base}_segment"]
    return [f"{base}_s{k + 1}" for k in range(len(plate.segments))] or [base]


def _piece_placements(p: CadParams, name: str) -> list[Placement]:
    """Where a plate's or mount's parts go: built in place; a repeated segment turned about
    the plate's centre."""
    base, plate = _pieces(p, name)
    names = _piece_names(p, name)
    if not plate.segments_identical:
        return [Placement(n) for n in names]
    out = []
    for a, _ in plate.segments:
        r, off = turn_about(plate.centre_xy_mm, a - plate.segments[0][0])
        out.append(Placement(names[0], tuple(map(float, off)), tuple(map(tuple, r))))
    return out


def _cap_names(p: CadParams, t) -> list[str]:
    if t.cap_upper is None:
        return []
    if t.cap_upper == t.cap_lower:
        return ["sensor_cap" + t.suffix]
    return ["sensor_cap_upper" + t.suffix, "sensor_cap_lower" + t.suffix]


def part_names(p: CadParams, kind: Literal["all", "exported"] = "all") -> list[str]:
    """Distinct parts of this design, in build order."""
    names = []
    for t in p.types:
        names.append(("bobbin" if t.bobbin.mandrel == "printed_tube" else "bobbin_flange")
                     + t.suffix)
        if t.core is not None:
            names.append("core" + t.suffix)
    names += _piece_names(p, "frame_upper") + _piece_names(p, "frame_lower") + ["standoff"]
    if p.sensor_holder == "mount":
        names += _piece_names(p, "sensor_mount_upper") + _piece_names(p, "sensor_mount_lower")
    for t in p.types:
        names += _cap_names(p, t)
    names.append("magnet_holder")
    if kind == "all":
        names += ["winding" + t.suffix for t in p.types] + ["magnet"]
    return names


def build_part(p: CadParams, name: str):
    """Build one named part (build123d Part) in its local frame."""
    base = _SUFFIX.sub("", name, count=1)
    t = next((t for t in p.types if t.suffix and name.endswith(t.suffix)), p.types[0])
    seg = re.search(r"_s(\d+)$", name)
    piece = 0 if name.endswith("_segment") else None if seg is None else int(seg.group(1)) - 1
    if base in ("frame_upper", "frame_lower"):
        return P.frame_plate(p.upper if base == "frame_upper" else p.lower, piece)
    if base in ("sensor_mount_upper", "sensor_mount_lower"):
        return P.sensor_mount(p.sensor_mount, base.rsplit("_", 1)[1], piece)
    builders = {
        "bobbin": lambda: P.bobbin(t.bobbin),
        "bobbin_flange": lambda: P.bobbin_flange(t.bobbin),
        "core": lambda: P.core(t.core),
        "standoff": lambda: P.standoff(p.standoff),
        "sensor_cap": lambda: P.sensor_cap(t.cap_upper),
        "sensor_cap_upper": lambda: P.sensor_cap(t.cap_upper),
        "sensor_cap_lower": lambda: P.sensor_cap(t.cap_lower),
        "magnet_holder": lambda: P.magnet_holder(p.magnet_holder),
        "winding": lambda: P.winding(t.bobbin),
        "magnet": lambda: P.magnet(p.magnet_holder),
    }
    return builders[base]()


def build_parts(p: CadParams, kind: Literal["all", "exported"] = "all") -> dict:
    """Every distinct part, ``{name: Part}``."""
    return {name: build_part(p, name) for name in part_names(p, kind)}


def _coil_placements(p: CadParams, k: int) -> list[Placement]:
    """Bobbin (or its two flanges), winding, core and sensor caps of coil k in its frame."""
    t = p.types[p.coil_type[k]]
    top, rot = p.coil_frames[k]
    r = np.asarray(rot, dtype=float)
    upright = bool(np.allclose(r, np.eye(3), atol=1e-12))
    rot_p = None if upright else rot
    turned = TURN_OVER if upright else tuple(map(tuple, r @ np.asarray(TURN_OVER)))
    length = t.bobbin.winding_length_mm

    def at(axial):
        return tuple(float(q) for q in np.asarray(top) + axial * r[:, 2])

    out = []
    if t.bobbin.mandrel == "printed_tube":
        out.append(Placement("bobbin" + t.suffix, at(0.0), rot_p))
    else:
        out.append(Placement("bobbin_flange" + t.suffix, at(0.0), rot_p))
        out.append(Placement("bobbin_flange" + t.suffix, at(-length), turned))
    out.append(Placement("winding" + t.suffix, at(0.0), rot_p))
    if t.core is not None:
        out.append(Placement("core" + t.suffix, at(0.0), rot_p))
    names = _cap_names(p, t)
    if names:
        out.append(Placement(names[0], at(t.reach_upper_mm), rot_p))
        out.append(Placement(names[-1], at(-length - t.reach_lower_mm), turned))
    return out


def placements(p: CadParams) -> list[Placement]:
    """Where every instance of every part goes in the array frame."""
    out: list[Placement] = []
    for k in range(len(p.coil_frames)):
        out += _coil_placements(p, k)
    out += _piece_placements(p, "frame_upper") + _piece_placements(p, "frame_lower")
    if p.sensor_holder == "mount":
        out += (_piece_placements(p, "sensor_mount_upper")
                + _piece_placements(p, "sensor_mount_lower"))
    for x, y in p.fixing_xy_mm:
        out.append(Placement("standoff", (x, y, p.standoff_top_z_mm)))
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
        shape.color = Color(part_info(pl.part).color)
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
