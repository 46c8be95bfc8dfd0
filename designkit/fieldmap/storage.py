"""Writing a map atomically and loading it as a :class:`FieldMap`: the numpy-only
:class:`firmware_io.mapfile.MapFile` with designkit's errors (the same parameter, value and
valid range, as :class:`designkit.errors.BadInputError`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from firmware_io import mapfile as mf
from firmware_io.errors import BadInputError as _FirmwareBadInput

from ..errors import BadInputError
from ..support.atomic import atomic_path


def check_output(path) -> Path:
    """Refuse an output path that cannot take a map file, before any computation."""
    path = Path(path)
    if path.is_dir():
        raise BadInputError("--out", "a file path (a map file is one .npz file)",
                            f"{path} (an existing folder)",
                            f"Give a file name, e.g. {path / 'fieldmap.npz'}.")
    if path.suffix != ".npz":
        raise BadInputError("--out", "a path ending in .npz", str(path))
    parent = path.parent if str(path.parent) else Path(".")
    if parent.exists() and not parent.is_dir():
        raise BadInputError("--out", "a path whose folder is a folder",
                            f"{path} ({parent} is a file)")
    return path


def write(path, data: dict) -> Path:
    """Write the map atomically (never a half-written file at ``path``)."""
    path = check_output(path)
    try:
        with atomic_path(path, suffix=".npz") as tmp:
            mf.write(tmp, data["arrays"], data["meta"])
    except _FirmwareBadInput as exc:
        raise _translate(exc) from None
    return path


def _translate(exc: _FirmwareBadInput) -> BadInputError:
    return BadInputError(exc.name, exc.valid, exc.received, exc.hint)


class FieldMap:
    """A loaded map v2: :class:`firmware_io.mapfile.MapFile` with designkit's errors.

    Attributes and methods are the MapFile's (``actuation``, ``bias_force``,
    ``sensor_induced_field``, ``sensor_coil_field``, ``sensor_coil_gradient``,
    ``saturation_factor``, ``bounds``, ``meta``, ``n_coils``, ``n_sensors``,
    ``sensor_positions_m``, ``sensor_rotations``, ``moment_a_m2``, ``design_sha256``,
    ``max_current_a``, ``total_current_a``); ``outside='extrapolate'`` is the MapFile's
    ``extrapolate=True``. The sensors are the map's flat list (n_sensors, ...).
    """

    def __init__(self, mapfile: "mf.MapFile"):
        self.file = mapfile

    def __getattr__(self, name):
        return getattr(self.file, name)

    # the ActuationSource attributes, explicit (a runtime protocol check looks them up statically)
    @property
    def n_coils(self) -> int:
        return self.file.n_coils

    @property
    def bounds(self) -> tuple:
        """(lower (3,), upper (3,)) corners of the map's box, m."""
        return self.file.bounds

    @property
    def moment_a_m2(self) -> np.ndarray:
        """The finger magnet's moment (3,) A m^2 the bias force was computed for."""
        return self.file.moment_a_m2

    @property
    def design_sha256(self) -> str:
        return self.file.design_sha256

    @property
    def n_sensors(self) -> int:
        return self.file.n_sensors

    @property
    def sensor_positions_m(self) -> np.ndarray:
        """(n_sensors, 3) m, the map's flat sensor list."""
        return self.file.sensor_positions_m

    def _call(self, fn, *args):
        try:
            return fn(*args)
        except _FirmwareBadInput as exc:
            raise _translate(exc) from None

    @staticmethod
    def _outside(outside: str) -> bool:
        if outside not in ("error", "extrapolate"):
            raise BadInputError("outside", "'error' or 'extrapolate'", outside)
        return outside == "extrapolate"

    def actuation(self, points, *, outside: str = "error", rows=None,
                  coils=None) -> np.ndarray:
        """Coupled A: (3,) -> (8, n_coils), (n, 3) -> (n, 8, n_coils); T/A, T/(m A).
        ``rows``, ``coils``: index subsets (MapFile.actuation), shapes (.., len(rows),
        len(coils))."""
        try:
            return self.file.actuation(points, self._outside(outside), rows=rows, coils=coils)
        except _FirmwareBadInput as exc:
            raise _translate(exc) from None

    def bias_force(self, points, *, outside: str = "error") -> np.ndarray:
        """F0 at zero current, N: (3,) -> (3,), (n, 3) -> (n, 3)."""
        return self._call(self.file.bias_force, points, self._outside(outside))

    def sensor_induced_field(self, magnet_position_m, *, outside: str = "error") -> np.ndarray:
        """Magnet-induced core field at the sensors, T: (3,) -> (n_sensors, 3)."""
        return self._call(self.file.sensor_induced_field, magnet_position_m,
                          self._outside(outside))

    def sensor_coil_field(self, currents=None) -> np.ndarray:
        """(n_sensors, 3, n_coils) T/A, or (n_sensors, 3) T for ``currents`` (A)."""
        return self._call(self.file.sensor_coil_field, currents)

    def saturation_factor(self, currents) -> np.ndarray:
        """Per-coil factors (n_coils,) on the columns of A at ``currents`` (A)."""
        return self._call(self.file.saturation_factor, currents)


def load(path, design=None) -> FieldMap:
    """Load and validate a map file; with ``design``, also check it was built from it.

    Raises BadInputError for a missing, non-map, truncated, foreign, pre-v2, corrupted or
    mismatched file, saying how to rebuild it where that helps.
    """
    try:
        f = mf.MapFile.load(path)
    except _FirmwareBadInput as exc:
        raise _translate(exc) from None
    if design is not None and f.design_sha256 != design.spec_hash():
        raise BadInputError("map file", f"built from design {design.name!r} (SHA-256 "
                            f"{design.spec_hash()[:12]}...)",
                            f"{path} (design {f.meta.get('design_name')!r}, SHA-256 "
                            f"{f.design_sha256[:12]}...)",
                            "Rebuild it: designkit map --design <design.toml> --out <file.npz>")
    return FieldMap(f)
