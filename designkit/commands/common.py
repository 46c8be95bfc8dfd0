"""What every ``designkit`` sub-command does the same way.

* output paths are checked before any work (:func:`check_output`), so a wrong ``--out`` costs
  nothing and never ends in a traceback;
* a folder job writes into a hidden staging folder next to ``--out`` and moves its files into
  place only when it succeeds (:func:`staged_folder`): a failing run leaves nothing behind;
* one progress flag, ``--no-progress`` (``--quiet`` is the same flag), in every command;
* per-coil currents: ``--currents I1,I2,...`` (a leading minus works: :func:`join_negative_values`)
  checked against the design's per-coil limit and total budget unless ``--allow-over-limit``;
* lengths (:func:`parse_length`): a number with an optional unit, ``40mm``, ``4cm``, ``0.04m``;
  a bare number is millimetres in an option (``--spacing 10``) and metres in a design key whose
  name ends in ``_m`` (``--param length_m=0.02:0.1:5``), as the key's name says;
* a rule no varied key can fix is named before a sweep or an optimization starts
  (:func:`unfixable_rules`).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Iterator, Sequence

from .. import rules
from ..design import NAMED_DESIGNS
from ..errors import BadInputError

VALUE_OPTIONS = ("--currents", "--current", "--mesh-at")
"""Options whose value may start with a minus sign (a negative current or coordinate)."""

_NEGATIVE = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)


def join_negative_values(argv: Sequence[str], options: Sequence[str] = VALUE_OPTIONS) -> list[str]:
    """``["--currents", "-6,0"]`` -> ``["--currents=-6,0"]``.

    argparse takes a value starting with "-" for an option unless it is a single plain number,
    so ``--currents -6,0,...`` failed with "expected one argument".
    """
    out: list[str] = []
    i = 0
    argv = list(argv)
    while i < len(argv):
        a = argv[i]
        if a in options and i + 1 < len(argv) and _NEGATIVE.match(argv[i + 1]):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


# ----------------------------------------------------------------------------- outputs
def check_output(path: str | Path, *, folder: bool, param: str = "--out") -> Path:
    """Raise :class:`BadInputError` unless ``path`` can be written as a folder (``folder=True``)
    or as a file; called before any computation. The folder ``path`` is in must exist: a
    command makes the folder ``--out`` names (a folder output), never the ones above it (a
    mistyped parent is an error, not a new tree)."""
    path = Path(path)
    if folder and path.exists() and not path.is_dir():
        raise BadInputError(param, "a folder to write into (this path is an existing file)",
                            str(path))
    if not folder and path.is_dir():
        raise BadInputError(param, "a file name (this path is an existing folder)", str(path))
    parent = path.absolute().parent
    if not parent.exists():
        missing = next(p for p in reversed(parent.parents) if not p.exists()) \
            if not parent.parent.exists() else parent
        raise BadInputError(param, f"a path in an existing folder ({missing} does not exist; "
                            f"designkit makes no folder above the one {param} names)",
                            str(path))
    if not parent.is_dir():
        raise BadInputError(param, f"a path under a folder ({parent} is a file)", str(path))
    if not _writable(parent):
        raise BadInputError(param, f"a path in a writable folder ({parent} is not)", str(path))
    return path


def _writable(folder: Path) -> bool:
    """True when a file can be created in ``folder`` (tried: permission bits say nothing to
    root, nor about read-only or virtual file systems)."""
    if not os.access(folder, os.W_OK | os.X_OK):
        return False
    try:
        fd, probe = tempfile.mkstemp(prefix=".designkit-probe.", dir=folder)
    except OSError:
        return False
    os.close(fd)
    os.unlink(probe)
    return True


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def staged_folder(out: str | Path, param: str = "--out") -> Iterator[Path]:
    """Yield an empty staging folder next to ``out`` (its folder must exist:
    :func:`check_output`); on success move everything written there into ``out`` (files
    already in ``out`` and not rewritten stay), on failure delete it."""
    out = check_output(out, folder=True, param=param).absolute()
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.staging.", dir=out.parent))
    os.chmod(stage, 0o777 & ~_umask())  # mkdtemp makes 0700; a plain mkdir would not
    try:
        yield stage
        if not out.exists():
            os.replace(stage, out)
        else:
            for src in sorted(stage.rglob("*")):
                dst = out / src.relative_to(stage)
                if src.is_dir():
                    dst.mkdir(exist_ok=True)
                else:
                    dst.parent.mkdir(parents=True, exist_ok=True)
                    os.replace(src, dst)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


# ----------------------------------------------------------------------------- design
def add_design_argument(parser: argparse.ArgumentParser, extra: str = "") -> None:
    """``--design``: a TOML file or a shipped design's name (the names listed in the help)."""
    names = ", ".join(n for n in NAMED_DESIGNS if n != "thesis-default")
    parser.add_argument("--design", default=None, metavar="FILE.toml|NAME",
                        help=f"design TOML file or a shipped design: {names} "
                             f"(default: thesis, the embedded thesis device){extra}")


