"""Evaluate a function over many rows in chunks: in this process, on local worker processes or
on a Dask cluster, with a progress bar from the first moment and a clean stop on Ctrl-C.

``run_chunks(fn, head, source, ...)`` calls ``fn(*head, rows)`` for consecutive slices
``rows = source.rows(start, stop)`` of a row source (``source.size`` rows in all; e.g. the
lazily indexed grid of a design sweep) and returns the results in row order. Chunks start at
one row, so the bar moves after the first evaluation whatever the job's size; later chunks are
sized from the measured cost per row to take about :data:`TARGET_CHUNK_S` (never more than
``max_chunk`` rows). At most two chunks per worker are in flight, so a million-row job is never
materialized or queued whole. Local workers ignore SIGINT (a Ctrl-C at the terminal reaches the
whole process group): the main process stops them all (``Pool.terminate``) and re-raises, so a
Ctrl-C or an error ends the job at once, with nothing left running.
"""

from __future__ import annotations

import multiprocessing
import os
import queue
import signal
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Protocol

from ..errors import BadInputError, require
from .progress import tqdm

TARGET_CHUNK_S = 2.0
"""Seconds of work a chunk is sized for once the cost per row is known (progress every few
seconds per worker, little overhead per task)."""
FIRST_CHUNK = 1
"""Rows of each worker's first chunk: the first progress comes after one evaluation."""
IN_FLIGHT_PER_WORKER = 2
"""Chunks submitted ahead per worker (one running, one waiting)."""


class RowSource(Protocol):
    """What :func:`run_chunks` reads: ``size`` rows, a slice of them by ``rows(start, stop)``."""

    size: int

    def rows(self, start: int, stop: int) -> Any: ...


@dataclass(frozen=True)
class ChunkRun:
    """Results of :func:`run_chunks`: ``results`` (each chunk's list of results, row order),
    wall seconds, workers used and the backend ('serial', 'processes', 'dask:ADDRESS')."""

    results: list
    seconds: float
    workers: int
    backend: str


class ChunkSizer:
    """Chunk sizes: :data:`FIRST_CHUNK` until a chunk's time per row is known, then
    :data:`TARGET_CHUNK_S` worth of rows (at least 1, at most ``max_chunk``)."""

    def __init__(self, max_chunk: int, target_s: float = TARGET_CHUNK_S):
        self.max_chunk = max_chunk
        self.target_s = target_s
        self.per_row_s: float | None = None

    def next_size(self) -> int:
        if self.per_row_s is None:
            return min(FIRST_CHUNK, self.max_chunk)
        n = self.target_s / max(self.per_row_s, 1e-9)
        return int(min(max(n, 1), self.max_chunk))

    def record(self, rows: int, seconds: float) -> None:
        """A chunk of ``rows`` took ``seconds`` of its worker's time (a running mean)."""
        if rows <= 0:
            return
        t = max(seconds, 0.0) / rows
        self.per_row_s = t if self.per_row_s is None else 0.5 * (self.per_row_s + t)


def timed_call(fn: Callable, head: tuple, rows) -> tuple[Any, float, int]:
    """``(fn(*head, rows), seconds it took, len(rows))``: the task a worker runs."""
    t0 = time.perf_counter()
    out = fn(*head, rows)
    return out, time.perf_counter() - t0, len(rows)


