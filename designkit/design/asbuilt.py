"""The as-built device: per-coil deviations from the nominal design and the build tolerances.

A design's ``[asbuilt]`` table (TOML) describes the device that was actually built:

* ``[[asbuilt.coils]]``, one table per coil in the design's row-major order (none: nominal):
  ``dx_m``, ``dy_m``, ``dz_m`` (winding-centre offset, m), ``tilt_x_rad``, ``tilt_y_rad``
  (rotation vector about the array's x and y axes through the winding centre, rad), ``turns``
  (the wound count), ``core_relative_permeability``, ``core_offset_m`` (the core's axial offset
  from its nominal place, m, along the coil axis);
* ``[asbuilt.tolerances]``: the build tolerances (one standard deviation each), the priors of
  the calibration fit (:mod:`designkit.calibration`); defaults in :class:`BuildTolerances`;
* ``notes``: where the numbers come from (a calibration, a measured magnet moment).

The measured magnet moment is the design's ``[magnet]`` (magnetization and direction).
Every field is SI. :meth:`AsBuilt.apply` turns nominal coils (:class:`designkit.Coil`) into the
as-built ones; ``CoilArray.from_design`` calls it and keeps the Hall sensors where the nominal
coils place them (the sensor arrays are boards). Parameter vector order of the fit:
:data:`PARAMETERS` per coil. Reference: docs/calibration.md.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field, fields
from typing import Any, Mapping

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import BadInputError
from ..geometry.pose import Pose
from ..support import validate as v

PARAMETERS = ("dx_m", "dy_m", "dz_m", "tilt_x_rad", "tilt_y_rad", "turns_rel", "log_mu_r",
              "core_dz_m")
"""Fit parameters per coil: offsets (m), tilt (rad), turns / nominal - 1, ln(mu_r / nominal
mu_r), core axial offset (m)."""


@dataclass(frozen=True)
class BuildTolerances:
    """Build tolerances, one standard deviation each: the priors of the calibration fit."""

    position_m: float = 0.6e-3
    """Winding-centre offset per axis, m."""
    tilt_rad: float = 0.005
    """Tilt about x and about y, rad."""
    turns_relative: float = 0.02
    """Turns count, relative."""
    core_log_mu_r: float = 1.0
    """ln(mu_r): the steel's permeability is unknown within a factor ~e."""
    core_offset_m: float = 0.5e-3
    """Core axial offset (glued deeper or shallower), m."""
    magnet_moment_relative: float = 0.03
    """Magnet moment (remanence), relative."""

    def sigmas(self) -> np.ndarray:
        """Prior standard deviations in :data:`PARAMETERS` order, shape (8,)."""
        return np.array([self.position_m] * 3 + [self.tilt_rad] * 2
                        + [self.turns_relative, self.core_log_mu_r, self.core_offset_m])


@dataclass(frozen=True)
class CoilDeviation:
    """One coil as built; None keeps the nominal value (turns, core permeability)."""

    dx_m: float = 0.0
    dy_m: float = 0.0
    dz_m: float = 0.0
    tilt_x_rad: float = 0.0
    tilt_y_rad: float = 0.0
    turns: int | None = None
    core_relative_permeability: float | None = None
    core_offset_m: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            val = getattr(self, f.name)
            if f.name == "turns":
                if val is not None:
                    v.positive_int("asbuilt.coils.turns", val)
            elif f.name == "core_relative_permeability":
                if val is not None:
                    v.positive("asbuilt.coils.core_relative_permeability", val)
                    object.__setattr__(self, f.name, float(val))
            else:
                v.finite(f"asbuilt.coils.{f.name}", val)
                object.__setattr__(self, f.name, float(val))
        if math.hypot(self.tilt_x_rad, self.tilt_y_rad) > 0.2:
            raise BadInputError("asbuilt.coils.tilt", "at most 0.2 rad", (self.tilt_x_rad,
                                                                         self.tilt_y_rad))


