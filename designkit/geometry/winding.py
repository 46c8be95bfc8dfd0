"""The winding geometry as a small value type, and the winding's applied field per ampere.

A thick multilayer winding is four numbers: inner and outer radius (m), length (m) and turns,
centred at z = 0 of its local frame with its axis along +z. The core models only need these
four numbers of a coil, so they take a :class:`WindingGeometry` (a :class:`designkit.Coil`
has the same four attributes and works wherever one is expected) and never import the coil.
The current density is uniform over the rectangular (r, z) section,
``J = turns * I / ((outer_radius - inner_radius) * length)``
(:func:`designkit.field.winding.winding_rz` integrates its field).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple, Protocol

import numpy as np

from ..constants import MU0
from ..field.winding import winding_rz


class WindingGeometry(NamedTuple):
    """Section of a thick winding (local frame, centred at z = 0, axis +z). Hashable.

    Parameters
    ----------
    inner_radius, outer_radius : float, m
    length : float, m
        The winding spans local z in [-length/2, +length/2].
    turns : int
    """

    inner_radius: float
    outer_radius: float
    length: float
    turns: int

    @classmethod
    def of(cls, winding) -> "WindingGeometry":
        """The geometry of anything with ``inner_radius``, ``outer_radius``, ``length`` and
        ``turns`` (a :class:`designkit.Coil` or a WindingGeometry), as floats and an int."""
        return cls(float(winding.inner_radius), float(winding.outer_radius),
                   float(winding.length), int(winding.turns))

    @property
    def current_density_per_amp(self) -> float:
        """Azimuthal current density per ampere of terminal current, A/m^2 per A."""
        return self.turns / ((self.outer_radius - self.inner_radius) * self.length)

    def h_rz(self, rho, z, gradient: bool = False, rtol: float = 1e-9):
        """The winding's H = B / mu0 per ampere at local (rho, z) (shape (n,) each, m).

        Returns (hr, hz) in 1/m, or with ``gradient`` the 7 components of
        :func:`designkit.field.winding.winding_rz` times the current density.
        """
        j = self.current_density_per_amp
        res = winding_rz(self.inner_radius, self.outer_radius, self.length / 2,
                         np.ascontiguousarray(rho, dtype=float),
                         np.ascontiguousarray(z, dtype=float), gradient=gradient, rtol=rtol)
        return tuple(np.asarray(r) * j for r in res)

    def disc_flux(self, r, z, nodes: int = 10) -> np.ndarray:
        """Flux of the winding's B through the discs of radius r (n,) at heights z (n,), Wb/A.

        Gauss-Legendre in s = (r'/r)^2 (area coordinate): the integrand B_z is smooth inside
        the bore, and r <= inner radius here.
        """
        x, w = np.polynomial.legendre.leggauss(nodes)
        s = 0.5 * (x + 1.0)
        rr = (np.sqrt(s)[None, :] * np.asarray(r)[:, None]).ravel()
        zz = np.repeat(np.asarray(z), nodes)
        hz = self.h_rz(rr, zz)[1].reshape(-1, nodes)
        # int_0^r Bz 2 pi r' dr' = pi r^2 int_0^1 Bz ds
        return MU0 * math.pi * np.asarray(r) ** 2 * (hz @ (0.5 * w))


class CoilLike(Protocol):
    """What the electrical model reads of a coil: the four numbers of its winding and its
    core (None for an air coil; else an object with ``extra_inductance(winding)``, H)."""

    inner_radius: float
    outer_radius: float
    length: float
    turns: int
    core: Any
