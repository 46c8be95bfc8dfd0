"""One progress bar for every long job: tqdm on a terminal, plain lines elsewhere.

``from ._progress import tqdm`` is a drop-in for ``from tqdm import tqdm``. When the stream is
not a terminal (a log file, CI, a pipe) tqdm's carriage-return redraws would pile up into one
unreadable line; there the bar writes a whole line at most every ``mininterval`` seconds
(default 5 s) instead.
"""

from __future__ import annotations

import sys

from tqdm import tqdm as _tqdm

__all__ = ["tqdm", "LineWriter"]


class LineWriter:
    """File-like wrapper that turns tqdm's ``\\r``-redraws into one line per update."""

    def __init__(self, stream):
        self.stream = stream

    @property
    def encoding(self):
        return getattr(self.stream, "encoding", None) or "utf-8"

    def write(self, text: str) -> int:
        # tqdm redraws with "\r" + status (+ cursor-up codes when nested); keep the status only
        text = text.replace("\r", "").replace("\x1b[A", "")
        if text.strip():
            self.stream.write(text.rstrip() + "\n")
        return len(text)

    def flush(self) -> None:
        self.stream.flush()

    def isatty(self) -> bool:
        return False


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def tqdm(*args, **kwargs):
    """``tqdm.tqdm`` with line-wise output when the target stream is not a terminal."""

    stream = kwargs.get("file") or sys.stderr
    if not isinstance(stream, LineWriter) and not _isatty(stream):
        kwargs["file"] = LineWriter(stream)
        kwargs.setdefault("mininterval", 5.0)
        kwargs.setdefault("ascii", True)
        kwargs["dynamic_ncols"] = False
        kwargs.setdefault("ncols", 100)
    return _tqdm(*args, **kwargs)
