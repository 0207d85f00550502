"""What every command shares: one-line errors with exit status 2, common options."""

from __future__ import annotations

import functools
import sys
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

import click
from click.core import ParameterSource

from ropod_sysid.errors import InputError, one_line_warning

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


def given(name: str) -> bool:
    """Whether the user gave option ``name`` (the parameter's name) rather than its default."""
    ctx = click.get_current_context()
    return ctx.get_parameter_source(name) not in (None, ParameterSource.DEFAULT)


quiet_option = click.option("--quiet", "-q", is_flag=True, help="No progress bar or summary.")
platform_option = click.option(
    "--platform", "platform_path", required=True, type=click.Path(dir_okay=False),
    help="Platform YAML (geometry, units; see the data contract).",
)
