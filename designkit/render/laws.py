"""Force laws: the thesis' constraint force and a passivity-clamped penetration (proxy) law.

Both evaluate through :mod:`firmware_io.scene` (one definition, numpy only); these classes hold
and check the parameters and produce the ``law`` entry of a compiled scene.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from firmware_io import scene as fs

from ..support import validate as v


@dataclass(frozen=True)
class ConstraintLaw:
    """F = lambda h(x, y) n(p) where g(p) <= contact_band_m (thesis eqs. 4.1-4.2), N.

    lam_n_per_m : the force constant lambda, N/m (from :func:`designkit.render.force_constant`).
    """

    lam_n_per_m: float
    contact_band_m: float = 0.0

    def __post_init__(self):
        v.nonnegative("lam_n_per_m", self.lam_n_per_m, "N/m")
        v.nonnegative("contact_band_m", self.contact_band_m, "m")

    def force(self, obj, points, velocities=None) -> np.ndarray:
        return fs.constraint_force(obj._obj(), points, self.lam_n_per_m,
                                   contact_band_m=self.contact_band_m)

    def meta(self) -> dict:
        return {"name": "constraint", "contact_band_m": self.contact_band_m}


@dataclass(frozen=True)
class PenetrationLaw:
    """God-object (proxy) wall: F = K (-g) n - B (v . n) n inside the solid, never pulling.

    The stiffness used is ``min(stiffness_n_per_m, K_max)`` with K_max from
    :func:`firmware_io.scene.passivity_stiffness_bound`: Colgate & Brown's passivity condition
    b > K T / 2 + |B| (T the loop period, b the physical damping -- here the finger's, assumed
    1 N s/m, since the magnet floats) and the position-noise bound K sigma <= F_threshold
    (0.8 mN, design.render.threshold_n) so that sensor noise is not felt.
    """

    stiffness_n_per_m: float = 200.0
    damping_n_s_per_m: float = 0.0
    loop_period_s: float = 0.005
    position_noise_m: float = 0.3e-3
    finger_damping_n_s_per_m: float = 1.0
    threshold_n: float = 0.8e-3

    def __post_init__(self):
        v.nonnegative("stiffness_n_per_m", self.stiffness_n_per_m, "N/m")
        v.nonnegative("damping_n_s_per_m", self.damping_n_s_per_m, "N s/m")
        v.positive("loop_period_s", self.loop_period_s, "s")
        v.nonnegative("position_noise_m", self.position_noise_m, "m")
        v.nonnegative("finger_damping_n_s_per_m", self.finger_damping_n_s_per_m, "N s/m")
        v.positive("threshold_n", self.threshold_n, "N")

    def bound(self) -> tuple[float, str]:
        return fs.passivity_stiffness_bound(self.loop_period_s, self.finger_damping_n_s_per_m,
                                            self.damping_n_s_per_m, self.position_noise_m,
                                            self.threshold_n)

    @property
    def effective_stiffness_n_per_m(self) -> float:
        return float(min(self.stiffness_n_per_m, self.bound()[0]))

    def force(self, obj, points, velocities=None) -> np.ndarray:
        p = np.atleast_2d(np.asarray(points, float))
        vel = np.zeros_like(p) if velocities is None else velocities
        return fs.penetration_force(obj._obj(), p, vel, self.effective_stiffness_n_per_m,
                                    self.damping_n_s_per_m)

    def meta(self) -> dict:
        k_max, why = self.bound()
        return {"name": "penetration", "stiffness_n_per_m": self.effective_stiffness_n_per_m,
                "requested_stiffness_n_per_m": self.stiffness_n_per_m,
                "stiffness_bound_n_per_m": k_max, "stiffness_limited_by": why,
                "damping_n_s_per_m": self.damping_n_s_per_m,
                "loop_period_s": self.loop_period_s, "position_noise_m": self.position_noise_m,
                "finger_damping_n_s_per_m": self.finger_damping_n_s_per_m,
                "threshold_n": self.threshold_n}
