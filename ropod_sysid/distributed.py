"""Many logs on a Dask cluster: each log reduced on a worker, the triangles stacked here.

``--dask ADDRESS`` connects to a running ``dask.distributed`` scheduler; ``--workers N`` starts
a local cluster of N worker processes with one thread each. A task is one log: the worker
reads it in chunks and returns its QR triangles per DOF (a few kB), so nothing of size N
travels. The workers must be able to import ``ropod_sysid`` and read the log paths.

Dask is optional (``pip install 'ropod-sysid[dask]'``) and imported only when asked for;
without ``workers`` and ``address`` everything runs serially in this process.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from ropod_sysid.errors import InputError, one_line_warning
from ropod_sysid.progress import Progress

INSTALL_HINT = "pip install 'ropod-sysid[dask]'"
CONNECT_TIMEOUT = "20s"  # to reach an existing scheduler
PROCESSES = True  # --workers: worker processes (False: threads of this process, for tests)
Run = Callable[..., list]


def _dask() -> Any:
    try:
        import distributed
    except ImportError:
        raise InputError(f"--workers/--dask need Dask, which is not installed; install it with "
                         f"{INSTALL_HINT}") from None
    return distributed


def _serial(func: Callable[..., Any], items: Sequence[Any], quiet: bool = True,
            **kwargs: Any) -> list:
    out = []
    with Progress(len(items), "logs", quiet=quiet) as bar:
        for item in items:
            out.append(func(item, **kwargs))
            bar.update()
    return out


def _task(func: Callable[..., Any], item: Any, **kwargs: Any) -> Any:
    """One task on a worker, whose warnings (e.g. numpy's) print as one line, as here."""
    warnings.formatwarning = one_line_warning
    return func(item, **kwargs)


class DaskPool:
    """A Dask client on a new local cluster (``workers``) or an existing scheduler
    (``address``); :meth:`map` runs one task per item and gathers the results in order."""

    def __init__(self, workers: int | None = None, address: str | None = None,
                 processes: bool | None = None) -> None:
        if workers is not None and address is not None:
            raise InputError("--workers and --dask: give one of them (--dask uses the workers "
                             "of the existing cluster)")
        if workers is None and address is None:
            raise InputError("DaskPool needs workers or an address")
        if workers is not None and workers < 1:
            raise InputError(f"--workers {workers}: give a positive number of worker processes")
        self.workers = workers
        self.address = address
        self.processes = PROCESSES if processes is None else processes
        self.cluster: Any = None
        self.client: Any = None

    def __enter__(self) -> DaskPool:
        distributed = _dask()
        try:
            if self.address is not None:
                self.client = distributed.Client(self.address, timeout=CONNECT_TIMEOUT)
            else:
                with warnings.catch_warnings():
                    # the scheduler's HTTP endpoint moves to a free port if 8787 is taken
                    warnings.filterwarnings("ignore", message=r"Port \d+ is already in use")
                    self.cluster = distributed.LocalCluster(
                        n_workers=self.workers, threads_per_worker=1, processes=self.processes,
                        dashboard_address=None, silence_logs=logging.ERROR)
                self.client = distributed.Client(self.cluster)
        except (OSError, TimeoutError, RuntimeError) as exc:
            self.close()
            what = f"--dask {self.address}" if self.address else f"--workers {self.workers}"
            hint = ("check the address, e.g. tcp://host:8786" if self.address else
                    "the worker processes did not start")
            raise InputError(f"{what}: cannot start or reach the Dask cluster ({exc}); "
                             f"{hint}") from None
        return self

    def map(self, func: Callable[..., Any], items: Sequence[Any], **kwargs: Any) -> list:
        """``[func(item, **kwargs) for item in items]``, one task per item on the workers.
        A task's exception (e.g. :class:`InputError` for a bad log) is raised here."""
        futures = self.client.map(functools.partial(_task, func), list(items), pure=False,
                                  **kwargs)
        try:
            return self.client.gather(futures)
        finally:
            self.client.cancel(futures)

    def close(self) -> None:
        if self.client is not None:
            with contextlib.suppress(Exception):
                self.client.close()
            self.client = None
        if self.cluster is not None:
            with contextlib.suppress(Exception):
                self.cluster.close()
            self.cluster = None

    def __exit__(self, *exc: object) -> None:
        self.close()


@contextlib.contextmanager
def pool(workers: int | None = None, address: str | None = None,
         processes: bool | None = None, quiet: bool = True) -> Iterator[Run]:
    """A ``run(func, items, **kwargs) -> list`` for the duration of the block: on Dask with
    ``workers`` or ``address``, else serial. One cluster serves every call (e.g. every delay
    that ``--input-delay auto`` tries). Serially, a progress bar counts the logs on a terminal
    unless ``quiet``."""
    if workers is None and address is None:
        yield functools.partial(_serial, quiet=quiet)
        return
    with DaskPool(workers, address, processes) as p:
        yield p.map
