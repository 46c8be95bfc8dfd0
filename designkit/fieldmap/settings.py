"""How densely a map samples: :class:`BuildSettings`, one frozen settings object of
:func:`designkit.fieldmap.build` (checked on creation, recorded in the map's meta).

Lengths in m. What each default costs and how accurate it is: docs/fieldmap.md.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import BadInputError
from ..support import validate as v

N_CHECK = 400
"""Random check points of a map over the design's whole box (its build's self-check)."""
SPACING_M = 0.01
"""x, y step of the bias force's residual grid when every core's axis is along the magnet's
moment (the per-core magnet tables then hold each core's whole pull), m."""
SPACING_TILTED_M = 0.005
"""... when some core's axis is not: the tables hold the pull of a moment along the core's
axis, and the residual grid carries the rest, as sharp near the core as the pull itself
(docs/fieldmap.md, "Tilted cores")."""


@dataclass(frozen=True)
class BuildSettings:
    """The sampling of a map (every field checked on creation: BadInputError naming it and
    its range).

    spacing, log_step
        x, y step (m) of the grid over magnet positions that carries what the per-core magnet
        tables miss (the bias force's core-to-core part, trilinear; for a core whose axis is
        not along the moment, the rest of its own pull too); its z steps grow from
        ``log_step`` x the height above the sources, never above ``spacing``. ``spacing``
        None: :data:`SPACING_M`, or :data:`SPACING_TILTED_M` when some core's axis is not
        along the magnet's moment (:meth:`resolved`).
    cell_ratio, layer_ratio, degree, fit_nodes
        A's harmonic cells (:func:`~designkit.fieldmap.plan.cell_layers`): cells no wider than
        ``cell_ratio`` and layers ``layer_ratio`` x their distance from the sources,
        potentials of degree ``degree`` (K = (degree + 1)^2 - 1 coefficients per cell and
        coil); each a sequence per layer from the lowest (the last entry for the layers above;
        ``layer_ratio`` may be one number); fitted on ``fit_nodes``^3 Chebyshev-Lobatto nodes
        per cell (shared across faces; each node is one evaluation of the coupled model).
    sensor_mode_tolerance
        The sensor field's core modes are kept while their singular value is above this
        fraction of the largest of their order (m = 0, 1, 2).
    rz_rho_scale, sensor_mode_rz_step, sensor_mode_rz_log_step, magnet_rz_step,
    magnet_rz_log_step
        The (rho, z) tables: rho steps grow as (1 + rho / rz_rho_scale)^2 (m); the sensor
        field's mode tables' rho step on the axis (m) and step in log(z - z_ref) (0.25 mm,
        4 %); the magnet tables' (0.5 mm, 2 %: the pull of one core falls ~z^-7 near it).
    n_check
        Random points where the finished map is compared with the coupled model (meta
        'errors'): n_check / |G| uniform points evaluated directly and their images under the
        box's symmetries G filled exactly (:func:`.symmetry.random_orbits`).
    """

    spacing: float | None = None
    log_step: float = 0.25
    cell_ratio: tuple = (1.0, 0.5)
    layer_ratio: tuple = (0.7, 0.5)
    degree: tuple = (12, 7)
    fit_nodes: int = 4
    sensor_mode_tolerance: float = 1e-3
    rz_rho_scale: float = 0.05
    sensor_mode_rz_step: float = 2.5e-4
    sensor_mode_rz_log_step: float = 0.04
    magnet_rz_step: float = 5e-4
    magnet_rz_log_step: float = 0.02
    n_check: int = N_CHECK

    def __post_init__(self):
        layer_ratio = self.layer_ratio
        if np.ndim(layer_ratio) == 0:
            layer_ratio = (layer_ratio,)
        if (np.ndim(self.cell_ratio) != 1 or np.ndim(self.degree) != 1
                or np.ndim(layer_ratio) != 1 or not len(self.cell_ratio)
                or not len(self.degree) or not len(layer_ratio)):
            raise BadInputError("cell_ratio, layer_ratio, degree", "sequences, per layer from "
                                "the lowest (the last one for the layers above)",
                                (self.cell_ratio, self.layer_ratio, self.degree))
        checked = {
            "spacing": None if self.spacing is None else v.in_range(
                "spacing", self.spacing, 5e-4, 0.1, "m"),
            "log_step": v.in_range("log_step", self.log_step, 1e-3, 2.0),
            "cell_ratio": tuple(v.in_range("cell_ratio", r, 0.05, 2.0) for r in self.cell_ratio),
            "layer_ratio": tuple(v.in_range("layer_ratio", r, 0.05, 2.0) for r in layer_ratio),
            "degree": tuple(int(v.in_range("degree", d, 2, 12)) for d in self.degree),
            "fit_nodes": int(v.in_range("fit_nodes", self.fit_nodes, 3, 8)),
            "sensor_mode_tolerance": v.in_range("sensor_mode_tolerance",
                                                self.sensor_mode_tolerance, 1e-8, 1e-1),
            "rz_rho_scale": v.in_range("rz_rho_scale", self.rz_rho_scale, 1e-3, 10.0, "m"),
            "sensor_mode_rz_step": v.in_range("sensor_mode_rz_step", self.sensor_mode_rz_step,
                                              1e-5, 0.01, "m"),
            "sensor_mode_rz_log_step": v.in_range("sensor_mode_rz_log_step",
                                                  self.sensor_mode_rz_log_step, 1e-3, 0.5),
            "magnet_rz_step": v.in_range("magnet_rz_step", self.magnet_rz_step, 1e-5, 0.01,
                                         "m"),
            "magnet_rz_log_step": v.in_range("magnet_rz_log_step", self.magnet_rz_log_step,
                                             1e-3, 0.5),
            "n_check": v.positive_int("n_check", self.n_check)}
        for name, value in checked.items():
            object.__setattr__(self, name, value)

    @classmethod
    def with_changes(cls, settings: "BuildSettings | None", changes: dict) -> "BuildSettings":
        """``settings`` (None: the defaults) with the fields in ``changes`` replaced; a name
        that is no field is refused (BadInputError naming it)."""
        base = cls() if settings is None else settings
        names = {f.name for f in dataclasses.fields(cls)}
        for key in changes:
            if key not in names:
                raise BadInputError("build setting", f"one of {sorted(names)}", key)
        return dataclasses.replace(base, **changes) if changes else base

    def resolved(self, tilted: bool) -> "BuildSettings":
        """The settings with ``spacing`` chosen when None: :data:`SPACING_TILTED_M` when
        ``tilted`` (some core's axis is not along the magnet's moment), else
        :data:`SPACING_M`."""
        if self.spacing is not None:
            return self
        return dataclasses.replace(self, spacing=SPACING_TILTED_M if tilted else SPACING_M)

    def meta(self, n_fit_points: int) -> dict:
        """The map's meta ``settings`` (lengths with their unit in the key)."""
        return {"spacing_m": self.spacing, "log_step": self.log_step,
                "cell_ratio": list(self.cell_ratio), "layer_ratio": list(self.layer_ratio),
                "degree": list(self.degree), "fit_nodes": self.fit_nodes,
                "n_fit_points": n_fit_points,
                "sensor_mode_tolerance": self.sensor_mode_tolerance,
                "rz_rho_scale_m": self.rz_rho_scale,
                "sensor_mode_rz_step_m": self.sensor_mode_rz_step,
                "sensor_mode_rz_log_step": self.sensor_mode_rz_log_step,
                "magnet_rz_step_m": self.magnet_rz_step,
                "magnet_rz_log_step": self.magnet_rz_log_step}
