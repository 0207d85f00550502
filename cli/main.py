"""Entry point of ``ropod-sysid``: the command group and its commands."""

from __future__ import annotations

import importlib
import warnings
from typing import Any

import click

from ropod_sysid import __version__
from ropod_sysid.errors import one_line_warning

# command name → module in this package that defines ``command``
COMMANDS = {
    "simulate": "simulate",
    "fit": "fit",
    "validate": "validate",
    "report": "report",
    "trajectory": "trajectory",
    "convert": "convert",
    "inspect": "inspect",
}


class OneLineUsageError(click.ClickException):
    """A usage error (missing option, bad choice, unknown command) as ``error: ...`` on one line
    with exit status 2, instead of click's Usage: block."""

    exit_code = 2

    def __init__(self, error: click.UsageError) -> None:
        path = error.ctx.command_path.split()[1:] if error.ctx is not None else []
        see = " ".join(["ropod-sysid", *path, "--help"])
        message = " ".join(error.format_message().split()).rstrip(".")
        super().__init__(f"{message} (see '{see}')")

    def show(self, file: Any = None) -> None:
        click.echo(f"error: {self.format_message()}", file=file, err=True)


def _one_line(error: click.UsageError) -> click.ClickException:
    if isinstance(error, click.exceptions.NoArgsIsHelpError):
        return error  # no arguments: the help, as click shows it
    return OneLineUsageError(error)


class LazyGroup(click.Group):
    """Imports a command's module only when that command runs (keeps ``--help`` fast).

    Usage errors anywhere below it come out as one line (:class:`OneLineUsageError`), and so
    does every warning."""

    def make_context(self, info_name: str | None, args: list[str],
                     parent: click.Context | None = None, **extra: Any) -> click.Context:
        warnings.formatwarning = one_line_warning
        try:
            return super().make_context(info_name, args, parent, **extra)
        except click.UsageError as exc:
            raise _one_line(exc) from None

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except click.UsageError as exc:
            raise _one_line(exc) from None

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [name for name in COMMANDS if self._load(name) is not None]

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        return self._load(cmd_name)

    @staticmethod
    def _load(name: str) -> click.Command | None:
        module = COMMANDS.get(name)
        if module is None:
            return None
        try:
            mod = importlib.import_module(f"ropod_sysid.cli.{module}")
        except ModuleNotFoundError as exc:
            if exc.name == f"ropod_sysid.cli.{module}":
                return None
            raise
        return mod.command


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="ropod-sysid")
def main() -> None:
    """Identify the dynamic parameters of wheeled mobile robots (swivel, steered, omni and legged
    wheel units; first the ropod) from their logs."""


def run() -> None:
    """The console script ``ropod-sysid``: :func:`main`, then the exit handlers, the standard
    streams flushed, and the process ended without the interpreter's teardown of its modules.

    That teardown does no work a command needs (every output file is written and closed, or
    renamed into place, before a command returns) and costs 0.1–0.3 s once numba or matplotlib
    has been loaded (measured on the report of the shipped sample). An exception that is not a
    ``SystemExit`` (a bug) takes the normal way out, with its traceback."""
    import atexit
    import os
    import sys

    _keep_freed_memory()
    _one_blas_thread()
    try:
        main.main()
        code: Any = 0
    except SystemExit as exc:
        code = exc.code
    if code is None:
        code = 0
    elif not isinstance(code, int):  # SystemExit("message"): printed, status 1
        print(code, file=sys.stderr)
        code = 1
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (`| head`): what was written is lost
            code = code or 1
    os._exit(code)


# glibc's mallopt parameters (malloc.h) and the values the console script sets
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_B = 32 << 20  # glibc's largest on 64-bit systems
TRIM_THRESHOLD_B = 1 << 30


def _keep_freed_memory() -> None:
    """Have glibc's malloc keep the memory a chunk's arrays free for the next chunk's instead
    of handing it back to the system and faulting it in again, zeroed: arrays up to
    :data:`MMAP_THRESHOLD_B` from the heap, which is trimmed only above
    :data:`TRIM_THRESHOLD_B` free at its top. Measured on the fit of a 60-minute 1 kHz CSV
    log: 510,000 → 63,000 page faults, 1.6–1.9 → 0.6 s of system time, 6.3–6.6 → 5.2–5.6 s,
    the peak memory the same (327 → 334 MB). Elsewhere than glibc, nothing."""
    import ctypes
    import platform

    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return
    try:
        libc = ctypes.CDLL(None)  # this process's symbols: glibc's among them
        libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_B)
        libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_B)
    except (OSError, AttributeError):  # no such library or function: the defaults stay
        pass


# the environment variables that set a BLAS library's threads: if the user sets one, it stands
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                         "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")


def _one_blas_thread() -> None:
    """Run the command's BLAS on one thread, unless the user set one of
    :data:`BLAS_THREAD_VARIABLES`: the libraries loaded already (numpy's) through threadpoolctl,
    those loaded later (scipy's) through ``OPENBLAS_NUM_THREADS``, which child processes
    inherit. The project's matrices have tens of columns, for which OpenBLAS's threads only
    wait on each other (numpy's spinning after a call while scipy's runs): measured on this
    repository's 2-core machine, ``trajectory check`` of a 60 s typical run 1.44-1.60 ->
    1.16-1.47 s and ``validate`` 0.53-0.57 -> 0.44-0.49 s. The library's own functions limit
    their threads where they solve (:func:`ropod_sysid.chunks.single_thread_blas`)."""
    import os

    if any(name in os.environ for name in BLAS_THREAD_VARIABLES):
        return
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")