def _ignore_ctrl_c() -> None:
    """Worker initializer: Ctrl-C is the main process's to handle (it stops the workers)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def quiet_pool(n_workers: int, start_method: str | None = None):
    """A ``multiprocessing`` pool of ``n_workers`` processes that ignore Ctrl-C (the parent
    answers it by terminating them). While the pool forks, this process's Ctrl-C handler only
    notes the signal: raised inside a fork's at-fork hooks the KeyboardInterrupt would be
    swallowed there ("Exception ignored") and the parent would work on (a signal mask would
    not do: another thread takes the signal and the handler still runs in those hooks); a noted
    Ctrl-C terminates the new pool and is then passed to the handler.
    ``start_method``: None (the platform's default) or e.g. 'fork'."""
    ctx = multiprocessing.get_context(start_method)
    handler = (signal.getsignal(signal.SIGINT)
               if threading.current_thread() is threading.main_thread() else None)
    noted: list = []
    if callable(handler):
        signal.signal(signal.SIGINT, lambda signum, frame: noted.append(signum))
    try:
        pool = ctx.Pool(n_workers, initializer=_ignore_ctrl_c)
    finally:
        if callable(handler):
            signal.signal(signal.SIGINT, handler)
    if noted:
        pool.terminate()
        handler(signal.SIGINT, None)      # Python's handler raises KeyboardInterrupt
        raise KeyboardInterrupt
    return pool


def run_chunks(fn: Callable, head: tuple, source: RowSource, *, workers: int | None = None,
               scheduler: str | None = None, progress: tuple[str, str] | None = ("rows", "row"),
               max_chunk: int = 500) -> ChunkRun:
    """Evaluate ``fn(*head, source.rows(a, b))`` over every row of ``source``.

    ``workers``: local processes (default: the CPU count; 1 or a single row: this process);
    ``scheduler``: a dask.distributed scheduler address (the chunks run there instead);
    ``max_chunk``: the largest chunk, rows; ``progress``: the bar's (description, unit), None
    for none; the bar shows the total at once. A KeyboardInterrupt or a worker's exception
    stops every worker and propagates.
    """
    max_chunk = int(max_chunk)
    if max_chunk < 1:
        raise BadInputError("max_chunk", "a whole number >= 1", max_chunk)
    t0 = time.perf_counter()
    sizer = ChunkSizer(max_chunk)
    bar = None if progress is None else tqdm(total=source.size, desc=progress[0],
                                             unit=progress[1])
    done: dict[int, Any] = {}
    n_workers = workers or os.cpu_count() or 1
    try:
        if scheduler is not None:
            backend = f"dask:{scheduler}"
            n_workers = _run_dask(scheduler, fn, head, source, sizer, done, bar)
        elif n_workers == 1 or source.size <= 1:
            backend, n_workers = "serial", 1
            start = 0
            while start < source.size:
                stop = min(start + sizer.next_size(), source.size)
                out, seconds, n = timed_call(fn, head, source.rows(start, stop))
                _collect(done, start, out, seconds, n, sizer, bar)
                start = stop
        else:
            backend = "processes"
            _run_pool(n_workers, fn, head, source, sizer, done, bar)
    finally:
        if bar is not None:
            bar.close()
    return ChunkRun([done[k] for k in sorted(done)], time.perf_counter() - t0, n_workers,
                    backend)


def _collect(done: dict, start: int, out, seconds: float, n: int, sizer: ChunkSizer,
             bar) -> None:
    done[start] = out
    sizer.record(n, seconds)
    if bar is not None:
        bar.update(n)


def _run_pool(n_workers: int, fn, head, source, sizer: ChunkSizer, done: dict, bar) -> None:
    """The chunks on ``n_workers`` local processes, :data:`IN_FLIGHT_PER_WORKER` each ahead."""
    finished: queue.SimpleQueue = queue.SimpleQueue()
    pool = quiet_pool(n_workers)
    ok = False
    try:
        start, in_flight = 0, 0
        while start < source.size or in_flight:
            while start < source.size and in_flight < IN_FLIGHT_PER_WORKER * n_workers:
                stop = min(start + sizer.next_size(), source.size)
                pool.apply_async(timed_call, (fn, head, source.rows(start, stop)),
                                 callback=lambda r, s=start: finished.put((s, r, None)),
                                 error_callback=lambda e, s=start: finished.put((s, None, e)))
                start, in_flight = stop, in_flight + 1
            try:  # a bounded wait: the main thread stays responsive to Ctrl-C
                s, res, err = finished.get(timeout=0.2)
            except queue.Empty:
                continue
            in_flight -= 1
            if err is not None:
                raise err
            _collect(done, s, *res, sizer, bar)
        ok = True
    finally:
        if ok:
            pool.close()
        else:  # Ctrl-C or a failed chunk: nothing may keep running
            pool.terminate()
        pool.join()


def _run_dask(address: str, fn, head, source, sizer: ChunkSizer, done: dict, bar) -> int:
    """The chunks on a dask scheduler's workers (two per worker in flight); returns the
    number of workers."""
    distributed = require("dask.distributed", "dask[distributed]", "designkit sweep --scheduler")
    try:
        client = distributed.Client(address, timeout="10s")
    except OSError as exc:
        raise BadInputError("--scheduler", "the address of a running dask scheduler",
                            address, str(exc)) from None
    futures: dict = {}
    try:
        n = max(len(client.scheduler_info().get("workers", {})), 1)
        pending = distributed.as_completed()
        start = 0

        def submit():
            nonlocal start
            while start < source.size and len(futures) < IN_FLIGHT_PER_WORKER * n:
                stop = min(start + sizer.next_size(), source.size)
                fut = client.submit(timed_call, fn, head, source.rows(start, stop), pure=False)
                futures[fut.key] = (fut, start)
                pending.add(fut)
                start = stop

        submit()
        for fut in pending:
            _, s = futures.pop(fut.key)
            _collect(done, s, *fut.result(), sizer, bar)
            submit()
    finally:
        if futures:  # interrupted or failed: drop what is still queued there
            client.cancel([f for f, _ in futures.values()])
        client.close()
    return n

