"""Rigid poses of sources (:mod:`.pose`) and the few numbers of a winding the field, core and
electrical models share (:mod:`.winding`)."""

from .pose import Pose
from .winding import WindingGeometry

__all__ = ["Pose", "WindingGeometry"]
