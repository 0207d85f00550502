"""Reading and writing logs (CSV, MCAP) and parameter files."""

from __future__ import annotations

from pathlib import Path

from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.platform import Platform

LOG_SUFFIXES = (".csv", ".csv.gz", ".mcap")


def log_format(path: str | Path) -> str:
    """The log format a file name asks for: ``.csv`` (also ``.csv.gz``) or ``.mcap``."""
    name = Path(path).name.lower()
    if name.endswith(".csv.gz"):
        return ".csv"
    suffix = Path(name).suffix
    if suffix in (".csv", ".mcap"):
        return suffix
    raise InputError(f"{path}: unknown log format '{suffix}'; use .csv, .csv.gz or .mcap")


def read_log(path: str | Path, platform: Platform) -> Log:
    """Read a log in any supported format, chosen by the file suffix (.csv, .csv.gz, .mcap).

    A CSV whose header names ``sensors.0.`` columns is read in the smart-wheel layout
    (:mod:`ropod_sysid.io.smartwheel`); an MCAP file's layout is recognised from its channels.
    """
    path = Path(path)
    if log_format(path) == ".csv":
        from ropod_sysid.io.smartwheel import is_smartwheel_csv, read_smartwheel_csv

        if is_smartwheel_csv(path):
            return read_smartwheel_csv(path, platform)
        from ropod_sysid.io.csvlog import read_csv_log

        return read_csv_log(path, platform)
    from ropod_sysid.io.mcaplog import read_mcap_log

    return read_mcap_log(path, platform)


def write_log(log: Log, path: str | Path, platform: Platform | None = None) -> None:
    """Write a log; the suffix picks the format (.csv, .csv.gz, .mcap)."""
    path = Path(path)
    if log_format(path) == ".csv":
        from ropod_sysid.io.csvlog import write_csv_log

        write_csv_log(log, path)
        return
    from ropod_sysid.io.mcaplog import write_mcap_log

    write_mcap_log(log, path)


__all__ = ["LOG_SUFFIXES", "Log", "log_format", "read_log", "write_log"]