@dataclass(frozen=True)
class AsBuilt:
    """The as-built description of a design (see the module docstring)."""

    coils: tuple[CoilDeviation, ...] = ()
    tolerances: BuildTolerances = field(default_factory=BuildTolerances)
    notes: str = ""

    def __post_init__(self):
        object.__setattr__(self, "coils", tuple(self.coils))

    def check(self, n_coils: int, has_core: bool) -> None:
        """The coil tables match the design: none, or one per coil; no core values without
        cores."""
        if self.coils and len(self.coils) != n_coils:
            raise BadInputError("asbuilt.coils", f"none or {n_coils} tables (one per coil, "
                                "row-major)", len(self.coils))
        if not has_core and any(c.core_relative_permeability is not None or c.core_offset_m
                                for c in self.coils):
            raise BadInputError("asbuilt.coils.core_*", "absent (the design has no cores)",
                                "given")

    def apply(self, coils):
        """Nominal coils (in the design's order) -> the as-built coils (tuple)."""
        if not self.coils:
            return tuple(coils)
        return tuple(_built(c, d) for c, d in zip(coils, self.coils))

    def parameters(self, nominal_coils) -> np.ndarray:
        """The deviations as fit parameters, shape (n_coils, 8), :data:`PARAMETERS` order."""
        out = np.zeros((len(nominal_coils), len(PARAMETERS)))
        for k, (c, d) in enumerate(zip(nominal_coils, self.coils)):
            out[k] = [d.dx_m, d.dy_m, d.dz_m, d.tilt_x_rad, d.tilt_y_rad,
                      (d.turns or c.turns) / c.turns - 1.0,
                      0.0 if c.core is None or d.core_relative_permeability is None
                      else math.log(d.core_relative_permeability
                                    / c.core.relative_permeability), d.core_offset_m]
        return out

    @classmethod
    def from_parameters(cls, nominal_coils, params, tolerances: BuildTolerances | None = None,
                        notes: str = "") -> "AsBuilt":
        """Fit parameters (n_coils, 8) -> an AsBuilt (turns rounded to whole turns)."""
        devs = []
        for c, p in zip(nominal_coils, np.asarray(params, dtype=float)):
            core = c.core is not None
            devs.append(CoilDeviation(
                *(float(x) for x in p[:5]), turns=max(1, int(round(c.turns * (1 + p[5])))),
                core_relative_permeability=(float(c.core.relative_permeability
                                                  * math.exp(p[6])) if core else None),
                core_offset_m=float(p[7]) if core else 0.0))
        return cls(tuple(devs), tolerances or BuildTolerances(), notes)

    def to_toml(self) -> str:
        """The ``[asbuilt]`` tables as TOML text."""
        lines = ["[asbuilt]", f"notes = {json.dumps(self.notes)}", "",
                 "[asbuilt.tolerances]"]
        lines += [f"{f.name} = {json.dumps(getattr(self.tolerances, f.name))}"
                  for f in fields(BuildTolerances)]
        for d in self.coils:
            lines += ["", "[[asbuilt.coils]]"]
            lines += [f"{f.name} = {json.dumps(getattr(d, f.name))}" for f in fields(d)
                      if getattr(d, f.name) is not None]
        return "\n".join(lines) + "\n"


def _built(coil, dev: CoilDeviation):
    """One nominal coil moved, tilted, rewound and with its core as built."""
    pos = np.asarray(coil.pose.position) + [dev.dx_m, dev.dy_m, dev.dz_m]
    rot = Rotation.from_rotvec([dev.tilt_x_rad, dev.tilt_y_rad, 0.0]).as_matrix() @ \
        coil.pose.matrix
    core = coil.core
    if core is not None:
        mu = (core.relative_permeability if dev.core_relative_permeability is None
              else dev.core_relative_permeability)
        core = dataclasses.replace(core, relative_permeability=mu,
                                   offset=core.offset + dev.core_offset_m)
    return dataclasses.replace(coil, turns=dev.turns or coil.turns, core=core,
                               pose=Pose.from_rotation(pos, rot))


def asbuilt_from_dict(data: Mapping[str, Any], source: str = "design") -> AsBuilt:
    """The ``[asbuilt]`` table of a design file -> :class:`AsBuilt`; unknown keys are errors."""
    if not isinstance(data, Mapping):
        raise BadInputError(f"{source}: [asbuilt]", "a table", data)
    allowed = {"coils", "tolerances", "notes"}
    unknown = set(data) - allowed
    if unknown:
        raise BadInputError(f"{source}: [asbuilt] key", f"one of {sorted(allowed)}",
                            sorted(unknown)[0])
    tol = _table(BuildTolerances, data.get("tolerances", {}), f"{source}: [asbuilt.tolerances]")
    for f in fields(BuildTolerances):
        v.positive(f"asbuilt.tolerances.{f.name}", getattr(tol, f.name))
    rows = data.get("coils", [])
    if not isinstance(rows, list):
        raise BadInputError(f"{source}: [[asbuilt.coils]]", "an array of tables", rows)
    coils = tuple(_table(CoilDeviation, r, f"{source}: [[asbuilt.coils]] #{k + 1}")
                  for k, r in enumerate(rows))
    notes = data.get("notes", "")
    if not isinstance(notes, str):
        raise BadInputError("asbuilt.notes", "a string", notes)
    return AsBuilt(coils, tol, notes)


def _table(cls, data, where: str):
    if not isinstance(data, Mapping):
        raise BadInputError(where, "a table", data)
    allowed = {f.name for f in fields(cls)}
    unknown = set(data) - allowed
    if unknown:
        raise BadInputError(f"{where} key", f"one of {sorted(allowed)}", sorted(unknown)[0])
    for key, val in data.items():
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            raise BadInputError(f"{where} {key}", "a number", val)
    return cls(**data)


def random_asbuilt(nominal_coils, tolerances: BuildTolerances, rng,
                   mu_r: float | None = None) -> AsBuilt:
    """A random as-built device within ``tolerances`` (normal deviations, one sigma each);
    ``mu_r``: every core's permeability (the unmeasured steel), else log-normal."""
    sig = tolerances.sigmas()
    params = rng.normal(size=(len(nominal_coils), len(PARAMETERS))) * sig
    if mu_r is not None:
        for k, c in enumerate(nominal_coils):
            if c.core is not None:
                params[k, 6] = math.log(mu_r / c.core.relative_permeability)
    return AsBuilt.from_parameters(nominal_coils, params, tolerances, "random as-built device")
