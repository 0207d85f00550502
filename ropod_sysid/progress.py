"""A progress bar on stderr, shown only on a terminal and never with ``quiet``."""

from __future__ import annotations

import sys
import time
from types import TracebackType
from typing import TextIO


class Progress:
    """Minimal progress bar: ``with Progress(total, "simulate") as p: p.update(k)``.

    Draws on ``stream`` (stderr by default) only when it is a terminal and ``quiet`` is false;
    otherwise every call is a no-op, so library code can always use it.
    """

    def __init__(self, total: float, label: str = "", quiet: bool = False,
                 stream: TextIO | None = None, width: int = 30) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = (not quiet) and bool(getattr(self.stream, "isatty", lambda: False)())
        self.total = max(float(total), 1e-12)
        self.label = label
        self.width = width
        self.done = 0.0
        self._last = 0.0
        self._start = time.monotonic()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self.enabled:
            if exc_type is None:
                self.set(self.total, force=True)
            self.stream.write("\n")
            self.stream.flush()

    def update(self, amount: float = 1.0) -> None:
        self.set(self.done + amount)

    def set(self, done: float, force: bool = False) -> None:
        self.done = done
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._last < 0.1:
            return
        self._last = now
        frac = min(max(self.done / self.total, 0.0), 1.0)
        n = int(round(frac * self.width))
        elapsed = now - self._start
        self.stream.write(f"\r{self.label} [{'#' * n}{'.' * (self.width - n)}] "
                          f"{100 * frac:5.1f}% {elapsed:6.1f}s")
        self.stream.flush()
