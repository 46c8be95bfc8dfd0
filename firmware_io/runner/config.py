"""The runner's configuration: bounds, period, rendered axes, fault policy, and the coil drives.

R, L and the MD10C supply voltage are stored once, in the configuration; its
``drives`` (one :class:`firmware_io.hw.md10c.CoilDrive` per coil, derived from them) is what
the runner's current path and the PWM driver both read. A map file
carries the drive data (``meta['drive']``, written by designkit.model.electrical.drive_data):
:func:`config_from_map`. SI units throughout; the fault and resume policy the fields tune is
described in docs/runner.md.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..errors import BadInputError, FirmwareIOError
from ..hw.md10c import MD10C_CONTINUOUS_A, MD10C_SUPPLY_MAX_V, MD10C_SUPPLY_MIN_V, CoilDrive


@dataclass(frozen=True)
class RunnerConfig:
    """Everything the loop needs besides its devices, SI units.

    Attributes
    ----------
    resistance_ohm, inductance_h : tuple of float, one per coil
        Coil resistance at the operating temperature and inductance (secant, at the operating
        current) -> the L/R lag the feed-forward compensates.
    supply_voltage_v : float
        MD10C motor supply, V (<= 30 V).
    current_limit_a, total_current_a : float
        Per-coil bound |I_k| <= u and the budget sum |I_k| <= I_t, A.
    unipolar : bool
        0 <= I_k (the thesis' drive) instead of the MD10C's bipolar drive.
    control_period_s : float
        Step period T, s.
    force_axes : {'z', 'xyz'}
        Force components to render: 'z' evaluates only the two rows of A(p) that Fz of a
        z-dipole needs.
    skip_force_n : float
        Leave a coil out when the bound of the force it could add at its current limit near p
        is at most this, N (0: never skip; see :class:`firmware_io.runner.skip.CoilSkipBound`).
    feedforward : bool
        Voltage feed-forward through the L/R model (off: the duty is the steady-state one).
    thermal_continuous_current_a, thermal_time_constant_s : float
        :class:`firmware_io.runner.thermal.ThermalGuard` parameters, A and s.
    resume_after_s : float
        Fault-free time before a transient device fault (pwm_nack, overrun, over_limit) is
        cleared, s.
    resume_fixes : int
        A localization fault (lost, gated, out_of_box, sensor_*) is cleared once this many
        fixes in a row were taken into the tracker with no fault in between: a few frames,
        each passing the localizer's tests, the gate and the alert limit.
    max_pwm_retries : int
        PCA9685 re-initialisations before a ``pwm_nack`` is latched.
    overrun_factor : float
        A step is an overrun when its compute time exceeds ``overrun_factor * control_period_s``
        (why 10: docs/runner.md, "Overrun").
    gate_risk : float
        Probability that a correct fix fails the tracker's innovation gate (Mahalanobis
        distance with the fix's and the prediction's covariances, chi-square with 3 dof).
    alert_limit_m : float
        The largest protection level of a fix the runner renders with, m (the localizer's;
        why 10 mm and what 5 mm costs in availability: docs/runner.md, "Integrity").
    max_fix_age_s : float
        The tracker's newest accepted fix may be at most this old (frame time), s; older: the
        prediction is not supported by the sensors ('lost', coils off).
    drives : tuple of CoilDrive (derived)
        One per coil: R, L, the supply, and the current the supply can push through R.
    """

    resistance_ohm: tuple
    inductance_h: tuple
    supply_voltage_v: float
    current_limit_a: float
    total_current_a: float
    unipolar: bool = False
    control_period_s: float = 1e-3
    force_axes: str = "z"
    skip_force_n: float = 0.0
    feedforward: bool = True
    thermal_continuous_current_a: float = 3.0
    thermal_time_constant_s: float = 300.0
    resume_after_s: float = 0.25
    resume_fixes: int = 3
    max_pwm_retries: int = 3
    overrun_factor: float = 10.0
    gate_risk: float = 1e-4
    alert_limit_m: float = 10e-3
    max_fix_age_s: float = 0.05

    def __post_init__(self):
        self.drives  # noqa: B018  (checks R, L and the supply, names the field in the error)
        if not (0 < self.current_limit_a <= MD10C_CONTINUOUS_A):
            raise BadInputError("current_limit_a", "in (0, 13] A", self.current_limit_a)
        if not (self.total_current_a >= 0 and math.isfinite(self.total_current_a)):
            raise BadInputError("total_current_a", "a finite value >= 0 A", self.total_current_a)
        if not (0 < self.control_period_s <= 0.1):
            raise BadInputError("control_period_s", "in (0, 0.1] s", self.control_period_s)
        if self.force_axes not in ("z", "xyz"):
            raise BadInputError("force_axes", "'z' or 'xyz'", self.force_axes)
        if not (0 <= self.skip_force_n and math.isfinite(self.skip_force_n)):
            raise BadInputError("skip_force_n", "a finite force >= 0 N", self.skip_force_n)
        if not (0 < self.gate_risk < 0.5):
            raise BadInputError("gate_risk", "a probability in (0, 0.5)", self.gate_risk)
        if not (int(self.resume_fixes) == self.resume_fixes and self.resume_fixes >= 1):
            raise BadInputError("resume_fixes", "an integer >= 1 (fixes)", self.resume_fixes)
        if not (self.max_fix_age_s > 0):
            raise BadInputError("max_fix_age_s", "a time > 0 s", self.max_fix_age_s)
        if not (self.alert_limit_m > 0):
            raise BadInputError("alert_limit_m", "a length > 0 m (inf: none)", self.alert_limit_m)

    @functools.cached_property
    def drives(self) -> tuple[CoilDrive, ...]:
        """One :class:`CoilDrive` per coil from R, L and the supply."""
        return _coil_drives(self.resistance_ohm, self.inductance_h, self.supply_voltage_v)

    @property
    def n_coils(self) -> int:
        return len(self.drives)


def _coil_drives(resistance_ohm, inductance_h, supply_voltage_v) -> tuple[CoilDrive, ...]:
    """Checked per-coil drives (errors name the configuration's field, its value and range)."""
    n = len(resistance_ohm)
    r = np.asarray(resistance_ohm, float)
    ind = np.asarray(inductance_h, float)
    if n == 0 or not np.all(np.isfinite(r)) or np.any(r <= 0):
        raise BadInputError("resistance_ohm", "one finite value > 0 ohm per coil", resistance_ohm)
    if ind.shape != (n,) or not np.all(np.isfinite(ind)) or np.any(ind <= 0):
        raise BadInputError("inductance_h", f"{n} finite values > 0 H", inductance_h)
    if not MD10C_SUPPLY_MIN_V <= supply_voltage_v <= MD10C_SUPPLY_MAX_V:
        raise BadInputError("supply_voltage_v", "in [5, 30] V (MD10C rating)", supply_voltage_v)
    return tuple(CoilDrive.supply_limited(supply_voltage_v, float(rk), float(lk))
                 for rk, lk in zip(resistance_ohm, inductance_h))


def config_from_map(fieldmap, **overrides) -> RunnerConfig:
    """RunnerConfig from the drive data a map file carries (``meta['drive']``, SI keys)."""
    d = dict(fieldmap.meta.get("drive") or {})
    need = ("resistance_ohm", "inductance_h", "supply_voltage_v", "current_limit_a",
            "total_current_a")
    missing = [k for k in need if k not in d]
    if missing:
        raise FirmwareIOError(f"the map file carries no drive data {missing}: rebuild it with "
                              "`designkit map` (map format v2)")
    n = fieldmap.n_coils
    kw = {k: d[k] for k in need}
    for k in ("resistance_ohm", "inductance_h"):
        v = kw[k]
        kw[k] = tuple(float(x) for x in (v if isinstance(v, (list, tuple)) else [v] * n))
    for k in ("thermal_continuous_current_a", "thermal_time_constant_s"):
        if k in d:
            kw[k] = float(d[k])
    kw.update(overrides)
    return RunnerConfig(**kw)
