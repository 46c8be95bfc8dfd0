"""Haptic rendering (thesis chapter 4): virtual objects, force laws, the force constant
(eq. 4.3) and compiled scenes for the runner.

Building lives here (designkit); evaluating lives in :mod:`firmware_io.scene` (numpy only), so
the runner loads a compiled scene and a map and only calls::

    scene = firmware_io.scene.Scene.load("scene.npz", expected_design_sha256=map.meta[...])
    f = scene.force(p)                                   # N, required force at the magnet
    currents, res = firmware_io.allocation.allocate(F(p), f, u, I_t, bias=F0(p))

Polarity: the magnet's moment is ``design.magnet.moment_vector_a_m2`` (default -z) and positive
current is counter-clockwise seen from above, so positive current pushes the finger up.
"""

from __future__ import annotations

from .constant import (ArrayActuation, ConstantSettings, ForceConstant, actuation_source,
                       force_constant)
from .laws import ConstraintLaw, PenetrationLaw
from .objects import (OBJECTS, HalfCylinder, Hemisphere, MeshSurface, Plane, VirtualObject,
                      Wedge)
from .scenefile import compile_scene, make_object

__all__ = ["Plane", "Hemisphere", "HalfCylinder", "Wedge", "MeshSurface", "VirtualObject",
           "OBJECTS", "ConstraintLaw", "PenetrationLaw", "force_constant", "ForceConstant",
           "ConstantSettings",
           "ArrayActuation", "actuation_source", "compile_scene", "make_object"]
