"""Drawing a report's figures in worker processes.

Drawing is most of a report's time and each figure is independent, so on a machine with two
CPUs or more the figures are drawn by forked worker processes (:class:`Painter`). The pool is
started before the logs are read: the workers load matplotlib and build the figures that are
redrawn per log (:func:`ropod_sysid.report.figures.warm`) while this process reads the logs, and
this process never loads matplotlib. A figure is named by its function in
:mod:`ropod_sysid.report.figures` and drawn from arrays; the PNGs come back as bytes and are
identical to those drawn in one process.
"""

from __future__ import annotations

import base64
import multiprocessing
import os
import pickle
import queue
import signal
import sys
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from multiprocessing.process import BaseProcess

    from ropod_sysid.platform import Layout

__all__ = ["Drawn", "Painter", "Pending", "default_workers", "png_uri"]


def png_uri(data: bytes) -> str:
    """A PNG as a ``data:`` URI (the report is one self-contained file)."""
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


DRAWERS_ENV = "ROPOD_SYSID_DRAWERS"  # the number of drawing processes, if set (1: in-process)


def default_workers() -> int:
    """Processes that draw the figures: :func:`ropod_sysid.forked.default_processes` with the
    environment's :data:`DRAWERS_ENV` (1: this process)."""
    from ropod_sysid.forked import default_processes

    return default_processes(DRAWERS_ENV)


def _figure(name: str, args: tuple[Any, ...]) -> bytes:
    from ropod_sysid.report import figures

    return getattr(figures, name)(*args)


PARENT_CHECK_S = 1.0  # how often an idle drawing process checks that its parent lives [s]


def _draw_loop(tasks: Any, results: Any, lock: Any, stop: Any) -> None:
    """Do the work of ``tasks`` ((id, function, args), pickled; None ends) into the connection
    ``results`` (shared: sent under ``lock``); after ``stop`` is set, or when this process's
    parent has ended, draw nothing more."""
    parent = os.getppid()

    def send(item: tuple[int, bool, Any]) -> None:
        with lock:
            results.send(item)

    while True:
        try:
            task = tasks.get(timeout=PARENT_CHECK_S)
        except queue.Empty:
            if os.getppid() != parent:  # orphaned: the process that asked has gone
                return
            continue
        if task is None:
            return
        if stop.is_set():
            continue
        key, func, args = pickle.loads(task)
        try:
            drawn = func(*args)
        except Exception as exc:  # raised in the parent where the figure is used
            try:
                send((key, False, exc))
            except Exception:  # an exception that does not pickle
                send((key, False, RuntimeError(f"{type(exc).__name__}: {exc}")))
        else:
            try:
                send((key, True, drawn))
            except Exception as exc:  # a result that does not pickle: the parent must hear
                send((key, False, RuntimeError(f"{func.__name__}: its result cannot be "
                                               f"sent ({type(exc).__name__}: {exc})")))


