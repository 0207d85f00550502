"""Reading and writing logs (CSV, MCAP) and parameter files."""

from __future__ import annotations

import hashlib
import os
import stat
import sys
from collections.abc import Sequence
from pathlib import Path

from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log, join_logs
from ropod_sysid.io.timebase import Gaps
from ropod_sysid.platform import Platform

LOG_SUFFIXES = (".csv", ".csv.gz", ".mcap")  # the formats written; also read: .bag, rosbag2


def log_format(path: str | Path) -> str:
    """The log format a file name asks for: ``.csv`` (also ``.csv.gz``), ``.mcap``, or
    ``.bag`` (a ROS 1 bag, or a rosbag2 directory: :mod:`ropod_sysid.io.rosbag`)."""
    name = Path(path).name.lower()
    if name.endswith(".csv.gz"):
        return ".csv"
    suffix = Path(name).suffix
    if suffix in (".csv", ".mcap"):
        return suffix
    from ropod_sysid.io.rosbag import is_bag

    if is_bag(path):
        return ".bag"
    raise InputError(f"{path}: unknown log format '{suffix}'; use .csv, .csv.gz, .mcap, a ROS "
                     "1 .bag or a rosbag2 directory")


def read_log(path: str | Path, platform: Platform, gaps: Gaps = "error") -> Log:
    """Read a log in any supported format, chosen by the file suffix (.csv, .csv.gz, .mcap).

    A CSV whose header names ``sensors.0.`` columns is read in the smart-wheel layout
    (:mod:`ropod_sysid.io.smartwheel`); an MCAP file's layout is recognised from its channels.
    Every reader checks the time base (:mod:`ropod_sysid.io.timebase`); ``gaps="allow"`` lets
    gaps in time through.
    """
    path = Path(path)
    if log_format(path) == ".csv":
        from ropod_sysid.io.smartwheel import is_smartwheel_csv, read_smartwheel_csv

        if is_smartwheel_csv(path):
            return read_smartwheel_csv(path, platform, gaps)
        from ropod_sysid.io.csvlog import read_csv_log

        return read_csv_log(path, platform, gaps)
    if log_format(path) == ".bag":
        from ropod_sysid.io.rosbag import iter_bag_log

        return join_logs(list(iter_bag_log(path, platform, sys.maxsize, gaps)))
    from ropod_sysid.io.mcaplog import read_mcap_log

    return read_mcap_log(path, platform, gaps)


def read_logs(paths: Sequence[str | Path], platform: Platform, gaps: Gaps = "error",
              ) -> list[Log]:
    """Read logs whole (:func:`read_log`), each listed once (:func:`check_distinct`)."""
    check_distinct(paths)
    return [read_log(p, platform, gaps) for p in paths]


def check_distinct(paths: Sequence[str | Path], what: str = "log") -> None:
    """Refuse a log listed twice: the same path, the same file by another path (a link), or
    a copy with identical content (same size, then the same BLAKE2 hash; files are hashed
    only when their sizes match). Stacking a log twice counts its samples twice and shrinks
    every standard deviation by √2. Files that do not exist are left to the readers."""
    seen: dict[tuple[int, int], str] = {}
    by_size: dict[int, list[str]] = {}
    for p in map(str, paths):
        try:
            st = os.stat(p)
        except OSError:
            continue
        if not stat.S_ISREG(st.st_mode):
            continue
        key = (st.st_dev, st.st_ino)
        if key in seen:
            how = "listed twice" if seen[key] == p else "the same file by another path"
            raise InputError(f"{p}: the same {what} as {seen[key]} ({how}); a {what} given "
                             "twice counts its samples twice and shrinks every σ by √2 — list "
                             "each once")
        seen[key] = p
        by_size.setdefault(st.st_size, []).append(p)
    digests: dict[bytes, str] = {}
    for group in by_size.values():
        if len(group) < 2:
            continue
        for p in group:
            digest = _digest(p)
            if digest in digests:
                raise InputError(f"{p}: the same content as {digests[digest]} (an identical "
                                 f"copy); a {what} given twice counts its samples twice and "
                                 "shrinks every σ by √2 — list each once")
            digests[digest] = p


def _digest(path: str) -> bytes:
    try:
        with open(path, "rb") as f:
            return hashlib.file_digest(f, "blake2b").digest()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the log file ({exc.strerror or exc})") from None


def write_log(log: Log, path: str | Path, platform: Platform | None = None) -> None:
    """Write a log; the suffix picks the format (.csv, .csv.gz, .mcap)."""
    path = Path(path)
    if path.name.lower().endswith(".bag"):
        raise InputError(f"{path}: ropod-sysid reads ROS bags but does not write them; write "
                         ".mcap (ROS 2 tools replay it) or .csv")
    if log_format(path) == ".csv":
        from ropod_sysid.io.csvlog import write_csv_log

        write_csv_log(log, path)
        return
    from ropod_sysid.io.mcapwrite import write_mcap_log

    write_mcap_log(log, path)


__all__ = ["LOG_SUFFIXES", "Log", "check_distinct", "log_format", "read_log", "read_logs",
           "write_log"]
