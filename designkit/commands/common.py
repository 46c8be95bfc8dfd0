"""What every ``designkit`` sub-command does the same way.

* output paths are checked before any work (:func:`check_output`), so a wrong ``--out`` costs
  nothing and never ends in a traceback;
* a folder job writes into a hidden staging folder next to ``--out`` and moves its files into
  place only when it succeeds (:func:`staged_folder`): a failing run leaves nothing behind;
* one progress flag, ``--no-progress`` (``--quiet`` is the same flag), in every command;
* per-coil currents: ``--currents I1,I2,...`` (a leading minus works: :func:`join_negative_values`)
  checked against the design's per-coil limit and total budget unless ``--allow-over-limit``.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Iterator, Sequence

from ..design import NAMED_DESIGNS
from ..errors import BadInputError

VALUE_OPTIONS = ("--currents", "--current")
"""Options whose value may start with a minus sign (a negative current)."""

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
    or as a file; called before any computation."""
    path = Path(path)
    if folder and path.exists() and not path.is_dir():
        raise BadInputError(param, "a folder to write into (this path is an existing file)",
                            str(path))
    if not folder and path.is_dir():
        raise BadInputError(param, "a file name (this path is an existing folder)", str(path))
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise BadInputError(param, f"a path under a folder ({parent} is a file)",
                                    str(path))
            if not _writable(parent):
                raise BadInputError(param, f"a path in a writable folder ({parent} is not)",
                                    str(path))
            break
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
    """Yield an empty staging folder next to ``out``; on success move everything written there
    into ``out`` (files already in ``out`` and not rewritten stay), on failure delete it."""
    out = check_output(out, folder=True, param=param).absolute()
    created = [p for p in reversed(out.parents) if not p.exists()]  # outermost first
    out.parent.mkdir(parents=True, exist_ok=True)
    stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.staging.", dir=out.parent))
    os.chmod(stage, 0o777 & ~_umask())  # mkdtemp makes 0700; a plain mkdir would not
    ok = False
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
        ok = True
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        if not ok:  # the parent folders this run made go too
            for folder in reversed(created):
                with contextlib.suppress(OSError):
                    folder.rmdir()


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
