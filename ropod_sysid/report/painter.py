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
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from multiprocessing.pool import AsyncResult

    from ropod_sysid.platform import Layout

__all__ = ["Drawn", "Painter", "default_workers", "png_uri"]


def png_uri(data: bytes) -> str:
    """A PNG as a ``data:`` URI (the report is one self-contained file)."""
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def default_workers() -> int:
    """Processes that draw the figures: 2 where this process may run on two CPUs or more and
    can fork, else 1 (this process)."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return 2 if cpus > 1 and "fork" in multiprocessing.get_all_start_methods() else 1


def _figure(name: str, args: tuple[Any, ...]) -> bytes:
    from ropod_sysid.report import figures

    return getattr(figures, name)(*args)


def _warm(layout: Layout | None) -> None:
    from ropod_sysid.report import figures

    figures.warm(layout)


class Drawn:
    """A figure being drawn; :meth:`uri` waits for it."""

    def __init__(self, result: bytes | AsyncResult[bytes]) -> None:
        self._result = result

    def uri(self) -> str:
        data = self._result if isinstance(self._result, bytes) else self._result.get()
        return png_uri(data)


class Painter:
    """Draws figures of :mod:`ropod_sysid.report.figures` in ``workers`` forked processes
    (default :func:`default_workers`) or, with 1, in this process. ``layout``: the platform's
    log layout, for the workers to build the per-log figures in advance. Use it as a context
    manager, so that the workers end (at once on an error)."""

    def __init__(self, workers: int | None = None, layout: Layout | None = None) -> None:
        n = default_workers() if workers is None else workers
        if n < 1:
            raise ValueError(f"workers {n}: at least 1")
        # a parent that has drawn before passes its fonts and figures on through the fork:
        # the workers then need no warming up
        warm = "ropod_sysid.report.figures" not in sys.modules
        self.pool = (multiprocessing.get_context("fork").Pool(
            n, _warm if warm else None, (layout,) if warm else ()) if n > 1 else None)

    def draw(self, name: str, *args: Any) -> Drawn:
        """The figure ``figures.<name>(*args)`` (PNG bytes), drawn now or by a worker."""
        if self.pool is None:
            return Drawn(_figure(name, args))
        return Drawn(self.pool.apply_async(_figure, (name, args)))

    def __enter__(self) -> Painter:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.pool is not None:
            if exc[0] is None:
                self.pool.close()
            else:
                self.pool.terminate()
            self.pool.join()
            self.pool = None
