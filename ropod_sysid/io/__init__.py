"""Reading and writing logs (CSV, MCAP) and parameter files."""

from __future__ import annotations

from pathlib import Path

from ropod_sysid.errors import InputError
from ropod_sysid.io.log import Log
from ropod_sysid.platform import Platform

LOG_SUFFIXES = (".csv", ".csv.gz", ".mcap")


def read_log(path: str | Path, platform: Platform) -> Log:
    """Read a log in any supported format, chosen by the file suffix (.csv, .mcap).

    A CSV whose header names ``sensors.0.`` columns is read in the smart-wheel layout
    (:mod:`ropod_sysid.io.smartwheel`); an MCAP file's layout is recognised from its channels.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        from ropod_sysid.io.smartwheel import is_smartwheel_csv, read_smartwheel_csv

        if is_smartwheel_csv(path):
            return read_smartwheel_csv(path, platform)
        from ropod_sysid.io.csvlog import read_csv_log

        return read_csv_log(path, platform)
    if suffix == ".mcap":
        from ropod_sysid.io.mcaplog import read_mcap_log

        return read_mcap_log(path, platform)
    raise InputError(f"{path}: unknown log format '{suffix}'; use .csv or .mcap")


def write_log(log: Log, path: str | Path, platform: Platform | None = None) -> None:
    """Write a log; the suffix picks the format (.csv, .mcap)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".csv":
        from ropod_sysid.io.csvlog import write_csv_log

        write_csv_log(log, path)
        return
    if suffix == ".mcap":
        from ropod_sysid.io.mcaplog import write_mcap_log

        write_mcap_log(log, path)
        return
    raise InputError(f"{path}: unknown log format '{suffix}'; use .csv or .mcap")


__all__ = ["LOG_SUFFIXES", "Log", "read_log", "write_log"]
