"""The chunked pass's sources and threads: a log's chunks, read ahead; one BLAS thread.

:func:`iter_chunks` gives the samples of a log file (:func:`ropod_sysid.io.csvlog.iter_csv_log`
for CSV, also ``.csv.gz``; :func:`ropod_sysid.io.mcaplog.iter_mcap_log` for MCAP; a smart-wheel
CSV is read whole and then cut) or of an in-memory :class:`Log` as consecutive logs of at most
``chunk`` samples, their time base checked (:mod:`ropod_sysid.io.timebase`). :func:`_prefetch`
reads the next chunks in a background thread while one is processed, and
:func:`single_thread_blas` runs the block computations of :mod:`ropod_sysid.stream` with one
BLAS thread.
"""

from __future__ import annotations

import contextlib
import queue
import threading
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

from threadpoolctl import threadpool_limits

from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.io.timebase import Gaps, TimeBase, checked_chunks
from ropod_sysid.platform import Platform

if TYPE_CHECKING:
    from ropod_sysid.model import PlatformModel

DEFAULT_CHUNK = 30_000  # samples per chunk read and per block (25–30k measured fastest)
Source = str | Path | Log


# ---------------------------------------------------------------------------------------------
# chunk sources


def _iter_path(path: Path, platform: Platform, chunk: int, gaps: Gaps) -> Iterator[Log]:
    name = path.name.lower()
    if name.endswith((".csv", ".csv.gz")):
        smartwheel = _smartwheel_reader(path) if name.endswith(".csv") else None
        if smartwheel is not None:
            # the robot's raw layout needs whole-log processing (frame checks, rates)
            yield from _iter_log(smartwheel.read_smartwheel_csv(path, platform, gaps), chunk)
            return
        from ropod_sysid.io.csvlog import iter_csv_log

        yield from iter_csv_log(path, platform, chunk, gaps)
        return
    if name.endswith(".mcap"):
        from ropod_sysid.io.mcaplog import iter_mcap_log

        yield from iter_mcap_log(path, platform, chunk, gaps)
        return
    from ropod_sysid.io.rosbag import is_bag, iter_bag_log

    if is_bag(path):
        yield from iter_bag_log(path, platform, chunk, gaps)
        return
    raise _unknown_format(path)


def _unknown_format(path: Path) -> InputError:
    name = path.name.lower()
    suffix = "".join(path.suffixes[-2:]) if name.endswith(".gz") else path.suffix
    return InputError(f"{path}: unknown log format '{suffix}'; use .csv, .csv.gz, .mcap, a ROS "
                      "1 .bag or a rosbag2 directory")


def _smartwheel_reader(path: Path) -> ModuleType | None:
    """The smart-wheel reader (:mod:`ropod_sysid.io.smartwheel`, optional) when the .csv
    ``path`` is the robot's raw smart-wheel layout, else None."""
    try:
        from ropod_sysid.io import smartwheel
    except ImportError:  # pragma: no cover - the smart-wheel layout is optional
        return None
    test = getattr(smartwheel, "is_smartwheel_csv", None)
    return smartwheel if test is not None and test(path) else None


def _iter_log(log: Log, chunk: int) -> Iterator[Log]:
    for start in range(0, max(log.n_samples, 1), chunk):
        yield log.slice(start, start + chunk)


def iter_chunks(source: Source, platform: Platform, chunk: int = DEFAULT_CHUNK,
                gaps: Gaps = "error") -> Iterator[Log]:
    """The samples of a log file (or an in-memory :class:`Log`) as consecutive logs of at most
    ``chunk`` samples, read as they are needed, their time base checked
    (:mod:`ropod_sysid.io.timebase`; ``gaps="allow"`` lets gaps through). A pose from a
    tracker slower than the log is fused with wheel odometry (:mod:`ropod_sysid.tracker`)."""
    from ropod_sysid.tracker import dense_or_fused

    def read() -> Iterator[Log]:
        if isinstance(source, Log):
            return checked_chunks(_iter_log(source, chunk), TimeBase(source.source, gaps=gaps))
        return _iter_path(Path(source), platform, chunk, gaps)

    def model() -> PlatformModel:
        from ropod_sysid.model import PlatformModel

        return PlatformModel(platform)

    # a tracker slower than the log: its pose corrects the odometry's drift (two passes)
    return dense_or_fused(read(), read, model)


# the longest a CSV field of a float64 takes, with its comma: "-2.2250738585072014e-308,"
CSV_FIELD_BYTES = 25
CSV_SAMPLE_BYTES = 1 << 16  # read at a few places to estimate a CSV log's rows


def _csv_head(path: Path) -> tuple[int, bytes, bytes] | None:
    """A CSV log's data bytes (a ``.csv.gz`` log's by the size gzip records: the last
    member's, mod 2³²), its header line and the first bytes after it; None for other
    sources or when unreadable."""
    name = path.name.lower()
    try:
        if name.endswith(".csv"):
            size = path.stat().st_size
            with path.open("rb") as f:
                header = f.readline(1 << 16)
                head = f.read(CSV_SAMPLE_BYTES)
        elif name.endswith(".csv.gz"):
            import gzip

            with path.open("rb") as f:
                f.seek(-4, 2)
                size = int.from_bytes(f.read(4), "little")
            with gzip.open(path, "rb") as g:
                header = g.readline(1 << 16)
                head = g.read(4 * CSV_SAMPLE_BYTES)  # (no seeking: more of its head)
        else:
            return None
    except (OSError, EOFError, ValueError):
        return None
    return max(0, size - len(header)), header, head


