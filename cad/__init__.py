"""Printable parts of the coil array, derived from the same :class:`designkit.design.Design`.

Lengths in ``cad`` are millimetres (``_mm`` names); the only conversion from the SI design
happens in :func:`cad.params.from_design`. The package is split so that the cheap parts
import nothing heavy:

- :mod:`cad.params`    frozen parameter dataclasses and the SI -> mm conversion (no build123d)
- :mod:`cad.rules`     design-rule checks run before any file is written (no build123d)
- :mod:`cad.meshcheck` independent numpy checks of exported STL/3MF bytes (no build123d)
- :mod:`cad.parts`     build123d part functions: ``bobbin(p) -> Part`` etc., writing nothing
- :mod:`cad.assembly`  placements of every instance and the interference check
- :mod:`cad.export`    the export step: files, mesh checks, parts list, assembly PNG

Frame: the array frame of the design (coil top faces at z = 0, z up), in millimetres.
"""

from .params import CadParams, from_design

__all__ = ["CadParams", "from_design"]
