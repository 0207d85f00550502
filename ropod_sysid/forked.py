"""Splitting a vectorised evaluation over forked copies of this process.

Work that is a function of the rows of an array (a population of candidates, one value
each) splits over processes without changing a single value when each process evaluates its
share exactly as this one would: where the work is batched and a value can differ in its last
digits with its batch's other rows (vectorised sums), each share must be whole batches (the
``pieces`` of :meth:`ForkedMap.__call__`). :class:`ForkedMap` forks the helper processes
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
from collections.abc import Callable, Sequence
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


def _cuts(sizes: np.ndarray, shares: int) -> list[int]:
    """Row indices that cut pieces of lengths ``sizes`` into ``shares`` non-empty shares of
    whole pieces, each cut at the piece boundary nearest its equal share of the rows."""
    bounds = np.cumsum(sizes)[:-1]  # the boundaries between pieces
    cuts: list[int] = []
    lo = 0  # the first boundary the next cut may take
    for k in range(1, shares):
        hi = len(bounds) - (shares - k)  # leave a piece for each share after this one
        j = lo + int(np.argmin(np.abs(bounds[lo:hi + 1] - k * sizes.sum() / shares)))
        cuts.append(int(bounds[j]))
        lo = j + 1
    return cuts


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
    """``func`` (rows (S, …) → values (S, …)) over ``processes`` processes (default
    :func:`default_processes`): calling it splits the rows into shares of about equal length,
    evaluates the first here and the others in processes forked when this object was made, and
    joins the values in order. Use it as a context manager (or :meth:`close` it) so that the
    helpers end."""

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

    def __call__(self, x: np.ndarray, pieces: Sequence[int] | None = None) -> np.ndarray:
        """``func`` of the rows x, split into shares of about equal length; ``pieces``: the
        lengths of consecutive runs of rows that no share may cut (default: single rows), e.g.
        where ``func`` batches the rows and a value may differ in its last digits with its
        batch's other rows: then each share must be whole batches."""
        sizes = np.ones(len(x), int) if pieces is None else np.asarray(pieces, int)
        if sizes.sum() != len(x) or (sizes < 1).any():
            raise ValueError(f"pieces {sizes.tolist()} do not make up {len(x)} rows")
        if not self._conns or len(sizes) < 2:
            return self.func(x)
        parts = np.split(x, _cuts(sizes, min(self.processes, len(sizes))))
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