# ----------------------------------------------------------------------------- progress
def add_progress_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-progress", "--quiet", dest="no_progress", action="store_true",
                        help="no progress bar (without a terminal the bar prints plain lines)")


def show_progress(args: argparse.Namespace) -> bool:
    return not getattr(args, "no_progress", False)


# ----------------------------------------------------------------------------- currents
def add_currents_arguments(parser: argparse.ArgumentParser, help: str) -> None:
    parser.add_argument("--currents", default=None, metavar="I1,I2,...", help=help)
    parser.add_argument("--allow-over-limit", action="store_true",
                        help="accept currents above the design's per-coil limit "
                             "(drive.max_current_a) and total budget (drive.total_current_a)")


def parse_currents(text: str | None) -> list[float] | None:
    """``"6,0,-6,..."`` -> list of floats (A); None stays None (the default currents)."""
    if text is None:
        return None
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        raise BadInputError("--currents", "comma-separated numbers in A, one per coil",
                            text) from None
    if not all(math.isfinite(x) for x in vals):
        raise BadInputError("--currents", "finite numbers in A", text)
    return vals


def check_current_limit(design, currents, *, allow: bool, param: str = "--currents") -> None:
    """Per-coil |I| <= ``drive.max_current_a`` and sum |I| <= ``drive.total_current_a``, unless
    ``allow`` (``--allow-over-limit``)."""
    if allow or currents is None:
        return
    vals = [abs(float(x)) for x in currents]
    limit, budget = design.drive.max_current_a, design.drive.total_current_a
    worst = max(vals, default=0.0)
    # a relative slack for decimal round-trips ("6.0000000001" from a script is still 6 A)
    if worst > limit * (1 + 1e-9):
        raise BadInputError(param, f"at most {limit:g} A per coil (drive.max_current_a)",
                            ",".join(f"{x:g}" for x in currents),
                            "Pass --allow-over-limit to go above the design's limit.")
    if sum(vals) > budget * (1 + 1e-9):
        raise BadInputError(param, f"a sum of |I| of at most {budget:g} A "
                                   f"(drive.total_current_a)",
                            ",".join(f"{x:g}" for x in currents),
                            "Pass --allow-over-limit to go above the design's budget.")


ROUND_OFF = 1e-9
"""A constraint margin smaller than this fraction of its limit (or value) is round-off: an active
constraint met exactly, printed as 0."""


def shown_margin(constraint: dict) -> float:
    """A rule's margin (its own unit) with round-off of an active constraint set to 0."""
    m = float(constraint["margin"])
    scale = max(abs(float(constraint["limit"])), abs(float(constraint["value"])))
    return 0.0 if abs(m) <= ROUND_OFF * scale else m


# ----------------------------------------------------------------------------- lengths
LENGTH_UNITS = {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6}
"""Units a length on the command line may carry: ``40mm``, ``4cm``, ``0.04m``, ``500um``."""

