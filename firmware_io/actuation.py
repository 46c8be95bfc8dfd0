"""The actuation source's names where callers look for them: the interface
(:class:`ActuationSource`, defined in :mod:`firmware_io.mapfile.source`), its ``rows=`` /
``coils=`` check and the row order of A(p) (:data:`firmware_io.mapfile.format.ROWS`)."""

from .mapfile.format import ROWS
from .mapfile.source import ActuationSource, selection

__all__ = ["ROWS", "ActuationSource", "selection"]
