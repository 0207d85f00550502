"""What every command shares: one-line errors with exit status 2, common options."""

from __future__ import annotations

import functools
import json
import math
import os
import stat
import sys
import warnings
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar, cast

import click
from click.core import ParameterSource

from ropod_sysid.errors import InputError, one_line_warning
from ropod_sysid.io.atomic import OutputSet, file_kind
from ropod_sysid.io.timebase import GAP_RULE

F = TypeVar("F", bound=Callable[..., Any])

split_gaps_option = click.option(
    "--split-gaps", is_flag=True,
    help=f"A log with gaps in time ({GAP_RULE}) is refused; with this flag its pieces between "
         "the gaps are fitted as separate logs, each with its own smoother ends (pieces too "
         "short for the span are left out with a note). Pieces are named run.csv[1], "
         "run.csv[2], … in the output.")


def fail(message: str) -> None:
    """Print ``error: message`` on one line to stderr and exit with status 2."""
    click.echo(f"error: {' '.join(str(message).split())}", err=True)
    sys.exit(2)


def reports_errors(func: F) -> F:
    """Turn :class:`InputError` (and unreadable files) into one line and exit status 2."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        warnings.formatwarning = one_line_warning
        try:
            return func(*args, **kwargs)
        except InputError as exc:
            message = str(exc)
        except MemoryError:
            message = "out of memory; use fewer or shorter logs, or a machine with more memory"
        except KeyboardInterrupt:
            click.echo("interrupted", err=True)
            sys.exit(130)
        # outside the handler: the exception's traceback (and the readers and open files its
        # frames hold) is released before the exit, not kept alive until interpreter shutdown
        fail(message)

    return wrapper  # type: ignore[return-value]


def writes(outputs: Mapping[str, str] | None = None, inputs: Mapping[str, str] | None = None,
           folders: Mapping[str, str] | None = None,
           folder_files: Iterable[str] = ()) -> Callable[[F], F]:
    """The command writes the files of its parameters ``outputs`` and reads ``inputs``
    (parameter name → option or argument name, e.g. ``{"out_path": "--out"}``; a parameter may
    hold several paths). Before the command runs they are checked, and its files are written
    all or none (:class:`~ropod_sysid.io.atomic.OutputSet`). ``folders`` are output folders,
    made if missing, into which the command writes ``folder_files``. Goes under
    :func:`reports_errors`."""
    names = list(folder_files)

    def pairs(spec: Mapping[str, str] | None, kwargs: dict[str, Any]) -> list[tuple[str, Any]]:
        out = []
        for name, label in (spec or {}).items():
            value = kwargs[name]
            out += [(label, v) for v in (value if isinstance(value, tuple | list) else [value])]
        return out

    def decorate(func: F) -> F:
        @functools.wraps(func)
        def wrapper(**kwargs: Any) -> Any:
            dirs = pairs(folders, kwargs)
            files = [(label, Path(d) / n) for label, d in dirs for n in names]
            with OutputSet(pairs(outputs, kwargs) + files, pairs(inputs, kwargs), folders=dirs):
                return func(**kwargs)

        return wrapper  # type: ignore[return-value]

    return decorate


def given(name: str) -> bool:
    """Whether the user gave option ``name`` (the parameter's name) rather than its default."""
    ctx = click.get_current_context()
    return ctx.get_parameter_source(name) not in (None, ParameterSource.DEFAULT)


class InputFile(click.Path):
    """A file the command reads. One that exists must be a regular file: a FIFO, a device or a
    socket would block the reader or never end. A missing file is left to the reader, whose
    message says what kind of file it expected."""

    def __init__(self, recordings: bool = False) -> None:
        super().__init__(dir_okay=recordings)
        self.recordings = recordings  # a log: a rosbag2 recording is a directory

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        # the argument as given (no path_type converts it): the command line's str
        path = cast(str, super().convert(value, param, ctx))
        try:
            mode = os.stat(path).st_mode
        except OSError:
            return path
        if stat.S_ISDIR(mode) and self.recordings:
            from ropod_sysid.io.rosbag import is_bag

            if is_bag(path):
                return path
            raise OptionError(f"{path}: is a directory without a rosbag2 metadata.yaml; give a "
                              "log file (.csv, .csv.gz, .mcap, .bag) or a rosbag2 recording")
        if not stat.S_ISREG(mode):
            name = param.opts[0] if param is not None and param.opts and isinstance(
                param, click.Option) else (param.human_readable_name if param else "")
            raise OptionError(f"{name} {path}: is {file_kind(mode)}, not a regular file; "
                              "give the file itself (copy a stream to a file first)")
        return path


INPUT = InputFile()
LOG_INPUT = InputFile(recordings=True)  # a log file, or a rosbag2 recording (a directory)
quiet_option = click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")
platform_option = click.option(
    "--platform", "platform_path", required=True, type=INPUT,
    help="Platform YAML (geometry, units; see docs/file-formats.md).",
)


class OptionError(click.ClickException):
    """A bad option value, found while the options are parsed: ``error: <message>`` on one
    line, exit status 2, before any work."""

    exit_code = 2

    def __init__(self, message: str) -> None:
        super().__init__(" ".join(str(message).split()))

    def show(self, file: Any = None) -> None:
        click.echo(f"error: {self.format_message()}", err=True)


def option_name(param: click.Parameter | None, default: str = "value") -> str:
    """``--name`` of a click parameter (its longest option string)."""
    if param is None or not getattr(param, "opts", None):
        return default
    return max(param.opts, key=len)


def _g(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"


class Number(click.ParamType):
    """A finite number (``integer``: a whole number) in a range, checked at parse time.

    ``low``/``high`` are the bounds (None: unbounded), ``low_open``/``high_open`` exclude them;
    ``unit`` names what the number counts (``"s"``, ``"Hz"``).
    """

    def __init__(self, low: float | None = None, high: float | None = None, *,
                 low_open: bool = False, high_open: bool = False, integer: bool = False,
                 unit: str = "") -> None:
        self.low, self.high = low, high
        self.low_open, self.high_open = low_open, high_open
        self.integer = integer
        self.unit = unit
        self.name = "integer" if integer else "float"

    def range_text(self) -> str:
        """The allowed values in words, e.g. 'a finite number in (0, 1)', 'a whole number ≥ 1'."""
        what = "a whole number" if self.integer else "a finite number"
        unit = f" {self.unit}" if self.unit else ""
        lo, hi = self.low, self.high
        if lo is not None and hi is not None:
            return (f"{what} in {'(' if self.low_open else '['}{_g(lo)}, {_g(hi)}"
                    f"{')' if self.high_open else ']'}{unit}")
        if lo is not None:
            return f"{what} {'>' if self.low_open else '≥'} {_g(lo)}{unit}"
        if hi is not None:
            return f"{what} {'<' if self.high_open else '≤'} {_g(hi)}{unit}"
        return f"{what}{unit}"

    def check(self, value: Any, name: str) -> float | int:
        """``value`` (text or number) as a checked number; :class:`InputError` otherwise."""
        text = str(value).strip()
        try:
            x = float(text)
        except ValueError:
            raise InputError(f"{name} {text!r}: not a number; give {self.range_text()}"
                             ) from None
        ok = math.isfinite(x) and (not self.integer or x.is_integer())
        if ok and self.low is not None:
            ok = x > self.low if self.low_open else x >= self.low
        if ok and self.high is not None:
            ok = x < self.high if self.high_open else x <= self.high
        if not ok:
            raise InputError(f"{name} {text}: must be {self.range_text()}")
        return int(x) if self.integer else x

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        try:
            return self.check(value, option_name(param))
        except InputError as exc:
            raise OptionError(str(exc)) from None


def positive(unit: str = "", **kwargs: Any) -> Number:
    """A finite number > 0."""
    return Number(0, None, low_open=True, unit=unit, **kwargs)


POSITIVE_INT = Number(1, None, integer=True)
SEED = Number(0, 2**32 - 1, integer=True)


class SpanType(click.ParamType):
    """``--span``: samples (an odd whole number ≥ 5) or seconds (``0.1s``), checked at parse
    time by :meth:`ropod_sysid.regressor.Span.parse`."""

    name = "span"

    def convert(self, value: Any, param: click.Parameter | None,
                ctx: click.Context | None) -> Any:
        from ropod_sysid.regressor import Span

        if value is None or isinstance(value, Span):
            return value
        try:
            return Span.parse(str(value))
        except InputError as exc:
            raise OptionError(str(exc)) from None


def json_text(data: Any) -> str:
    """``data`` as strict JSON (indent 2): NaN and infinities become null, numpy scalars and
    arrays plain numbers and lists, so that every JSON parser reads it."""
    from ropod_sysid.io.paramfile import plain_data

    return json.dumps(plain_data(data), indent=2, ensure_ascii=False, allow_nan=False)
