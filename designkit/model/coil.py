"""A coil: a thick multilayer winding with an optional soft-iron core, in a pose.

The winding is modelled with uniform current density ``turns * current / ((Ro - Ri) * L)`` over
its rectangular (r, z) section (see :func:`designkit.field.winding_field`); the core's field is
added by :class:`designkit.cores.Core`, which sees only the winding's geometry
(:attr:`Coil.winding`, a :class:`designkit.geometry.winding.WindingGeometry`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..cores import Core
from ..design import CoilSpec, CoreSpec, Design, WireSpec
from ..errors import BadInputError
from ..field import winding_field
from ..geometry.pose import Pose
from ..geometry.winding import WindingGeometry
from ..support import validate as v
from . import electrical


@dataclass(frozen=True)
class Coil:
    """Thick solenoid (winding centred at its pose's origin, axis = local +z) plus optional core.

    Parameters
    ----------
    inner_radius, outer_radius : float, m
        Winding section radii, ``0 < inner_radius < outer_radius``.
    length : float, m
        Winding length along the axis; the winding spans local z in [-length/2, +length/2].
    turns : int
        Number of turns (> 0).
    core : Core or None
        Soft-iron core in the bore, or None for an air coil.
    pose : Pose
        Position of the winding centre and orientation of the axis, global frame.
    """

    inner_radius: float
    outer_radius: float
    length: float
    turns: int
    core: "Core | None" = None
    pose: Pose = field(default_factory=Pose)

    def __post_init__(self):
        ri = v.positive("inner_radius", self.inner_radius)
        ro = v.positive("outer_radius", self.outer_radius)
        if ro <= ri:
            raise BadInputError("outer_radius", f"> inner_radius ({ri} m)", self.outer_radius)
        v.positive("length", self.length)
        v.positive_int("turns", self.turns)
        if not isinstance(self.pose, Pose):
            raise BadInputError("pose", "a designkit.Pose", type(self.pose).__name__)
        if self.core is not None:
            if not isinstance(self.core, Core):
                raise BadInputError("core", "a designkit.Core or None", type(self.core).__name__)
            if self.core.radius > ri * (1 + 1e-12):
                raise BadInputError("core.radius", f"<= inner_radius ({ri} m) to fit the bore",
                                    self.core.radius)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_design(cls, design: Design, position=(0.0, 0.0, None)) -> "Coil":
        """The design's (base) coil, upright; by default its top face at z = 0 (centre at
        -length/2)."""
        x, y, z = position
        if z is None:
            z = -design.coil.length_m / 2
        return cls.from_specs(design.coil, design.core, Pose((float(x), float(y), float(z))))

    @classmethod
    def of_design(cls, design: Design, k: int) -> "Coil":
        """Coil k of the design's layout: its own winding and core (its group's), in its pose."""
        return cls.from_specs(design.coil_spec(k), design.core_spec(k), design.coil_poses()[k])

    @classmethod
    def from_specs(cls, coil: CoilSpec, core: CoreSpec | None, pose: Pose) -> "Coil":
        """A coil from a design's winding and core tables, in a pose."""
        model = None
        if core is not None:
            model = Core(radius=core.radius_m, length=core.length_m,
                         relative_permeability=core.relative_permeability,
                         offset=core.offset_m, bh=core.bh, knee_t=core.saturation_t)
        return cls(coil.inner_radius_m, coil.outer_radius_m, coil.length_m, coil.turns, model,
                   pose)

    def replace(self, **changes) -> "Coil":
        return dataclasses.replace(self, **changes)

    def moved(self, position) -> "Coil":
        return dataclasses.replace(self, pose=Pose(tuple(position), self.pose.rotation))

    # ------------------------------------------------------------------ geometry
    @property
    def winding(self) -> WindingGeometry:
        """The winding's geometry alone (radii and length in m, turns): what the core and the
        electrical models read of a coil."""
        return WindingGeometry.of(self)

    @property
    def current_density_per_amp(self) -> float:
        """Azimuthal current density per ampere of terminal current, A/m^2 per A."""
        return self.winding.current_density_per_amp

    @property
    def top_z_local(self) -> float:
        return self.length / 2

    @property
    def dipole_moment_per_amp(self) -> float:
        """Far-field dipole moment of the winding alone, A m^2 per A:
        N pi (Ri^2 + Ri Ro + Ro^2) / 3 (the section-averaged loop area)."""
        ri, ro = self.inner_radius, self.outer_radius
        return self.turns * np.pi * (ri * ri + ri * ro + ro * ro) / 3

    # ------------------------------------------------------------------ field
    def field(self, points, current: float, *, gradient: bool = False, rtol: float = 1e-10,
              include: str = "all"):
        """Flux density (and gradient) of winding + core at global points.

        Parameters
        ----------
        points : array-like, shape (3,) or (n, 3), m
        current : float, A
            Terminal current (counter-clockwise about the local +z axis when positive).
        gradient : bool
            Also return ``G[:, i, j] = dB_i/dx_j``, T/m.
        rtol : float
            Relative accuracy requested from the winding quadrature.
        include : {'all', 'winding', 'core'}
            Which parts to sum.

        Returns
        -------
        B : ndarray, shape (n, 3) or (3,), T
        G : ndarray, shape (n, 3, 3) or (3, 3), T/m (only when gradient=True)
        """
        p, single = v.points(points)
        current = v.finite("current", current, "A")
        if include not in ("all", "winding", "core"):
            raise BadInputError("include", "'all', 'winding' or 'core'", include)
        local = self.pose.to_local(p)
        n = len(p)
        b = np.zeros((n, 3))
        g = np.zeros((n, 3, 3)) if gradient else None
        if include in ("all", "winding"):
            res = winding_field(local, self.inner_radius, self.outer_radius, self.length,
                                self.turns, current, gradient=gradient, rtol=rtol)
            if gradient:
                b += res[0]
                g += res[1]
            else:
                b += res
        if self.core is not None and include in ("all", "core"):
            res = self.core.field_local(local, self.winding, current, gradient=gradient)
            if gradient:
                b += res[0]
                g += res[1]
            else:
                b += res
        b = self.pose.vectors_to_global(b)
        if gradient:
            g = self.pose.tensors_to_global(g)
            return (b[0], g[0]) if single else (b, g)
        return b[0] if single else b

    # ------------------------------------------------------------------ electrical
    def resistance(self, wire: WireSpec | None = None) -> float:
        """DC resistance of the winding, ohm (see :mod:`designkit.model.electrical`)."""
        return electrical.resistance(self, wire)

    def inductance(self, wire: WireSpec | None = None) -> float:
        """Self-inductance including the core, H (see :mod:`designkit.model.electrical`)."""
        return electrical.inductance(self, wire)
