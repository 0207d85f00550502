"""What every command shares: one-line errors with exit status 2, common options."""

from __future__ import annotations

import functools
import sys
import warnings
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import click
from click.core import ParameterSource

from ropod_sysid.errors import InputError, one_line_warning
from ropod_sysid.io.atomic import OutputSet

F = TypeVar("F", bound=Callable[..., Any])


def fail(message: str) -> None:
    """Print ``error: message`` on one line to stderr and exit with status 2."""
    click.echo(f"error: {' '.join(str(message).split())}", err=True)
    sys.exit(2)


def reports_errors(func: F) -> F:
    """Turn :class:`InputError` (and unreadable files) into one line and exit status 2."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        warnings.formatwarning = one_line_warning  # type: ignore[assignment]
        try:
            return func(*args, **kwargs)
        except InputError as exc:
            fail(str(exc))
        except MemoryError:
            fail("out of memory; use fewer or shorter logs, or a machine with more memory")
        except KeyboardInterrupt:
            click.echo("interrupted", err=True)
            sys.exit(130)

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


quiet_option = click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")
platform_option = click.option(
    "--platform", "platform_path", required=True, type=click.Path(dir_okay=False),
    help="Platform YAML (geometry, units; see the data contract).",
)
