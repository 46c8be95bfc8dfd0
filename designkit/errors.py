"""Exceptions of designkit and the one input-checking message pattern.

Every exception inherits from a built-in (so ``except ValueError`` works) and from
:class:`DesignkitError` (so ``except DesignkitError`` catches everything designkit raises).
They keep their fields and pickle, because sweeps run in worker processes.
"""

from __future__ import annotations

import importlib

from firmware_io.errors import InputRangeError


class DesignkitError(Exception):
    """Base class of every error designkit raises on purpose."""


class BadInputError(InputRangeError, DesignkitError):
    """An input is outside its valid range.

    The message always names the parameter, the valid range and the value received:
    ``Input inner_radius must be > 0 m; instead received -0.012.`` (the pattern is
    :class:`firmware_io.errors.InputRangeError`'s, shared so both packages say it alike).
    """


class DesignRuleError(ValueError, DesignkitError):
    """A design is self-consistent in its numbers but violates a physical or manufacturing rule."""


class MissingDependencyError(ImportError, DesignkitError):
    """An optional heavy library is not installed."""

    def __init__(self, module: str, package: str, purpose: str):
        self.module = module
        self.package = package
        self.purpose = purpose
        super().__init__(f"{purpose} needs {module}: pip install {package}")

    def __reduce__(self):
        return (type(self), (self.module, self.package, self.purpose))


def require(module: str, package: str | None = None, purpose: str = "this feature"):
    """Import an optional module or raise :class:`MissingDependencyError` with the install hint."""

    try:
        return importlib.import_module(module)
    except ImportError as exc:  # pragma: no cover - exercised only without the package
        raise MissingDependencyError(module, package or module, purpose) from exc