def _painter(tasks: Any, results: Any, lock: Any, stop: Any, workers: int, warm: bool,
             layout: Layout | None, reader: Any) -> None:
    """The first drawing process: loads matplotlib and builds the per-log figures once
    (:func:`ropod_sysid.report.figures.warm`), then forks the other ``workers`` − 1, which so
    start warm; all draw.
    Ctrl-C is the parent's to handle (it stops the drawing). ``reader``: the parent's end of
    ``results``, closed here (so that a drawer whose parent has gone gets an error sending,
    and the parent's end sees the last drawer leave)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    reader.close()
    if warm:
        from ropod_sysid.report import figures

        figures.warm(layout)
    children = []
    for _ in range(workers - 1):
        pid = os.fork()
        if pid == 0:  # a forked drawer: ends without this process's exit handlers
            code = 1
            try:
                _draw_loop(tasks, results, lock, stop)
                code = 0
            finally:
                os._exit(code)
        children.append(pid)
    _draw_loop(tasks, results, lock, stop)
    for pid in children:
        os.waitpid(pid, 0)


class Pending:
    """Work being done by a painter; :meth:`get` waits for its result."""

    def __init__(self, result: Any = None, wait: Callable[[], Any] | None = None) -> None:
        self._result = result
        self._wait = wait

    def get(self) -> Any:
        if self._wait is not None:
            self._result, self._wait = self._wait(), None
        return self._result


class Drawn(Pending):
    """A figure being drawn; :meth:`uri` waits for it."""

    def uri(self) -> str:
        return png_uri(self.get())


class Painter:
    """Draws figures of :mod:`ropod_sysid.report.figures` in ``workers`` forked processes
    (default :func:`default_workers`) or, with 1, in this process. ``layout``: the platform's
    log layout, for the workers to build the per-log figures in advance. Use it as a context
    manager, so that the workers end (at once on an error).

    One process is forked from this one; it loads matplotlib and builds the per-log figures
    while this process reads the logs, then forks the other workers, which so start warm
    (matplotlib loaded and the figures built once, not once per worker: 0.7 s of CPU each on
    the shipped sample). The workers take the figures from one queue in the order they are
    asked for; a thread here collects the PNGs as they come."""

    def __init__(self, workers: int | None = None, layout: Layout | None = None) -> None:
        n = default_workers() if workers is None else workers
        if n < 1:
            raise ValueError(f"workers {n}: at least 1")
        self.workers = n
        self.pool: BaseProcess | None = None  # the first drawing process
        if n == 1:
            return
        ctx = multiprocessing.get_context("fork")
        # a parent that has drawn before passes its fonts and figures on through the fork:
        # the workers then need no warming up
        warm = "ropod_sysid.report.figures" not in sys.modules
        self._tasks = ctx.Queue()  # fed by a thread here: asking never waits for a worker
        self._results, results = ctx.Pipe(duplex=False)
        self._stop = ctx.Event()
        self._done: dict[int, tuple[bool, Any]] = {}
        self._ready = threading.Condition()
        self._next = 0
        self._ended = False
        self.pool = ctx.Process(target=_painter, name="ropod-sysid-painter", daemon=True,
                                args=(self._tasks, results, ctx.Lock(), self._stop, n, warm,
                                      layout, self._results))
        self.pool.start()
        results.close()  # the drawers hold the sending ends: the last to end ends the results
        self._collector = threading.Thread(target=self._collect, daemon=True,
                                           name="ropod-sysid-painter-results")
        self._collector.start()

    def _collect(self) -> None:
        """Take the workers' results as they come, until the last worker has ended."""
        while True:
            try:
                key, ok, value = self._results.recv()
            except (EOFError, OSError):
                break
            with self._ready:
                self._done[key] = (ok, value)
                self._ready.notify_all()
        with self._ready:
            self._ended = True
            self._ready.notify_all()

    def _result(self, key: int) -> bytes:
        """The PNG of figure ``key`` (its worker's error raised here)."""
        with self._ready:
            while key not in self._done:
                if self._ended:
                    raise RuntimeError("the drawing processes ended before the figure was "
                                       "drawn")
                self._ready.wait()
            ok, value = self._done.pop(key)
        if not ok:
            raise value
        return value

    def submit(self, func: Callable[..., Any], *args: Any) -> Pending:
        """``func(*args)`` (a module's function; arguments and result picklable), done now or
        by a worker."""
        if self.pool is None:
            return Pending(func(*args))
        key = self._next
        # pickled here, not by the queue's feeder thread: work that does not pickle raises in
        # the caller instead of never reaching a worker (which the caller would wait for)
        task = pickle.dumps((key, func, args), protocol=pickle.HIGHEST_PROTOCOL)
        self._next += 1
        self._tasks.put(task)
        return Pending(wait=lambda: self._result(key))

    def draw(self, name: str, *args: Any) -> Drawn:
        """The figure ``figures.<name>(*args)`` (PNG bytes), drawn now or by a worker."""
        pending = self.submit(_figure, name, args)
        return Drawn(pending._result, pending._wait)

    def draw_each(self, name: str, n: int, *args: Any) -> list[Drawn]:
        """The ``n`` figures ``figures.<name>(*args)`` draws in one piece of work (a list of
        PNG bytes), each as a :class:`Drawn` of its own."""
        pending = self.submit(_figure, name, args)
        if pending._wait is None:
            return [Drawn(png) for png in pending.get()]
        return [Drawn(wait=lambda k=k: pending.get()[k]) for k in range(n)]  # type: ignore[misc]

    def __enter__(self) -> Painter:
        return self

    def __exit__(self, *exc: object) -> None:
        first = self.pool
        if first is None:
            return
        if exc[0] is not None:  # the figures asked for are not drawn
            self._stop.set()
            self._tasks.cancel_join_thread()
        for _ in range(self.workers):
            self._tasks.put(None)
        first.join(None if exc[0] is None else 2.0)
        if first.is_alive():  # (its forked drawers end within PARENT_CHECK_S after it)
            first.terminate()
            first.join()
        else:
            self._collector.join()  # the drawers have all ended
        self._tasks.close()
        self.pool = None
