"""``designkit`` command line. Thin: parse, call the library, write, return an exit code.

Each sub-command lives in its own module (``designkit/commands/<name>.py`` or ``cad/cli.py``)
exposing ``add_arguments(parser)`` and ``run(args) -> int``; only the chosen one is imported,
so ``designkit map`` never pays for build123d or pyvista.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import signal
import sys
import threading

from .commands.common import join_negative_values
from firmware_io.errors import FirmwareIOError

from . import __version__
from .errors import DesignkitError

COMMANDS: dict[str, tuple[str, str]] = {
    "report": ("designkit.commands.report", "main job: whole pipeline on a design -> report folder"),
    "check": ("designkit.commands.check", "every design rule and constraint: value, limit, fix"),
    "optimize": ("designkit.commands.optimize", "the real device: coil, wire, saturating core"),
    "sweep": ("designkit.commands.sweep", "evaluate a grid of coil designs (parallel)"),
    "map": ("designkit.commands.map", "force-current map file for the controller"),
    "cad": ("cad.cli", "printable parts (STL/STEP/3MF) and assembly"),
    "fem": ("designkit.commands.fem", "GetDP FEM cross-check of coil + core"),
    "viz": ("designkit.commands.viz", "off-screen pyvista figures"),
    "scene": ("designkit.commands.scene", "compile a virtual object for the runner (ch. 4)"),
    "run": ("designkit.commands.run", "the rendering runner on the simulated device"),
    "calibrate": ("designkit.commands.calibrate", "fit the as-built device to field readings"),
    "sensors": ("designkit.commands.sensors", "plan a sensor layout from the Cramer-Rao bound"),
}


def _usage() -> str:
    width = max(map(len, COMMANDS))
    rows = "\n".join(f"  {name:<{width}}  {desc}" for name, (_, desc) in COMMANDS.items())
    return (
        "usage: designkit COMMAND [options]   (designkit COMMAND --help for its options)\n\n"
        f"commands:\n{rows}\n"
    )


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(_usage())
        return 0 if argv else 2
    if argv[0] == "--version":
        print(__version__)
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"designkit: unknown command {name!r}\n\n{_usage()}", file=sys.stderr)
        return 2
    interrupted = False
    previous = _watch_ctrl_c()
    try:
        return _dispatch(name, rest)
    except KeyboardInterrupt:
        interrupted = True
    except Exception as exc:  # an import or library call cut short by Ctrl-C
        if not (_SIGINT_SEEN or _caused_by_ctrl_c(exc)):
            raise
        interrupted = True
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
        if interrupted:  # after the except block: progress bars closed, staged outputs gone
            gc.collect()
    # Ctrl-C: staged folders and atomic files were removed on the way out; one line, exit 130
    print(f"designkit {name}: interrupted; nothing written", file=sys.stderr)
    return 130


def _dispatch(name: str, rest: list[str]) -> int:
    """Import the sub-command, parse its options, run it; errors as one line, exit 1 or 2."""
    module_name, desc = COMMANDS[name]
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name and module_name.startswith(exc.name):
            print(f"designkit {name}: not available in this build ({exc})", file=sys.stderr)
            return 2
        raise
    parser = argparse.ArgumentParser(prog=f"designkit {name}", description=desc)
    module.add_arguments(parser)
    try:
        args = parser.parse_args(join_negative_values(rest))
    except SystemExit as exc:  # argparse exits on --help and on bad options
        return int(exc.code or 0)
    try:
        return int(module.run(args) or 0)
    except DesignkitError as exc:
        print(f"designkit {name}: error: {exc}", file=sys.stderr)
        return 1
    except FirmwareIOError as exc:  # e.g. a map file refused by its (numpy-only) reader
        print(f"designkit {name}: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # a disk or permission problem is a message, not a traceback
        print(f"designkit {name}: error: {exc}", file=sys.stderr)
        return 1


_SIGINT_SEEN = False


def _watch_ctrl_c():
    """Python's own Ctrl-C handler, also noting that it fired (an extension module whose
    import is cut short raises a plain ImportError); returns the handler it replaced."""
    global _SIGINT_SEEN
    _SIGINT_SEEN = False
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):
        global _SIGINT_SEEN
        _SIGINT_SEEN = True
        signal.default_int_handler(signum, frame)

    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return None
    return signal.signal(signal.SIGINT, handler)


def _caused_by_ctrl_c(exc: BaseException) -> bool:
    """True when a KeyboardInterrupt is in ``exc``'s chain of causes and contexts."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
