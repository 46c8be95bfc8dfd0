"""The design spec: one frozen, SI-unit description of the whole device, :class:`Design`.

Every product (field, force, optimized coil, printed parts, FEM mesh, force-current map,
plots, currents on the wire) is derived from one :class:`Design`, so they can never disagree.
A design is loaded from TOML (:func:`designkit.design.load_design`) or taken from
:func:`default_design`, the thesis' device (the EHI thesis this toolkit reproduces, sections
2.2-3.2). Its tables: :mod:`.tables`; its layout: :mod:`.layouts`; its checks: :mod:`.checks`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field, fields
from typing import Any, Mapping

import numpy as np

from ..constants import MU0  # noqa: F401  (re-exported: designkit.design.MU0 is public)
from ..errors import BadInputError
from ..geometry.pose import Pose
from .asbuilt import AsBuilt
from .checks import check_design
from .layouts import GridLayout, Layout, pose_on_axis
from .tables import (SECTIONS, CadSpec, CoilGroup, CoilSpec, CoreSpec, DriveSpec, MagnetSpec,
                     OptimizeSpec, RenderSpec, SensorSpec, WireSpec, WorkspaceSpec, implied_shape)
from .workspace import Workspace


@dataclass(frozen=True)
class Design:
    """The whole device. Immutable; sweeps use :func:`dataclasses.replace`."""

    name: str = "thesis-default"
    magnet: MagnetSpec = field(default_factory=MagnetSpec)
    wire: WireSpec = field(default_factory=WireSpec)
    coil: CoilSpec = field(default_factory=CoilSpec)
    core: CoreSpec | None = field(default_factory=CoreSpec)
    array: Layout = field(default_factory=GridLayout)
    """Where the coils sit (:mod:`designkit.design.layouts`): grid, hex, ring or free."""
    drive: DriveSpec = field(default_factory=DriveSpec)
    sensors: SensorSpec = field(default_factory=SensorSpec)
    workspace: WorkspaceSpec = field(default_factory=WorkspaceSpec)
    optimize: OptimizeSpec = field(default_factory=OptimizeSpec)
    render: RenderSpec = field(default_factory=RenderSpec)
    cad: CadSpec = field(default_factory=CadSpec)
    asbuilt: AsBuilt | None = None
    """The device as built (designkit.design.asbuilt); None: the nominal design."""
    groups: tuple[CoilGroup, ...] = ()
    """Coils whose winding or core differ from ``coil`` / ``core`` (none: all alike)."""
    other_magnets: tuple[MagnetSpec, ...] = ()
    """Magnets beyond ``magnet`` (several fingers: ``[[magnets]]`` in a design file, the first
    of which is ``magnet``); :attr:`magnets` lists them all."""

    def __post_init__(self):
        check_design(self)
        if self.asbuilt is not None:
            self.asbuilt.check(self.n_coils, self.core is not None)

    # -- derived quantities -------------------------------------------------------------
    @property
    def design_coil(self) -> int:
        """Index of the coil the design point sits above: the coil whose top-face centre is
        nearest (in x, y) to the layout's centre, the mean of the top-face centres; of equally
        near coils (a 4 x 4 grid's four middle ones, a ring's all) the first in the layout's
        order."""
        tops = self.array.top_centres_m()
        d = np.hypot(*(tops[:, :2] - tops[:, :2].mean(axis=0)).T)
        return int(np.flatnonzero(d <= d.min() + 1e-9)[0])

    @property
    def design_point_m(self) -> tuple[float, float, float]:
        """The design point, m: the magnet's centre ``optimize.height_m`` above the top face of
        :attr:`design_coil`, on its axis (for an upright coil at the origin (0, 0, h), where the
        single-coil problem of thesis eq. 2.14 puts it)."""
        k = self.design_coil
        point = self.array.top_centres_m()[k] + self.optimize.height_m * self.array.axes()[k]
        return tuple(float(c) + 0.0 for c in point)

    @property
    def magnets(self) -> tuple[MagnetSpec, ...]:
        """Every finger magnet, ``magnet`` first."""
        return (self.magnet,) + self.other_magnets

    @property
    def n_coils(self) -> int:
        """Number of coils of the layout."""
        return len(self.array.top_centres_m())

    def coil_spec(self, k: int) -> CoilSpec:
        """The winding of coil k (its group's, else ``coil``)."""
        for g in self.groups:
            if k in g.coils:
                return g.coil
        return self.coil

    def core_spec(self, k: int) -> CoreSpec | None:
        """The core of coil k (its group's, else ``core``; None: an air coil)."""
        for g in self.groups:
            if k in g.coils:
                return g.core
        return self.core

    def coil_poses(self) -> list[Pose]:
        """Each coil's pose: its winding centre (``length_m / 2`` below its top face along its
        axis), its local +z the layout's axis (the identity rotation for an upright coil), m."""
        tops, axes = self.array.top_centres_m(), self.array.axes()
        return [pose_on_axis(top - axis * self.coil_spec(k).length_m / 2, axis)
                for k, (top, axis) in enumerate(zip(tops, axes))]

    def coil_centres_m(self) -> list[tuple[float, float, float]]:
        """Centres of the windings, m, in the layout's coil order."""
        return [p.position for p in self.coil_poses()]

    def workspace_region(self) -> Workspace:
        """The region the magnet moves in (:class:`designkit.design.workspace.Workspace`)."""
        ws = self.workspace
        if ws.shape == "box":
            return Workspace.box(ws.half_width_m, ws.z_min_m, ws.z_max_m)
        if ws.shape == "disc":
            return Workspace.disc(ws.radius_m, ws.z_min_m, ws.z_max_m)
        return Workspace.from_polygon(self.array.footprint_m(), ws.z_min_m, ws.z_max_m)

    def sensor_poses(self) -> tuple[np.ndarray, np.ndarray]:
        """Sensor positions (n_sensors, 3) m and frames (n_sensors, 3, 3) (columns: each chip's
        x, y, z axes in the array frame), in :class:`SensorSpec`'s order."""
        s = self.sensors
        if s.layout == "free":
            pos = np.array(s.positions_m, dtype=float).reshape(-1, 3)
            rot = (np.array(s.rotations, dtype=float).reshape(-1, 3, 3) if s.rotations
                   else np.tile(np.eye(3), (len(pos), 1, 1)))
            return pos, rot
        poses = self.coil_poses()
        up, down, frames = [], [], []
        for k, p in enumerate(poses):
            axis = p.matrix[:, 2]
            reach = self.coil_spec(k).length_m / 2 + s.offset_m
            up.append(np.asarray(p.position) + reach * axis)
            down.append(np.asarray(p.position) - reach * axis)
            frames.append(p.matrix)
        return np.array(up + down), np.array(frames + frames)

    def replace(self, **changes) -> "Design":
        """A copy with top-level or dotted-path changes: ``d.replace(**{"coil.turns": 1000})``."""
        return replace_path(self, changes)

    def to_dict(self) -> dict[str, Any]:
        """The spec as nested dicts (``array`` with its ``layout``; ``groups`` and ``asbuilt``
        only when present, so that a design without them keeps its hash)."""
        out = dataclasses.asdict(self)
        out["array"] = {"layout": self.array.kind, **out["array"]}
        if self.asbuilt is None:
            del out["asbuilt"]
        if not self.groups:
            del out["groups"]
        if not self.other_magnets:
            del out["other_magnets"]
        return out

    def spec_hash(self) -> str:
        """SHA-256 of the canonical JSON of the physics spec (stable across runs and machines;
        the printing choices of ``cad`` change no field, so they are not part of it)."""
        spec = {k: val for k, val in self.to_dict().items() if k != "cad"}
        blob = json.dumps(spec, sort_keys=True, separators=(",", ":"), default=float)
        return hashlib.sha256(blob.encode()).hexdigest()


def default_design() -> Design:
    """The thesis device with the assumptions stated in the field docs."""
    return Design()


def replace_path(design: Design, changes: Mapping[str, Any]) -> Design:
    """Apply ``{"section.field": value}`` (or top-level ``{"name": ...}``) changes."""
    top: dict[str, Any] = {}
    per_section: dict[str, dict[str, Any]] = {}
    for key, value in changes.items():
        if "." in key:
            sec, _, name = key.partition(".")
            if sec not in SECTIONS:
                raise BadInputError("parameter", f"one of {sorted(SECTIONS)} before the dot", key)
            current = getattr(design, sec)
            allowed = {f.name for f in fields(SECTIONS[sec] if current is None else current)}
            if name not in allowed:
                raise BadInputError("parameter", f"a field of [{sec}]: {sorted(allowed)}", key)
            per_section.setdefault(sec, {})[name] = value
        else:
            top[key] = value
    for sec, vals in per_section.items():
        current = getattr(design, sec)
        if current is None:
            current = SECTIONS[sec]()
        if sec == "workspace":
            vals = implied_shape(vals)
        top[sec] = dataclasses.replace(current, **vals)
    return dataclasses.replace(design, **top)