def fewest_samples(source: Source) -> int:
    """A lower bound of a log's samples that costs no reading: for a CSV log (also
    ``.csv.gz``, by the size gzip records) its bytes over the longest row its header's fields
    can make (:data:`CSV_FIELD_BYTES` each); 0 for other sources, or when unsure. (The recipe
    check, :mod:`ropod_sysid.crosscheck`, forms its reference on a part of a log that is
    surely too long for ``fit``'s default check.)"""
    if isinstance(source, Log):
        return source.n_samples
    got = _csv_head(Path(source))
    return 0 if got is None else _fewest(got[0], got[1])


def _fewest(size: int, header: bytes) -> int:
    """:func:`fewest_samples` of a CSV log's data bytes ``size`` under ``header``."""
    return size // (CSV_FIELD_BYTES * (header.count(b",") + 1) + 1)


def estimated_samples(source: Source) -> int:
    """A log's samples as near as a few reads tell (its length for an in-memory log): a CSV
    log's data bytes over its rows' length, measured on :data:`CSV_SAMPLE_BYTES` after
    the header and, in a plain ``.csv``, the median of that and as many at the middle and at
    the end (a log's first rows, at rest, are short); 0 for other sources, or when unsure.
    Where the recipe check's reference windows go in a long log
    (:func:`ropod_sysid.crosscheck.reference_windows`)."""
    if isinstance(source, Log):
        return source.n_samples
    path = Path(source)
    got = _csv_head(path)
    if got is None:
        return 0
    size, header, head = got
    blocks = [head]
    if path.name.lower().endswith(".csv") and size > 3 * CSV_SAMPLE_BYTES:
        try:
            with path.open("rb") as f:
                for at in (len(header) + size // 2, len(header) + size - CSV_SAMPLE_BYTES):
                    f.seek(at)
                    blocks.append(f.read(CSV_SAMPLE_BYTES))
        except OSError:
            pass
    lengths = sorted(len(b) / b.count(b"\n") for b in blocks if b.count(b"\n"))
    fewest = _fewest(size, header)
    return max(fewest, round(size / lengths[len(lengths) // 2])) if lengths else fewest


def source_name(source: Source) -> str:
    return source.source if isinstance(source, Log) else str(source)


def _prefetch(chunks: Iterator[Log], depth: int = 2) -> Iterator[Log]:
    """Read the next chunks in a background thread (Arrow parses without the GIL) while the
    current one is processed; exceptions surface in order."""
    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()
    done = object()

    def work() -> None:
        try:
            for item in chunks:
                while not stop.is_set():
                    try:
                        q.put(item, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if stop.is_set():
                    return
            q.put(done)
        except BaseException as exc:  # handed to the consumer
            q.put(exc)
        finally:
            close = getattr(chunks, "close", None)
            if close is not None:
                close()

    thread = threading.Thread(target=work, daemon=True, name="ropod-sysid-reader")
    thread.start()
    try:
        while True:
            item = q.get()
            if item is done:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        with contextlib.suppress(queue.Empty):
            while True:
                q.get_nowait()
        thread.join()


# ---------------------------------------------------------------------------------------------
# BLAS threads


_blas_lock = threading.Lock()
_blas_users = 0
_blas_limits: threadpool_limits | None = None


@contextlib.contextmanager
def single_thread_blas() -> Iterator[None]:
    """Run the block computations with one BLAS thread (threadpoolctl).

    The blocks are tall and thin (QR leaves of 256 × 30, batched 3 × 3 solves); threaded
    OpenBLAS gains nothing there and, on a busy machine, loses several-fold to spinning
    threads. The setting is process-wide: the first of concurrent users (e.g. Dask worker
    threads) sets it, the last restores it.
    """
    global _blas_users, _blas_limits
    with _blas_lock:
        if _blas_users == 0:
            _blas_limits = threadpool_limits(limits=1, user_api="blas")
        _blas_users += 1
    try:
        yield
    finally:
        with _blas_lock:
            _blas_users -= 1
            if _blas_users == 0 and _blas_limits is not None:
                _blas_limits.restore_original_limits()
                _blas_limits = None


def check_source(source: Source, platform: Platform) -> None:
    """Cheap checks of a log before a long pass: the file exists, its format is known and, for
    a contract CSV, the header names the platform's columns (one-line :class:`InputError`)."""
    if isinstance(source, Log):
        return
    path = Path(source)
    name = path.name.lower()
    from ropod_sysid.io.rosbag import is_bag

    if not name.endswith((".csv", ".csv.gz", ".mcap")) and not is_bag(path):
        raise _unknown_format(path)
    if name.endswith(".csv") and path.is_file() and _smartwheel_reader(path) is not None:
        return
    if name.endswith((".csv", ".csv.gz")):
        from ropod_sysid.io.csvlog import check_csv_header

        check_csv_header(path, platform)
