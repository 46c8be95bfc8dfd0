"""The design spec: one frozen, SI-unit description of the whole device, and its files.

:mod:`.spec` (:class:`Design`), :mod:`.tables` (its tables' dataclasses), :mod:`.checks`
(the range checks), :mod:`.layouts` (where the
coils sit: grid, hex, ring, free), :mod:`.workspace` (the region the magnet moves in),
:mod:`.files` (TOML in and out, shipped designs by name), :mod:`.asbuilt` (the device as
built). Frame and polarity
conventions: :mod:`.spec`.
"""

from ..constants import MU0
from .asbuilt import AsBuilt, BuildTolerances, CoilDeviation, asbuilt_from_dict, random_asbuilt
from .files import NAMED_DESIGNS, design_from_dict, design_to_toml, load_design, named_design
from .layouts import (LAYOUTS, FreeLayout, GridLayout, HexLayout, Layout, RingLayout,
                      pose_on_axis)
from .checks import MAX_LENGTH_M, check_design
from .spec import Design, default_design, replace_path
from .tables import (SECTIONS, SENSOR_LAYOUTS, WORKSPACE_SHAPES, CadSpec, CoilGroup, CoilSpec,
                     CoreSpec, DriveSpec, MagnetSpec, OptimizeSpec, RenderSpec, SensorSpec,
                     WireSpec, WorkspaceSpec)
from .workspace import Workspace

__all__ = [
    "MU0", "AsBuilt", "BuildTolerances", "CoilDeviation", "asbuilt_from_dict", "random_asbuilt",
    "NAMED_DESIGNS", "design_from_dict", "design_to_toml", "load_design", "named_design",
    "LAYOUTS", "FreeLayout", "GridLayout", "HexLayout", "Layout", "RingLayout", "pose_on_axis",
    "Workspace", "SENSOR_LAYOUTS", "WORKSPACE_SHAPES", "CoilGroup",
    "MAX_LENGTH_M", "SECTIONS", "CadSpec", "CoilSpec", "CoreSpec", "Design",
    "DriveSpec", "MagnetSpec", "OptimizeSpec", "RenderSpec", "SensorSpec", "WireSpec",
    "WorkspaceSpec", "check_design", "default_design", "replace_path",
]
