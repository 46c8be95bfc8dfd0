"""What the map samples, for one design: :class:`MapPhysics`, the one place its physics comes
from (the coupled array model, :mod:`designkit.cores.coupled` through :class:`CoilArray`);
SI units; the sensors as the array's flat list (:meth:`CoilArray.sensor_poses`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.array import CoilArray


@dataclass(frozen=True)
class MapPhysics:
    """What the map samples, for one design (all SI); every method takes the CoilArray it is
    about (the design's array, or one coil alone for the per-type tables). All of it comes from
    the coupled array model (:mod:`designkit.cores.coupled` through :class:`CoilArray`).
    """

    moment_a_m2: np.ndarray
    max_current_a: float
    magnet_size_m: tuple | None = None
    """(radius, length) m of the finger magnet's cylinder (:meth:`bias_force_finite`)."""
    source: str = "designkit.cores.coupled (all cores solved together, linear cores)"

    def sensor_positions(self, array: CoilArray) -> np.ndarray:
        """(n_sensors, 3) m, the array's flat sensor list (:meth:`CoilArray.sensor_poses`;
        the default layout: the upper array in coil order, then the lower array)."""
        return array.sensor_poses()[0]

    def sensor_rotations(self, array: CoilArray) -> np.ndarray:
        """(n_sensors, 3, 3): each sensor's frame (columns: the chip's x, y, z axes in the
        array frame)."""
        return array.sensor_poses()[1]

    def actuation(self, array: CoilArray, points) -> np.ndarray:
        """Coupled A (n, 8, n_coils), T/A and T/(m A)."""
        return array.actuation_matrix(np.asarray(points, float))

    def bias_force(self, array: CoilArray, points) -> np.ndarray:
        """F0 (n, 3) N on the magnet, as a point dipole, at ``points`` at zero current."""
        return array.bias_force(np.asarray(points, float), self.moment_a_m2)

    def bias_force_finite(self, array: CoilArray, points) -> np.ndarray:
        """F0 (n, 3) N on the magnet as the uniformly magnetized cylinder it is
        (:attr:`magnet_size_m`; ~20 x the dipole's cost), at ``points`` at zero current: the
        map's per-core tables carry its difference from the dipole (docs/fieldmap.md, "The
        magnet's finite size")."""
        return array.bias_force(np.asarray(points, float), self.moment_a_m2,
                                magnet_size_m=self.magnet_size_m)

    def sensor_induced(self, array: CoilArray, magnet_positions, chunk: int = 64) -> np.ndarray:
        """(n, n_sensors, 3) T: the field of the magnet-magnetized cores at the sensors (array
        frame)."""
        p = np.asarray(magnet_positions, float)
        sens = self.sensor_positions(array)
        system = array.coupled()
        out = np.zeros((len(p),) + sens.shape)
        if system is None:
            return out
        for a in range(0, len(p), chunk):  # one back-substitution per magnet position
            x = system.magnet_solution(p[a:a + chunk], self.moment_a_m2)
            b = system.core_field(sens, x)  # (n_sensors, 3, k)
            out[a:a + chunk] = np.moveaxis(b, -1, 0)
        return out

    def sensor_coil_rows(self, array: CoilArray) -> np.ndarray:
        """(n_sensors, 8, n_coils): the coupled field (T/A) and gradient rows (T/(m A),
        :data:`~designkit.model.array.ROWS`) of each coil at the sensors (array frame)."""
        return self.actuation(array, self.sensor_positions(array))

    def sensor_coil_field(self, array: CoilArray) -> np.ndarray:
        """(n_sensors, 3, n_coils) T/A: the coupled field of each coil at the sensors."""
        return self.sensor_coil_rows(array)[:, :3]

    def saturation(self, array: CoilArray) -> tuple[np.ndarray, np.ndarray]:
        """Currents (n_s,) A and per-coil factors (n_s, n_coils) on the columns of A
        (:meth:`CoilArray.saturation_correction`; 1 for air coils and linear cores)."""
        if not array.saturating_coils():  # air or linear cores: nothing to solve for
            cur = np.array([0.0, 1.0])
            return cur, np.ones((2, array.n_coils))
        # 7 currents: linear interpolation between them follows a 13-point curve closely (the
        # factor bends only above ~4 A; docs/fieldmap.md) for half the nonlinear solves
        s = array.saturation_correction(currents_a=np.linspace(0.0, self.max_current_a, 7))
        return s["saturation_current_a"], s["saturation_factor"]


def map_physics(design) -> MapPhysics:
    """The one place the map's physics comes from (see :class:`MapPhysics`)."""
    return MapPhysics(np.asarray(design.magnet.moment_vector_a_m2, float),
                      design.drive.max_current_a,
                      (design.magnet.radius_m, design.magnet.length_m))
