"""Splitting a vectorised evaluation over forked copies of this process.

Work that is a pure function of the rows of an array (a population of candidates, one value
each) splits over processes without changing a single value: each process evaluates its
share of the rows exactly as this one would. :class:`ForkedMap` forks the helper processes
once, when it is made, so they start with everything this process has built (models,
caches, compiled code) and receive only the rows; this process evaluates the first share
itself. Each process keeps one BLAS thread: two processes with threaded BLAS on two CPUs
lose several-fold to spinning threads.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["PROCESSES_ENV", "ForkedMap", "default_processes"]

PROCESSES_ENV = "ROPOD_SYSID_PROCESSES"  # processes for split work, if set (1: in-process)


def default_processes(env: str = PROCESSES_ENV) -> int:
    """Processes for work split by rows: the environment's ``env`` when set (a whole number
    ≥ 1; e.g. 1 where other processes already use every CPU, as parallel test workers do),
    else 2 where this process may run on two CPUs or more, else 1; always 1 where this
    platform cannot fork."""
    if "fork" not in multiprocessing.get_all_start_methods():
        return 1
    given = os.environ.get(env, "").strip()
    if given.isdigit() and int(given) >= 1:
        return int(given)
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cpus = os.cpu_count() or 1
    return 2 if cpus > 1 else 1


def _serve(func: Callable[[np.ndarray], np.ndarray], conn: Any) -> None:
    """A helper process: ``func`` of each array received, sent back, until None or the end
    of the connection (the parent has gone). Ctrl-C is the parent's to handle."""
    from threadpoolctl import threadpool_limits

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threadpool_limits(limits=1, user_api="blas")
    while True:
        try:
            x = conn.recv()
        except (EOFError, OSError):
            return
        if x is None:
            return
        try:
            conn.send((True, func(x)))
        except Exception as exc:  # raised in the parent, which waits for this share
            try:
                conn.send((False, exc))
            except Exception:  # an exception that does not pickle
                conn.send((False, RuntimeError(f"{type(exc).__name__}: {exc}")))


class ForkedMap:
    """``func`` (rows (S, …) → values (S, …), each row's values depending on that row alone)
    over ``processes`` processes (default :func:`default_processes`): calling it splits the
    rows into equal shares (:func:`numpy.array_split`), evaluates the first here and the others
    in processes forked when this object was made, and joins the values in order. Use it as a
    context manager (or :meth:`close` it) so that the helpers end."""

    def __init__(self, func: Callable[[np.ndarray], np.ndarray],
                 processes: int | None = None) -> None:
        n = default_processes() if processes is None else processes
        if n < 1:
            raise ValueError(f"processes {n}: at least 1")
        self.func = func
        self._conns: list[Any] = []
        self._procs: list[Any] = []
        self._limits: Any = None
        if n == 1:
            return
        from threadpoolctl import threadpool_limits

        ctx = multiprocessing.get_context("fork")
        for _ in range(n - 1):
            mine, theirs = ctx.Pipe()
            proc = ctx.Process(target=_serve, args=(func, theirs), daemon=True,
                               name="ropod-sysid-helper")
            proc.start()
            theirs.close()
            self._conns.append(mine)
            self._procs.append(proc)
        self._limits = threadpool_limits(limits=1, user_api="blas")

    @property
    def processes(self) -> int:
        return 1 + len(self._procs)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        if not self._conns or len(x) < 2:
            return self.func(x)
        parts = np.array_split(x, min(self.processes, len(x)))
        for conn, part in zip(self._conns, parts[1:], strict=False):
            conn.send(part)
        values = [self.func(parts[0])]
        failed: BaseException | None = None
        for conn, _ in zip(self._conns, parts[1:], strict=False):
            try:
                ok, value = conn.recv()
            except (EOFError, OSError):
                ok, value = False, RuntimeError("a helper process ended before its share "
                                                "was done")
            if ok:
                values.append(value)
            else:
                failed = failed or value
        if failed is not None:
            raise failed
        return np.concatenate(values)

    def close(self) -> None:
        """End the helper processes and restore this process's BLAS threads."""
        for conn in self._conns:
            with contextlib.suppress(OSError):  # a helper that has ended
                conn.send(None)
            conn.close()
        for proc in self._procs:
            proc.join(2.0)
            if proc.is_alive():
                proc.terminate()
                proc.join()
        self._conns, self._procs = [], []
        if self._limits is not None:
            self._limits.restore_original_limits()
            self._limits = None

    def __enter__(self) -> ForkedMap:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
