"""The runner's configuration: the drive record, period, rendered axes and fault policy.

The coils' R, L, supply, driver and current bounds are the map's drive record
(:class:`firmware_io.mapfile.drive.DriveRecord`, ``meta['drive']``, written by
designkit.model.electrical.drive_data), held whole in :attr:`RunnerConfig.drive`; its ``drives`` (one
:class:`firmware_io.hw.driver.CoilDrive` per coil) is what the runner's current path and the
PWM driver both read; :attr:`RunnerConfig.saturation` is the map's saturation table (the cores'
factor on A's columns, applied by the allocation). :func:`config_from_map` builds the
configuration from a map. SI units throughout; the fault and resume policy the fields tune is
described in docs/runner.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import BadInputError
from ..mapfile.drive import DriveRecord
from ..mapfile.saturation import SaturationTable


@dataclass(frozen=True)
class RunnerConfig:
    """Everything the loop needs besides its devices, SI units.

    Attributes
    ----------
    drive : DriveRecord
        The coils' R (at the operating temperature) and L -> the L/R lag the feed-forward
        compensates; the supply and the driver; the per-coil bound |I_k| <= u and the budget
        sum |I_k| <= I_t (A); the I^2 t guard's parameters; the PWM frequency.
    unipolar : bool
        0 <= I_k (the thesis' drive) instead of the driver's bipolar drive.
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
    saturation : SaturationTable or None
        The map's saturation correction (column k of A scaled by s_k(|I_k|)); None: linear
        cores (nothing to apply). How the allocation applies it: docs/runner.md, "Saturation".
    """

    drive: DriveRecord
    unipolar: bool = False
    control_period_s: float = 1e-3
    force_axes: str = "z"
    skip_force_n: float = 0.0
    feedforward: bool = True
    resume_after_s: float = 0.25
    resume_fixes: int = 3
    max_pwm_retries: int = 3
    overrun_factor: float = 10.0
    gate_risk: float = 1e-4
    alert_limit_m: float = 10e-3
    max_fix_age_s: float = 0.05
    saturation: SaturationTable | None = None

    def __post_init__(self):
        if not isinstance(self.drive, DriveRecord):
            raise BadInputError("drive", "a firmware_io.mapfile.drive.DriveRecord",
                                type(self.drive).__name__)
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
        if self.saturation is not None and not (
                isinstance(self.saturation, SaturationTable)
                and self.saturation.n_coils == self.drive.n_coils):
            raise BadInputError("saturation", f"None or a SaturationTable of {self.drive.n_coils} "
                                "coils (the map's)", type(self.saturation).__name__)

    @property
    def n_coils(self) -> int:
        return self.drive.n_coils


def config_from_map(fieldmap, **overrides) -> RunnerConfig:
    """RunnerConfig from the drive record a map file carries (``meta['drive']``, checked by
    :meth:`DriveRecord.from_dict`) and its saturation table (None when every factor is 1);
    ``overrides``: the other fields."""
    drive = DriveRecord.from_dict(fieldmap.meta.get("drive"), fieldmap.n_coils)
    table = fieldmap.saturation_table()
    overrides.setdefault("saturation", None if table.linear else table)
    return RunnerConfig(drive, **overrides)
