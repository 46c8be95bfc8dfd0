"""The simulated device with N finger magnets: the same coils, drivers and sensor buses as
:class:`~designkit.sim.device.SimulatedDevice`, the physics of every magnet at once.

The truth is designkit's coupled model, never the map: the force on magnet i is

    F_i = F(m_i) G5(p_i, I) I  +  sum_k F0_ik  +  P_i,

its own force rows (``CoilArray.actuation_matrix`` at its true position, contracted with its
moment; saturating cores' columns at the true currents), the pull of the cores magnetized by
every magnet, finite cylinders (``CoilArray.bias_force_matrix``: its own F0 on the diagonal,
the cross terms off it) and the other magnets' direct pull (finite cylinders,
:class:`firmware_io.magnet_pair.MagnetPairs`, evaluated at every step). The sensors see every
magnet's exact cylinder field, the coils' field and the cores magnetized by all the magnets
(``CoilArray.magnets_core_field``), through their errors and noise. Positions m, moments A m^2,
forces N, fields T, currents A.
"""

from __future__ import annotations

import numpy as np

from firmware_io.magnet_pair import MagnetPairs

from ..model.array import force_matrix
from .device import SimulatedDevice
from .readings import analog_reading, magnet_field
from .samples import Sampled, sample_steps
from .saturation import PATH_STEP_M

BIAS_STEP_M = 1e-3
"""Path step (of any magnet) between evaluations of the cores' pull (own and cross terms), m:
the terms are smooth on the coil scale; linear interpolation over 1 mm is within ~0.1 %."""

INDUCED_STEP_M = 2e-3
"""Path step between evaluations of the cores' field at the sensors, m."""


class MagnetsDevice(SimulatedDevice):
    """:class:`SimulatedDevice` with the design's N magnets (``design.magnets``, in order);
    the keywords are :class:`SimulatedDevice`'s. :meth:`prepare` takes every magnet's path."""

    def __init__(self, design, array=None, **kw):
        super().__init__(design, array, **kw)
        specs = design.magnets
        self.names = [s.name for s in specs]
        self.moments = np.array([s.moment_vector_a_m2 for s in specs], float)
        self.sizes = np.array([(s.radius_m, s.length_m) for s in specs], float)
        self.pairs = MagnetPairs(self.sizes[:, 0], self.sizes[:, 1], names=self.names)

    @property
    def n_magnets(self) -> int:
        return len(self.names)

    def prepare(self, paths_m, directions=None, *, sample_step_m: float = 2.5e-4,
                max_stride: int = 10, induced_step_m: float = INDUCED_STEP_M) -> None:
        """Evaluate the coupled model along every magnet's path (``paths_m`` (N, k, 3) m, one
        position per step; the moments stay the design's): each magnet's A(p) where it moved
        ``sample_step_m``, the cores' pull (:data:`BIAS_STEP_M`) and field at the sensors
        where any magnet moved, the pair force at every step."""
        paths = np.asarray(paths_m, float).reshape(self.n_magnets, -1, 3)
        k = paths.shape[1]
        up = np.tile([0.0, 0.0, 1.0], (k, 1))
        self.paths_m = paths
        self.path_m = paths[0]
        self.moment_steps = np.tile(self.moments[0], (k, 1))
        self.rows, self.sat = [], []
        for p in paths:
            idx = sample_steps(p, up, step_m=sample_step_m, turn_rad=np.pi,
                               max_stride=max_stride)
            self.rows.append(Sampled(idx, self.array.actuation_matrix(p[idx])))
            if self.saturation is not None:
                at = sample_steps(p, up, step_m=PATH_STEP_M, turn_rad=np.pi)
                self.sat.append(Sampled(at, self.saturation.deltas(p[at])))
        joint = np.concatenate(list(paths), axis=1)          # (k, 3 N): any magnet moving
        at = sample_steps(joint, up, step_m=BIAS_STEP_M, turn_rad=np.pi)
        own, cross = [], []
        for s in at:
            f = self.array.bias_force_matrix(paths[:, s], self.moments,
                                             magnet_sizes_m=self.sizes)[0]
            diag = np.einsum("iij->ij", f)
            own.append(diag)
            cross.append(f.sum(axis=1) - diag)
        self.own_bias = Sampled(at, np.array(own))
        self.cross_bias = Sampled(at, np.array(cross))
        self.pair_n = np.array([self.pairs.forces(paths[:, s], self.moments)[0]
                                for s in range(k)])
        coarse = sample_steps(joint, up, step_m=induced_step_m, turn_rad=np.pi)
        pts = self.sensor_sim.true_m.reshape(-1, 3)
        self.induced = Sampled(coarse, [self.array.magnets_core_field(
            pts, paths[:, s], self.moments, magnet_sizes_m=self.sizes) for s in coarse])

    def magnet_actuation(self, i: int, step: int, current_a) -> np.ndarray:
        """Magnet i's A (8, n) at its true position of step ``step``, each column at its coil's
        |I| when the cores saturate."""
        a = self.rows[i].at(step)
        if self.saturation is None:
            return a
        return self.saturation.columns(a, self.sat[i].at(step), current_a)

    def true_forces_n(self, step: int, current_a, *, pair: bool = True) -> np.ndarray:
        """(N, 3) N: the force on each true magnet at step ``step`` with the currents
        ``current_a`` (n,) A (module docstring); ``pair`` False leaves the magnets' direct pull
        out (what the coils and cores alone exert)."""
        i = np.asarray(current_a, float)
        coils = np.array([force_matrix(m) @ self.magnet_actuation(k, step, i)[3:] @ i
                          for k, m in enumerate(self.moments)])
        f = coils + self.own_bias.at(step) + self.cross_bias.at(step)
        return f + self.pair_n[step] if pair else f

    def true_torques_n_m(self, step: int, current_a) -> np.ndarray:
        """(N, 3) N m: the coils' torque m x B on each true magnet."""
        i = np.asarray(current_a, float)
        return np.array([np.cross(m, self.magnet_actuation(k, step, i)[:3] @ i)
                         for k, m in enumerate(self.moments)])

    def sensor_readings_t(self, step: int, position_m, current_a) -> np.ndarray:
        """(n_sensors, 3) T, what each sensor's ADC converts at step ``step`` with the magnets
        at ``position_m`` (N, 3) m: every magnet's exact field, the cores magnetized by all of
        them, the coils', the room's, through the sensor errors and noise."""
        sim = self.sensor_sim
        pts = sim.true_m.reshape(-1, 3)
        pos = np.asarray(position_m, float).reshape(self.n_magnets, 3)
        b = self.induced.at(step) + self.ambient_t
        for p, m, (r, length) in zip(pos, self.moments, self.sizes):
            b = b + magnet_field(pts, p, m, r, length)
        b = b.reshape(sim.true_m.shape) + sim.coil_part(np.asarray(current_a, float)[None])[0]
        a = analog_reading(b[None], sim.errors, self.noise_t, self.rng)[0].reshape(-1, 3)
        return a + self.field_offset_t