_LENGTH = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-z]*)\s*$")


def parse_length(text: str | float, param: str, *, valid_m: tuple[float, float] | None,
                 bare: str = "mm") -> float:
    """A length of the command line, in metres.

    ``text``: a number with an optional unit of :data:`LENGTH_UNITS`; ``bare``: the unit of a
    bare number ('mm' in an option, 'm' in a design key ending in ``_m``). ``valid_m``: the
    closed range (m) the length must lie in (None: any finite length). Raises
    :class:`BadInputError` naming ``param``, the range (in ``bare`` units) and the value; when
    the number would lie in the range in the other unit (m for mm, mm for m), the message says
    which unit to write.
    """
    raw = str(text).strip()
    m = _LENGTH.match(raw.lower())
    lo, hi = (-math.inf, math.inf) if valid_m is None else valid_m
    scale = LENGTH_UNITS[bare]
    where = "" if valid_m is None else f" in [{lo / scale:g}, {hi / scale:g}] {bare}"
    valid = f"a length{where} (a number is {bare}; or give the unit: 10mm, 1cm, 0.01m)"
    if m is None or (m.group(2) and m.group(2) not in LENGTH_UNITS):
        raise BadInputError(param, valid, raw)
    number = float(m.group(1))
    value = number * LENGTH_UNITS[m.group(2) or bare]
    if not (math.isfinite(value) and lo <= value <= hi):
        hint = ""
        if not m.group(2):
            other = "m" if bare == "mm" else "mm"
            if lo <= number * LENGTH_UNITS[other] <= hi:
                hint = (f"{'Metres' if other == 'm' else 'Millimetres'} where {bare} are "
                        f"expected? Write {number:g}{other}"
                        + (f" or {number * LENGTH_UNITS[other] / scale:g}." if other == "mm"
                           else "."))
        raise BadInputError(param, valid, raw, hint)
    return value


def parse_lengths(text: str, param: str, count: int, *, sep: str = ",",
                  valid_m: tuple[float, float], bare: str = "mm") -> tuple[float, ...]:
    """``count`` lengths separated by ``sep`` (``X,Y,Z``, ``LO:HI``), each as
    :func:`parse_length` (metres)."""
    parts = str(text).split(sep)
    if len(parts) != count:
        raise BadInputError(param, f"{count} lengths separated by {sep!r} (a number is {bare};"
                            f" or give the unit: 10mm, 1cm, 0.01m)", str(text))
    return tuple(parse_length(p, param, valid_m=valid_m, bare=bare) for p in parts)


# ----------------------------------------------------------------------------- rules
def unfixable_rules(design, varied: Sequence[str]) -> list[str]:
    """The rules of the rule book (:mod:`designkit.rules`) that ``design`` violates and that
    no key in ``varied`` can fix, one sentence each: every design a sweep or an optimization
    makes from ``design`` inherits them, so none can be feasible. ``varied``: the design keys
    the job changes, ``section.field`` or a whole table as ``section.``; a rule is unfixable
    when none of its keys (``Rule.keys``) is among them."""
    def moved(key: str) -> bool:
        return any(key == k or (k.endswith(".") and key.startswith(k)) for k in varied)

    return [f"every design breaks rule {r.name} ({r.message.rstrip('.')}) and "
            f"{', '.join(r.keys)} {'is' if len(r.keys) == 1 else 'are'} not varied: fix "
            f"{'it' if len(r.keys) == 1 else 'them'} in the design file"
            for r in rules.violations(design) if not any(moved(k) for k in r.keys)]


def say_unfixable(command: str, design, varied: Sequence[str]) -> list[str]:
    """Print :func:`unfixable_rules` at once, one line each on stderr (the job still runs:
    its numbers may be wanted all the same); returns them."""
    lines = unfixable_rules(design, varied)
    for line in lines:
        print(f"designkit {command}: note: {line}", file=sys.stderr, flush=True)
    return lines
